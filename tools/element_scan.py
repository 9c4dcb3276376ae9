#!/usr/bin/python3
"""Hessian products and the solution of the cube on a sphere against Poisson's ratio, per element.

    tools/element_scan.py --program build-release/bin/feticontact --workdir DIR \
        [--nsub 4,4,3] [--nel 4,4,5] [--nu 0.3,0.4995] [--elements q1_bbar,q1] [--ranks 2]

Each (nu, element) runs once (`mpirun --bind-to none -n RANKS`) on the cube of
inputs/cube.nml's kind (top moved down by 0.005, sphere of radius 1 touching the
bottom centre, tol 1e-6) with &material poisson = nu, element = the element, into
DIR/nu<nu>_<element>_nel<nel>. One markdown row per run: products, KKT check, the
polish's face condition estimate (report.json solver.polish_condition_estimate),
the contact force, the active nodes and the largest u_x on the face x = 1 (HDF5).
"""
import argparse
import json
import os
import subprocess

import h5py
import numpy as np


def run(args, nu, element):
    name = "nu%s_%s_nel%s" % (nu, element, args.nel.replace(",", ""))
    work = os.path.abspath(os.path.join(args.workdir, name))
    os.makedirs(work, exist_ok=True)
    with open(os.path.join(work, "in.nml"), "w") as f:
        f.write("&mesh nsub = %s, nel = %s /\n" % (args.nsub, args.nel))
        f.write("&material young = 2.1e5, poisson = %s, element = '%s' /\n" % (nu, element))
        f.write("&boundary top_dirichlet = .true., top_displacement = 0.0, 0.0, -0.005 /\n")
        f.write("&obstacle shape = 'sphere', radius = 1.0, gap = 0.0 /\n&solver tol = 1e-6 /\n")
        f.write("&output directory = '%s/out', run_name = 'r', write_hdf5 = .true. /\n" % work)
    with open(os.path.join(work, "log.txt"), "w") as log:
        rc = subprocess.call(["mpirun", "--bind-to", "none", "-n", str(args.ranks), args.program,
                              os.path.join(work, "in.nml")], stdout=log, stderr=subprocess.STDOUT)
    with open(os.path.join(work, "out", "report.json")) as f:
        r = json.load(f)
    with h5py.File(os.path.join(work, "out", "r.h5"), "r") as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
    bulge = u[np.abs(x[:, 0] - 1.0) < 1e-9, 0].max()
    s = r["solver"]
    kappa_mu = 2 * (1 + float(nu)) / (3 * (1 - 2 * float(nu)))
    return "| %s | %.4g | %s | %s | %d | %s | %.1f | %.2f | %d | %.4e |" % (
        nu, kappa_mu, element, args.nel, s["hessian_multiplications"],
        "passed" if (rc == 0 and r["kkt"]["passed"]) else "FAILED (exit %d)" % rc,
        s.get("polish_condition_estimate") or 0.0, r["contact"]["total_force"],
        r["contact"]["active_nodes"], bulge)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--program", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--nsub", default="4,4,3")
    ap.add_argument("--nel", default="4,4,5")
    ap.add_argument("--nu", default="0.3,0.4995")
    ap.add_argument("--elements", default="q1_bbar,q1")
    ap.add_argument("--ranks", type=int, default=2)
    args = ap.parse_args()
    args.program = os.path.abspath(args.program)
    print("| nu | kappa/mu | element | nel | products | KKT | face condition | contact force | active nodes "
          "| max u_x on x = 1 |")
    print("|---|---:|---|---|---:|---|---:|---:|---:|---:|")
    for nu in args.nu.split(","):
        for element in args.elements.split(","):
            print(run(args, nu, element), flush=True)


if __name__ == "__main__":
    main()
