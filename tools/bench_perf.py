#!/usr/bin/python3
"""Performance benchmark: where each phase stands against the machine.

    tools/bench_perf.py INPUT.nml [--ranks 2] [--repeat 3] [--build build]
                        [--set group:variable=value ...]
                        [--variant NAME=group:variable=value[;group:variable=value...] ...]

Runs the case R times (each variant once per repetition, interleaved, so that
machine drift hits all variants alike) and prints, per variant, the median time
of every phase (max over ranks), the work the phase does and the fraction of
the machine it reaches, with the machine's figures measured in the same run:

- F action: bytes one action reads and writes on all ranks
  (report.json performance.f_bytes_per_action_sum: implicit = the factors of
  K_reg twice + B twice + the vector passes; explicit = what BLAS reads of the
  local operators + B twice + the vector passes, see src/feti/f_operator.f90)
  per second, against a STREAM-like triad (tools/bench/stream_triad) on the
  same number of ranks, measured before and after the runs;
- factorization and explicit F (the build of the explicit local operators):
  floating-point operations (MUMPS's count RINFOG(3); + n_d^3 per subdomain
  for the dense inverses) per second, against dgemm (numpy, one BLAS thread
  per process, as many processes as ranks at once);
- F action with the shared explicit operators (`&solver share_subdomains`,
  one dgemm per class of congruent subdomains): also its flops
  (performance.f_flops_per_action_sum, 2 n_c^2 per member) per second against
  the same dgemm figure.

Example (F action implicit against explicit, three sizes of subdomain):

    for c in "4,4,4 4,4,4" "4,4,4 8,8,8" "2,2,2 12,12,12"; do set -- $c
      tools/bench_perf.py inputs/weak/cube_h8_n64.nml --set mesh:nsub=$1 --set mesh:nel=$2 \\
        --variant "implicit=solver:f_action='implicit'" --variant "explicit=solver:f_action='explicit'"
    done

Use /usr/bin/python3 (it has numpy).
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")

DGEMM = r"""
import time, numpy as np
n = 1500
a = np.random.rand(n, n); b = np.random.rand(n, n)
a @ b
best = 0
for _ in range(5):
    t = time.perf_counter(); a @ b; t = time.perf_counter() - t
    best = max(best, 2 * n**3 / t)
