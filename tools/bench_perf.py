#!/usr/bin/python3
"""Performance benchmark: the median time of every phase over R runs of one
case, and the memory bandwidth one F action achieves next to a STREAM-like
triad measured in the same run.

    tools/bench_perf.py INPUT.nml [--ranks 2] [--repeat 3] [--build build]
                        [--set group:variable=value ...] [--markdown]

The F action reads the factors of K_reg twice (forward and backward
substitution) and B twice (B^T, then B); report.json gives those bytes
(performance.f_bytes_per_action_sum) and the time of one F action (the max
over ranks of the 'F action' timer divided by the number of F actions).
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
           OMPI_MCA_rmaps_base_oversubscribe="1")


def triad(build, ranks):
    out = subprocess.run(["mpirun", "--bind-to", "none", "-n", str(ranks), os.path.join(build, "bin", "stream_triad")],
                         capture_output=True, text=True, env=ENV, check=True).stdout
    return float(re.search(r"([0-9.]+) GB/s", out).group(1))


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


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--set", action="append", default=[])
    args = ap.parse_args()

    work = tempfile.mkdtemp(prefix="bench_perf_")
    bw1 = triad(args.build, 1)
    bwp = triad(args.build, args.ranks)
    reports = []
    for r in range(args.repeat):
        outdir = os.path.join(work, "run%d" % r)
        rep = run_case(args.build, args.ranks, case_text(args.input, args.set, os.path.join(outdir, "out")), outdir)
        reports.append(rep)
        print("run %d/%d: total %.3f s" % (r + 1, args.repeat, rep["timings"]["total"]["max"]), file=sys.stderr)
    bw_after = triad(args.build, args.ranks)

    phases = list(reports[0]["timings"].keys())
    s = reports[0]["sizes"]
    print("case %s: %d subdomains, %d ranks, %d primal dofs, %d dual dofs; median of %d runs (max over ranks)"
          % (os.path.basename(args.input), s["subdomains"], s["ranks"], s["primal_dofs"], s["dual_dofs"], args.repeat))
    print()
    print("| phase | median [s] | min [s] | max [s] |")
    print("|---|---:|---:|---:|")
    for ph in phases:
        v = [rep["timings"][ph]["max"] for rep in reports]
        print("| %s | %.4f | %.4f | %.4f |" % (ph, statistics.median(v), min(v), max(v)))
    sol = reports[0]["solver"]
    print()
    print("iterations: outer %d, Hessian multiplications %d, F actions %d, coarse solves %d"
          % (sol["outer_iterations"], sol["hessian_multiplications"], sol["f_applications"], sol["coarse_solves"]))
    fb = [rep["performance"]["f_bandwidth_bytes_per_second"] / 1e9 for rep in reports]
    fs = [rep["performance"]["f_action_seconds_per_call"] for rep in reports]
    print("F action: %.4f s per call (median), %.3f GB read per call on all ranks, %.2f GB/s (median)"
          % (statistics.median(fs), reports[0]["performance"]["f_bytes_per_action_sum"] / 1e9, statistics.median(fb)))
    print("triad: %.2f GB/s on 1 rank, %.2f GB/s on %d ranks before the runs, %.2f GB/s after"
          % (bw1, bwp, args.ranks, bw_after))
    print("F action bandwidth / triad bandwidth (%d ranks): %.2f" % (args.ranks, statistics.median(fb) / max(bwp, bw_after)))
    print("memory: peak RSS max %.1f MB per rank, %.1f MB in all; %.0f bytes per primal dof"
          % (reports[0]["memory"]["peak_rss_bytes"]["max"] / 1e6, reports[0]["memory"]["peak_rss_bytes"]["sum"] / 1e6,
             reports[0]["memory"]["peak_rss_bytes"]["sum"] / s["primal_dofs"]))


if __name__ == "__main__":
    main()
