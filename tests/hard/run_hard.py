#!/usr/bin/python3
"""run_case.py (tests/app) plus the exact solutions of the hard `block` family.

    run_hard.py <run_case.py arguments> [--check block_family:TOL]

`block_family:TOL` compares the HDF5 displacement with the exact solution of
hard_checks.py: the homogeneous `block` solution for any E and nu, or the
layered one (nsub = 1, 1, Nz, checkerboard E, nu = 0). Every other argument
goes to run_case.py unchanged.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "app"))
sys.path.insert(0, HERE)
import run_case  # noqa: E402
import hard_checks  # noqa: E402


def main():
    argv, extra = [], []
    args = sys.argv[1:]
    i = 0
    while i < len(args):
        if args[i] == "--check" and i + 1 < len(args) and args[i + 1].startswith("block_family:"):
            extra.append(float(args[i + 1].split(":", 1)[1]))
            i += 2
        else:
            argv.append(args[i])
            i += 1
    workdir = argv[argv.index("--workdir") + 1]
    sys.argv = [sys.argv[0]] + argv
    try:
        run_case.main()
    except SystemExit:
        pass
    for tol in extra:
        with open(os.path.join(workdir, "case.nml")) as f:
            groups = run_case.parse_namelist(f.read())
        try:
            err = hard_checks.block_error(os.path.join(workdir, "out"), groups)
            run_case.check(err <= tol, "block family: max |u - u_exact| / max |u_exact| = %.3e <= %.1e" % (err, tol))
        except (OSError, ValueError, RuntimeError, KeyError) as e:
            run_case.check(False, "block family exact solution: %s" % e)
    print("%d passed, %d failed" % (len(run_case.PASSED), len(run_case.FAILURES)))
    sys.exit(1 if run_case.FAILURES else 0)


if __name__ == "__main__":
    main()
