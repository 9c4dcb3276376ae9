#!/usr/bin/python3
"""Speed against accuracy on uniform and heterogeneous material.

    tools/accuracy_table.py [--program build/bin/feticontact] [--ranks 2]
        [--workdir output/accuracy] [--nsub 3] [--nel 4] [--delta 0.025]
        [--materials none:1,checkerboard:1e4,checkerboard:1e6,random:1e6]
        [--tols 1e-4,1e-6,1e-8] [--stopping violation,norm] [--ref-tol 1e-11]

Runs the `cube` case (docs/CASES.md; nsub^3 subdomains of nel^3 elements, or
Nx,Ny,Nz of nx,ny,nz; top face moved down by delta) for every material, stopping test and tol, and once per
material at ref-tol, and prints a Markdown table: Hessian multiplications,
solve time, the displacement error max |u - u_ref| / max |u_ref| and the
largest difference between the copies of a node (both computed from the HDF5
output, copies matched by coordinates), the KKT check's gluing measure, and
error/tol. Run with /usr/bin/python3 (numpy, h5py).
"""
import argparse
import json
import os
import shutil
import subprocess

import h5py
import numpy as np


def triple(v):
    """'3' or 3 -> '3, 3, 3'; '2,1,1' -> '2, 1, 1'."""
    parts = [p.strip() for p in str(v).split(",")]
    return ", ".join(parts * 3 if len(parts) == 1 else parts)


def write_case(path, out, nsub, nel, variation, contrast, tol, stopping, seed=1, delta=0.025):
    with open(path, "w") as f:
        f.write("&mesh nsub = %s, nel = %s /\n" % (triple(nsub), triple(nel)))
        f.write("&material young = 2.1e5, poisson = 0.3, variation = '%s', contrast = %s, seed = %d /\n"
                % (variation, contrast, seed))
        f.write("&boundary top_dirichlet = .true., top_displacement = 0.0, 0.0, -%s /\n" % delta)
        f.write("&obstacle shape = 'sphere', radius = 1.0, gap = 0.0 /\n")
        f.write("&solver tol = %s, stopping = '%s', max_hessian = 200000, max_outer = 2000, monitor = .false. /\n"
                % (tol, stopping))
        f.write("&reconstruction kkt_tol = 1.0 /\n")
        f.write("&output directory = '%s', run_name = 'c' /\n" % out)


def run_case(program, mpiexec, ranks, directory, timeout=3600, **case):
    """Run one case in `directory`; return (exit status, log text, report or None, x, u)."""
    shutil.rmtree(directory, ignore_errors=True)
    os.makedirs(directory)
    nml = os.path.join(directory, "case.nml")
    out = os.path.join(directory, "out")
    write_case(nml, out, **case)
    cmd = [mpiexec, "--oversubscribe", "--bind-to", "none", "-n", str(ranks), program, nml]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    log = p.stdout + p.stderr
    with open(os.path.join(directory, "log.txt"), "w") as f:
        f.write(log)
    if p.returncode != 0:
        return p.returncode, log, None, None, None
    with open(os.path.join(out, "report.json")) as f:
        report = json.load(f)
    with h5py.File(os.path.join(out, "c.h5"), "r") as h5:
        return 0, log, report, h5["coordinates"][...], h5["displacement"][...]


def copy_jump(x, u):
    """Largest max - min over the copies of a node component (copies share coordinates)."""
    key = np.round(x / np.abs(x).max() * 1e9).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    n = inv.max() + 1
    hi = np.full((n, 3), -np.inf)
    lo = np.full((n, 3), np.inf)
    np.maximum.at(hi, inv, u)
    np.minimum.at(lo, inv, u)
    return float(np.max(hi - lo))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--program", default="build/bin/feticontact")
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--workdir", default="output/accuracy")
    ap.add_argument("--nsub", default="3", help="subdomains per direction: N or Nx,Ny,Nz")
    ap.add_argument("--nel", default="4", help="elements per subdomain and direction: n or nx,ny,nz")
    ap.add_argument("--delta", default="0.025", help="the downward displacement of the top face")
    ap.add_argument("--materials", default="none:1,checkerboard:1e4,checkerboard:1e6,random:1e6")
    ap.add_argument("--tols", default="1e-4,1e-6,1e-8")
    ap.add_argument("--stopping", default="violation,norm")
    ap.add_argument("--ref-tol", default="1e-11")
    args = ap.parse_args()
    print("| material | stopping | tol | Hessian | solve [s] | error | error/tol | jump | KKT gluing |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for material in args.materials.split(","):
        variation, contrast = material.split(":")
        common = dict(nsub=args.nsub, nel=args.nel, variation=variation, contrast=contrast, delta=args.delta)
        base = os.path.join(args.workdir, "%s_%s" % (variation, contrast))
        status, _, _, xr, ur = run_case(args.program, args.mpiexec, args.ranks, os.path.join(base, "ref"),
                                        tol=args.ref_tol, stopping="violation", **common)
        if status != 0:
            print("| %s %s | reference at %s failed (exit %d) | | | | | | | |" % (variation, contrast,
                                                                              args.ref_tol, status))
            continue
        umax = float(np.abs(ur).max())
        for stopping in args.stopping.split(","):
            for tol in args.tols.split(","):
                status, _, rep, x, u = run_case(args.program, args.mpiexec, args.ranks,
                                                os.path.join(base, "%s_%s" % (stopping, tol)),
                                                tol=tol, stopping=stopping, **common)
                if status != 0:
                    print("| %s %s | %s | %s | exit %d | | | | | |" % (variation, contrast, stopping, tol, status))
                    continue
                err = float(np.abs(u - ur).max()) / umax
                jump = copy_jump(x, u) / float(np.abs(u).max())
                solve = rep["timings"]["solve"]["max"] if "timings" in rep and "solve" in rep["timings"] else float("nan")
                print("| %s %s | %s | %s | %d | %.3g | %.2e | %.1f | %.2e | %.2e |" % (
                    variation, contrast, stopping, tol, rep["solver"]["hessian_multiplications"], solve, err,
                    err / float(tol), jump, rep["kkt"]["gluing"]))


if __name__ == "__main__":
    main()
