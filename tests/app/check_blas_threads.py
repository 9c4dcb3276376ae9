#!/usr/bin/python3
"""BLAS threads per rank (src/external/blas_threads.f90), end to end.

    check_blas_threads.py --run-case tests/app/run_case.py --program feticontact --mpiexec mpiexec \
        --ranks 2 --input inputs/block.nml --workdir DIR

Runs the case through run_case.py with different environments and reads the
`blas` object of report.json:
  - no thread variable set: 1 thread per rank, source 'default';
  - FETICONTACT_BLAS_THREADS=2: 2 threads when the loaded BLAS can thread
    (blas.multithreaded); with a single-threaded BLAS that check is skipped
    (and says which BLAS was found), the count must then be 1;
  - FETICONTACT_BLAS_THREADS=abc: exit status 2 (input error) on every rank,
    with a message that names the variable.
Exit status 0 when every check passes.
"""
import argparse
import json
import os
import subprocess
import sys

# variables a BLAS reads for its thread count (removed for the default run)
THREAD_VARIABLES = ["FETICONTACT_BLAS_THREADS", "OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "BLIS_NUM_THREADS",
                    "MKL_NUM_THREADS", "OMP_NUM_THREADS"]
FAILURES = []
PASSED = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    (PASSED if condition else FAILURES).append(what)


def run(args, name, extra_env, run_case_args):
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env.update(extra_env)
    workdir = os.path.join(args.workdir, name)
    cmd = [sys.executable, args.run_case, "--program", args.program, "--mpiexec", args.mpiexec,
           "--ranks", str(args.ranks), "--input", args.input, "--workdir", workdir] + run_case_args
    print("--- %s: %s %s" % (name, " ".join("%s=%s" % kv for kv in extra_env.items()), " ".join(cmd)))
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.timeout)
    print(p.stdout[-3000:] + p.stderr[-2000:])
    check(p.returncode == 0, "%s: run_case.py checks pass" % name)
    return workdir, p.stdout


def blas_of(workdir, name):
    path = os.path.join(workdir, "out", "report.json")
    try:
        with open(path) as f:
            blas = json.load(f).get("blas")
    except (OSError, ValueError) as e:
        check(False, "%s: report.json readable (%s)" % (name, e))
        return None
    check(isinstance(blas, dict), "%s: report.json has a 'blas' object" % name)
    if not isinstance(blas, dict):
        return None
    for key, kind in [("library", str), ("path", str), ("threads", int), ("source", str), ("multithreaded", bool)]:
        check(isinstance(blas.get(key), kind), "%s: blas.%s is a %s" % (name, key, kind.__name__))
    return blas


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--run-case", required=True)
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--input", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--timeout", type=int, default=300)
    args = ap.parse_args()

    # 1. default: one thread per rank, and the log line says so
    workdir, out = run(args, "default", {}, ["--check", "report"])
    blas = blas_of(workdir, "default")
    if blas:
        print("BLAS found: %s (%s), multithreaded: %s" % (blas["library"], blas["path"], blas["multithreaded"]))
        check(blas["threads"] == 1, "default: blas.threads == 1 (got %s)" % blas["threads"])
        check(blas["source"] == "default", "default: blas.source == 'default' (got %r)" % blas["source"])
    check("BLAS: " in out and "1 thread per rank (default" in out, "default: the log has the BLAS line")

    # 2. FETICONTACT_BLAS_THREADS=2
    workdir, out = run(args, "threads2", {"FETICONTACT_BLAS_THREADS": "2"}, ["--check", "report"])
    blas = blas_of(workdir, "threads2")
    if blas:
        check(blas["source"] == "FETICONTACT_BLAS_THREADS", "threads2: blas.source names the variable")
        if blas["multithreaded"]:
            check(blas["threads"] == 2, "threads2: blas.threads == 2 (got %s)" % blas["threads"])
        else:
            print("skipped: blas.threads == 2 with FETICONTACT_BLAS_THREADS=2: the loaded BLAS is single-threaded: "
                  "%s (%s)" % (blas["library"], blas["path"]))
            check(blas["threads"] == 1, "threads2: a single-threaded BLAS reports 1 thread (got %s)" % blas["threads"])

    # 3. an invalid value: exit status 2 from every rank, a message naming the variable
    run(args, "invalid", {"FETICONTACT_BLAS_THREADS": "abc"},
        ["--expect-exit", "2", "--expect-message", "FETICONTACT_BLAS_THREADS='abc' is not a positive integer"])

    print("%d passed, %d failed" % (len(PASSED), len(FAILURES)))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
