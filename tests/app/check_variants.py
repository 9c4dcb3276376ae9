#!/usr/bin/python3
"""A differential test matrix: every value of every setting that chooses an algorithm or a data
layout, run on the same input as the default path, gives the same solution.

    check_variants.py --program BIN --mpiexec MPIEXEC --ranks N --workdir DIR --material uniform|checker

The input is a cube of 2^3 subdomains of 3^3 elements pressed onto a sphere of radius 20 (a
contact patch of several of its 49 contact nodes), at tol 1e-8; `checker` gives it a checkerboard
of moduli (contrast 1e3). Each variant (tools/variants.py syntax) is one run; its HDF5
displacements (matched by node position) and its contact force must agree with the default run's
to 2 x 60 tol relative: docs/INPUT.md states that tol buys a displacement error of about 20 tol,
and the reference tests (app_reference_*) hold each run to 60 tol of the exact discrete solution,
so two runs differ by at most twice that. Every run must exit 0 (converged, KKT check passed).
Variants that the heterogeneous material does not admit (clusters need uniform moduli; METIS
subdomains change which elements the checkerboard makes stiff) run on the uniform one only.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "tools"))
import variants  # noqa: E402

TOL = 1e-8
BOUND = 2 * 60 * TOL

BASE = {
    "mesh": [("nsub", "2, 2, 2"), ("nel", "3, 3, 3")],
    "boundary": [("top_displacement", "0.0, 0.0, -0.005")],
    "obstacle": [("shape", "'sphere'"), ("radius", "20.0")],
    "solver": [("tol", repr(TOL))],
    "output": [("run_name", "'run'")],
}
CHECKER = {"material": [("variation", "'checkerboard'"), ("contrast", "1e3")]}

# name:settings (tools/variants.py); "uniform" marks those run on the uniform material only
MATRIX = [
    ("coarse_mumps", "coarse_factor=mumps", "both"),
    ("coarse_dense", "coarse_factor=dense;coarse_ranks=1", "both"),
    ("coarse_orthonormal", "coarse=orthonormal", "both"),
    # share_subdomains = 'none': with shared classes (the default) the class's solver is used
    ("local_dense", "local_solver=dense;share_subdomains=none", "both"),
    ("local_block", "local_solver=block;share_subdomains=none", "both"),
    ("local_subdomain", "local_solver=subdomain;share_subdomains=none", "both"),
    ("ordering_amd", "local_ordering=amd;local_solver=subdomain;share_subdomains=none", "both"),
    ("ordering_metis", "local_ordering=metis;local_solver=subdomain;share_subdomains=none", "both"),
    ("f_implicit", "f_action=implicit", "both"),
    ("f_explicit_packed", "f_action=explicit;f_storage=packed", "both"),
    ("f_explicit_symmetric", "f_action=explicit;f_storage=symmetric", "both"),
    ("f_explicit_general", "f_action=explicit;f_storage=general", "both"),
    ("unshared", "share_subdomains=none", "both"),
    ("shared_explicit", "share_subdomains=auto;f_action=explicit", "both"),
    ("precond_none", "preconditioner=none", "both"),
    ("precond_lumped", "preconditioner=lumped", "both"),
    ("precond_dirichlet", "preconditioner=dirichlet", "both"),
    ("scaling_none", "scaling=none", "both"),
    ("stopping_norm", "stopping=norm", "both"),
    ("expansion_optimal", "expansion=optimal", "both"),
    ("no_polish", "polish_window=0", "both"),
    ("rec_multiplier", "reconstruction:method=multiplier", "both"),
    ("rec_standard", "reconstruction:method=standard", "both"),
    ("hybrid", "mesh:cluster=2,1,1", "uniform"),
    ("metis", "mesh:decomposition=metis", "uniform"),
]


def write_namelist(groups, path):
    with open(path, "w") as f:
        for g, items in groups.items():
            f.write("&%s %s /\n" % (g, ", ".join("%s = %s" % kv for kv in items)))


def groups_settings(groups):
    return [(g, n, v) for g, items in groups.items() for n, v in items]


def run(args, name, groups):
    out = os.path.join(args.workdir, name)
    shutil.rmtree(out, ignore_errors=True)
    groups = variants.merge(groups, {"settings": [("output", "directory", "'%s'" % out)]})
    os.makedirs(args.workdir, exist_ok=True)
    path = os.path.join(args.workdir, name + ".nml")
    write_namelist(groups, path)
    launcher = [] if args.ranks == 1 else [args.mpiexec, "-n", str(args.ranks)]   # one rank: an MPI singleton
    p = subprocess.run(launcher + [args.program, path], capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        return None, "exit %d: %s" % (p.returncode, (p.stdout + p.stderr)[-800:])
    import h5py
    with h5py.File(os.path.join(out, "run.h5"), "r") as h5:
        x, u = h5["coordinates"][...], h5["displacement"][...]
    report = json.load(open(os.path.join(out, "report.json")))
    force = report["contact"]["total_force"]
    # a variant that chooses the local solver or the F action must be the one the run used
    perf = report.get("performance", {})
    for var in ("local_solver", "f_action", "local_ordering"):
        wanted = [v.strip("'") for g, n, v in groups_settings(groups) if g == "solver" and n == var]
        if wanted and var in perf and perf[var] != wanted[0]:
            return None, "report.json performance.%s = %s, not the variant's %s" % (var, perf[var], wanted[0])
    keys = [tuple(k) for k in np.round(x * 1e9).astype(np.int64)]
    return (dict(zip(keys, u)), force), None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--material", choices=["uniform", "checker"], default="uniform")
    args = ap.parse_args()
    base = dict(BASE)
    if args.material == "checker":
        base.update(CHECKER)
    ref, err = run(args, "default", base)
    if ref is None:
        sys.exit("default run failed: " + err)
    u0, f0 = ref
    scale = max(np.abs(v).max() for v in u0.values())
    failures = []
    for name, spec, where in MATRIX:
        if where == "uniform" and args.material != "uniform":
            continue
        variant = variants.parse_variant("%s:%s" % (name, spec))
        res, err = run(args, name, variants.merge(base, variant))
        if res is None:
            failures.append("%s (%s): %s" % (name, variants.describe(variant), err))
            print("FAIL " + failures[-1])
            continue
        u, f = res
        if set(u) != set(u0):
            failures.append("%s: other node positions than the default run" % name)
            print("FAIL " + failures[-1])
            continue
        du = max(np.abs(u[k] - u0[k]).max() for k in u0) / scale
        df = abs(f - f0) / abs(f0)
        ok = du <= BOUND and df <= BOUND
        print("%s %-22s %-48s |du|/|u| %.2e, |dF|/|F| %.2e (bound %.1e)"
              % ("ok  " if ok else "FAIL", name, variants.describe(variant), du, df, BOUND))
        if not ok:
            failures.append("%s: |du|/|u| %.2e, |dF|/|F| %.2e > %.1e" % (name, du, df, BOUND))
    print("%s material: %d failed" % (args.material, len(failures)))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
