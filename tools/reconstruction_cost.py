#!/usr/bin/python3
"""Cost of the displacement reconstruction: the new formula (paper Eq. 24,
alpha_bar = alpha - muhat) against the standard one (Eq. 10: G_A G_A^T
assembled, factorized by MUMPS and solved), in the paper's weak-scaling
setting (the counterpart of its Fig. 1).

The `cube` case of docs/CASES.md at fixed H/h (nel = 4,4,4 elements per
subdomain) with nsub = N,N,N subdomains for each N given, on a fixed number of
ranks, run by the Release binary that tools/run.sh builds (build/); each size
is repeated and the MEDIANS of the times in report.json are tabulated
(Markdown) and plotted (log-log).

    /usr/bin/python3 tools/reconstruction_cost.py \\
        --program build/bin/feticontact --ranks 2 --sizes 2 4 8 16 \\
        --repeats 3 3 3 1 --workdir output/reconstruction_cost \\
        --table output/reconstruction_cost/table.md --plot docs/figures/reconstruction_cost.png

Run it from the repository root (the default paths are relative to it); the
inputs, logs and report.json of every run stay in --workdir.

Times read from report.json: reconstruction.new.seconds and
reconstruction.standard.seconds (max over ranks of the 'rec new' and 'rec
standard' timers), reconstruction.standard.{assembly,factorization,solve}
(rank 0's parts of the standard formula), timings.solve.max and
timings.total.max. A run that fails or exceeds --timeout is reported as such
and left out of the medians. Ranks run with OMPI_MCA_mpi_yield_when_idle=1
(the machine may be shared). Use /usr/bin/python3 (numpy, matplotlib).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

CUBE = """&mesh nsub = {n}, {n}, {n}, nel = {nel}, {nel}, {nel} /
&material young = 2.1e5, poisson = 0.3 /
&boundary top_dirichlet = .true., top_displacement = 0.0, 0.0, -0.005 /
&obstacle shape = 'sphere', radius = 1.0, gap = 0.0 /
&solver tol = {tol}, monitor = .false. /
&reconstruction method = 'both' /
&output directory = '{out}', run_name = 'cube', write_hdf5 = .false., write_report = .true. /
"""


def run_one(args, n, rep):
    """One run of the cube with N^3 subdomains; the parsed report, or None."""
    work = os.path.join(args.workdir, "n%d_r%d" % (n, rep))
    os.makedirs(work, exist_ok=True)
    out = os.path.join(work, "out")
    nml = os.path.join(work, "cube.nml")
    with open(nml, "w") as f:
        f.write(CUBE.format(n=n, nel=args.nel, tol=args.tol, out=out))
    cmd = [args.mpiexec, "--oversubscribe", "--bind-to", "none", "-n", str(args.ranks), args.program, nml]
    # waiting ranks yield the core: on a machine shared with other jobs, busy
    # polling in MPI collectives would otherwise inflate communication-heavy phases
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_mpi_yield_when_idle="1")
    load = os.getloadavg()[0]
    t0 = time.time()
    try:
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout, env=env)
    except subprocess.TimeoutExpired:
        print("  N=%d run %d: timed out after %d s" % (n, rep, args.timeout), flush=True)
        return None
    wall = time.time() - t0
    with open(os.path.join(work, "log.txt"), "w") as f:
        f.write(run.stdout + run.stderr)
    report = os.path.join(out, "report.json")
    if run.returncode != 0 or not os.path.exists(report):
        print("  N=%d run %d: exit status %d (see %s)" % (n, rep, run.returncode, work), flush=True)
        return None
    with open(report) as f:
        r = json.load(f)
    r["wall"] = wall
    r["load"] = max(load, os.getloadavg()[0])
    rec = r["reconstruction"]
    print("  N=%d run %d: %.1f s wall, load %.1f, solve %.2f s, new %.2e s, standard %.2e s, alpha diff %.1e"
          % (n, rep, wall, r["load"], r["timings"]["solve"]["max"], rec["new"]["seconds"],
             rec["standard"]["seconds"], rec["alpha_difference"]), flush=True)
    return r


def median(values):
    return statistics.median(values) if values else float("nan")


def summarize(n, reports):
    r0 = reports[0]
    get = lambda f: median([f(r) for r in reports])
    std = lambda key: get(lambda r: r["reconstruction"]["standard"][key])
    row = {
        "nsub": n ** 3,
        "runs": len(reports),
        "coarse_dim": r0["sizes"]["coarse_dim"],
        "primal_dofs": r0["sizes"]["primal_dofs"],
        "dual_dofs": r0["sizes"]["dual_dofs"],
        "active": r0["reconstruction"]["standard"]["active_contact_rows"],
        "new": get(lambda r: r["reconstruction"]["new"]["seconds"]),
        "standard": std("seconds"),
        "assembly": std("assembly"),
        "factorization": std("factorization"),
        "std_solve": std("solve"),
        "solve": get(lambda r: r["timings"]["solve"]["max"]),
        "total": get(lambda r: r["timings"]["total"]["max"]),
        "alpha_difference": max(r["reconstruction"]["alpha_difference"] for r in reports),
        "hessian": r0["solver"]["hessian_multiplications"],
        "load": get(lambda r: r["load"]),
    }
    row["ratio"] = row["standard"] / row["new"] if row["new"] > 0 else float("nan")
    return row


def table(rows, args):
    lines = [
        "Cube (docs/CASES.md), nel = %d^3 per subdomain, tol = %s, %d MPI ranks, Release build; medians of the "
        "runs (times in s; standard = assembly + factorization + solve of G_A G_A^T)." % (args.nel, args.tol, args.ranks),
        "",
        "| subdomains | coarse dim | primal dofs | dual dofs | active contact | runs | new (Eq. 24) | standard (Eq. 10) "
        "| assembly | factorization | solve | standard / new | dual solve | total | max rel. alpha diff | load |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append("| %d | %d | %d | %d | %d | %d | %.2e | %.2e | %.2e | %.2e | %.2e | %.0f | %.3g | %.3g | %.1e | %.1f |"
                     % (r["nsub"], r["coarse_dim"], r["primal_dofs"], r["dual_dofs"], r["active"], r["runs"],
                        r["new"], r["standard"], r["assembly"], r["factorization"], r["std_solve"], r["ratio"],
                        r["solve"], r["total"], r["alpha_difference"], r["load"]))
    lines += ["", "load: median over the runs of the 1-minute load average (the machine has 2 cores)."]
    return "\n".join(lines) + "\n"


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["nsub"] for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.loglog(n, [r["standard"] for r in rows], "o-", color="C3", label="standard, Eq. (10): total")
    ax.loglog(n, [r["factorization"] for r in rows], "s--", color="C1", ms=4, label="  G_A G_A^T factorization")
    ax.loglog(n, [r["assembly"] for r in rows], "^--", color="C2", ms=4, label="  G_A G_A^T assembly")
    ax.loglog(n, [r["new"] for r in rows], "o-", color="C0", label="new, Eq. (24): alpha - muhat")
    ax.loglog(n, [r["solve"] for r in rows], ":", color="0.5", label="dual solve (SMALBE), for scale")
    for r in rows:
        ax.annotate("standard/new = %.0f" % r["ratio"], (r["nsub"], r["new"]), textcoords="offset points",
                    xytext=(0, -13), ha="center", fontsize=7, color="C0")
    ax.set_xlim(min(n) / 1.6, max(n) * 1.6)
    ax.set_ylim(min(r["new"] for r in rows) / 5, None)
    ax.set_xlabel("number of subdomains")
    ax.set_ylabel("time [s] (median)")
    ax.set_title("Reconstruction of the rigid body amplitudes, cube, H/h = 4")
    ax.set_xticks(n)
    ax.set_xticklabels([str(v) for v in n])
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=120)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--program", default="build/bin/feticontact")
    ap.add_argument("--mpiexec", default="mpirun")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--sizes", type=int, nargs="+", default=[2, 4, 8, 16], help="N: nsub = N,N,N")
    ap.add_argument("--repeats", type=int, nargs="+", default=[3, 3, 3, 1], help="runs per size")
    ap.add_argument("--nel", type=int, default=4)
    ap.add_argument("--tol", default="1e-6")
    ap.add_argument("--timeout", type=int, default=1800, help="seconds per run")
    ap.add_argument("--workdir", default="output/reconstruction_cost")
    ap.add_argument("--table", default=None, help="write the Markdown table here too")
    ap.add_argument("--plot", default="docs/figures/reconstruction_cost.png")
    ap.add_argument("--json", default=None, help="write the summary rows as JSON here")
    ap.add_argument("--from-json", default=None, help="no runs: table and plot from a --json file of an earlier run")
    args = ap.parse_args()
    repeats = args.repeats + [args.repeats[-1]] * (len(args.sizes) - len(args.repeats))

    rows = []
    if args.from_json:
        with open(args.from_json) as f:
            rows = json.load(f)
        args.sizes = []
    for n, reps in zip(args.sizes, repeats):
        print("N = %d (%d subdomains), %d runs" % (n, n ** 3, reps), flush=True)
        reports = [r for r in (run_one(args, n, k) for k in range(reps)) if r is not None]
        if reports:
            rows.append(summarize(n, reports))
        else:
            print("  N=%d: no successful run, left out" % n, flush=True)
    if not rows:
        sys.exit("no successful run")
    text = table(rows, args)
    print()
    print(text)
    if args.table:
        os.makedirs(os.path.dirname(os.path.abspath(args.table)), exist_ok=True)
        with open(args.table, "w") as f:
            f.write(text)
    if args.json and not args.from_json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    plot(rows, args.plot)
    print("plot: %s" % args.plot)


if __name__ == "__main__":
    main()