print(best / 1e9)
"""


def triad(build, ranks):
    out = subprocess.run(["mpirun", "--bind-to", "none", "-n", str(ranks), os.path.join(build, "bin", "stream_triad")],
                         capture_output=True, text=True, env=ENV, check=True).stdout
    return float(re.search(r"([0-9.]+) GB/s", out).group(1))


def dgemm(procs):
    """GF/s of dgemm summed over `procs` processes running at once."""
    ps = [subprocess.Popen([sys.executable, "-c", DGEMM], stdout=subprocess.PIPE, text=True, env=ENV)
          for _ in range(procs)]
    return sum(float(p.communicate()[0]) for p in ps)


def run_case(build, ranks, text, workdir):
    os.makedirs(workdir, exist_ok=True)
    path = os.path.join(workdir, "case.nml")
    with open(path, "w") as f:
        f.write(text)
    run = subprocess.run(["mpirun", "--bind-to", "none", "-n", str(ranks), os.path.join(build, "bin", "feticontact"),
                          path], capture_output=True, text=True, env=ENV)
    if run.returncode != 0:
        sys.stderr.write(run.stdout[-3000:] + run.stderr[-3000:])
        raise SystemExit("feticontact exited with status %d" % run.returncode)
    with open(os.path.join(workdir, "out", "report.json")) as f:
        return json.load(f)


def case_text(input_file, overrides, outdir):
    with open(input_file) as f:
        text = re.sub(r"!.*", "", f.read())
    groups = {m.group(1).lower(): m.group(2).strip() for m in re.finditer(r"&(\w+)(.*?)/", text, re.S)}
    overrides = ["output:directory='%s'" % outdir, "output:write_hdf5=.false.", "solver:monitor=.false."] + overrides
    for s in overrides:
        gv, value = s.split("=", 1)
        g, v = gv.split(":")
        body = groups.get(g, "")
        body = re.sub(r"\b%s\s*=\s*[^=]*?(?=(,\s*\w+\s*=)|$)" % v, "", body).strip().strip(",")
        groups[g] = (body + ", " if body else "") + "%s = %s" % (v, value)
    return "".join("&%s %s /\n" % (g, b) for g, b in groups.items())


def med(v):
    return statistics.median(v)


def report_variant(name, reports, bw, gf, ranks):
    phases = list(reports[0]["timings"].keys())
    perf = [r["performance"] for r in reports]
    sol = reports[0]["solver"]
    calls = sol["f_applications"]
    print("### %s (F action %s%s)" % (name, perf[0].get("f_action", "implicit"),
                                      ", shared per class" if perf[0].get("f_shared") else ""))
    print()
    print("| phase | median [s] | min [s] | max [s] | work | rate | fraction of the machine |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for ph in phases:
        v = [rep["timings"][ph]["max"] for rep in reports]
        work = rate = frac = ""
        if ph == "F action" and calls > 0:
            b = perf[0]["f_bytes_per_action_sum"]
            work = "%.3f GB x %d calls" % (b / 1e9, calls)
            gbs = med([p["f_bandwidth_bytes_per_second"] / 1e9 for p in perf])
            rate = "%.2f GB/s" % gbs
            frac = "%.2f of triad" % (gbs / bw)
            ffl = perf[0].get("f_flops_per_action_sum", 0)
            if ffl:   # shared explicit operators: one dgemm per class, compute bound
                gfs = ffl / 1e9 / med([p["f_action_seconds_per_call"] for p in perf])
                work += ", %.3f Gflop per call" % (ffl / 1e9)
                rate += ", %.2f GF/s" % gfs
                frac += ", %.2f of dgemm" % (gfs / gf)
        elif ph in ("factorization", "explicit F"):
            key = "factorization_flops_sum" if ph == "factorization" else "explicit_f_flops_sum"
            fl = perf[0].get(key, 0)
            if fl and med(v) > 0:
                work = "%.2f Gflop" % (fl / 1e9)
                rate = "%.2f GF/s" % (fl / 1e9 / med(v))
                frac = "%.2f of dgemm" % (fl / 1e9 / med(v) / gf)
        print("| %s | %.4f | %.4f | %.4f | %s | %s | %s |" % (ph, med(v), min(v), max(v), work, rate, frac))
    print()
    print("iterations: outer %d, Hessian multiplications %d, F actions %d, coarse solves %d"
          % (sol["outer_iterations"], sol["hessian_multiplications"], calls, sol["coarse_solves"]))
    fs = med([p["f_action_seconds_per_call"] for p in perf])
    print("F action: %.5f s per call (median), %.4f GB per call on all ranks, %.2f GB/s, %.2f of the triad (%d ranks)"
          % (fs, perf[0]["f_bytes_per_action_sum"] / 1e9,
             med([p["f_bandwidth_bytes_per_second"] / 1e9 for p in perf]),
             med([p["f_bandwidth_bytes_per_second"] / 1e9 for p in perf]) / bw, ranks))
    mem = reports[0]["memory"]["peak_rss_bytes"]
    print("memory: peak RSS max %.1f MB per rank, %.1f MB in all" % (mem["max"] / 1e6, mem["sum"] / 1e6))
    print()
    return fs


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME=group:variable=value[;group:variable=value...] (repeatable)")
    args = ap.parse_args()

    variants = [("default", [])]
    if args.variant:
        variants = []
        for v in args.variant:
            name, sets = v.split("=", 1)
            variants.append((name, [s for s in sets.split(";") if s]))

    work = tempfile.mkdtemp(prefix="bench_perf_")
    bw1 = triad(args.build, 1)
    bwp = triad(args.build, args.ranks)
    gf1 = dgemm(1)
    gfp = dgemm(args.ranks)
    reports = {name: [] for name, _ in variants}
    for r in range(args.repeat):
        for name, sets in variants:
            outdir = os.path.join(work, name, "run%d" % r)
            rep = run_case(args.build, args.ranks,
                           case_text(args.input, args.set + sets, os.path.join(outdir, "out")), outdir)
            reports[name].append(rep)
            print("run %d/%d %s: total %.3f s" % (r + 1, args.repeat, name, rep["timings"]["total"]["max"]),
                  file=sys.stderr)
    bw_after = triad(args.build, args.ranks)
    gf_after = dgemm(args.ranks)
    bw = max(bwp, bw_after)
    gf = max(gfp, gf_after)

    s = reports[variants[0][0]][0]["sizes"]
    print("case %s %s: %d subdomains, %d ranks, %d primal dofs, %d dual dofs; median of %d runs (max over ranks)"
          % (os.path.basename(args.input), " ".join(args.set), s["subdomains"], s["ranks"], s["primal_dofs"],
             s["dual_dofs"], args.repeat))
    print("machine, same run: triad %.2f GB/s on 1 rank, %.2f / %.2f GB/s on %d ranks before / after the runs; "
          "dgemm %.1f GF/s on 1 process, %.1f / %.1f GF/s on %d at once; fractions use the larger figure"
          % (bw1, bwp, bw_after, args.ranks, gf1, gfp, gf_after, args.ranks))
    print()
    fs = {}
    for name, _ in variants:
        fs[name] = report_variant(name, reports[name], bw, gf, args.ranks)
    if len(variants) > 1:
        base = variants[0][0]
        print("| variant | total [s] | F action [s/call] | F action vs %s |" % base)
        print("|---|---:|---:|---:|")
        for name, _ in variants:
            tot = med([r["timings"]["total"]["max"] for r in reports[name]])
            print("| %s | %.3f | %.5f | %.2fx |" % (name, tot, fs[name], fs[base] / fs[name]))


if __name__ == "__main__":
    main()
