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
OpenBLAS's kernels (blas.core, blas.core_chosen_by_library; fc_openblas_core in
src/external/blas_threads_c.c), when the BLAS is OpenBLAS:
  - default run: blas.core is named; where the library fell back to its
    generic Prescott kernels on a CPU with AVX2 and FMA (/proc/cpuinfo), the
    program chose again: core_chosen_by_library is 'Prescott', core is SkylakeX
    (the CPU has AVX-512 F, CD, DQ, BW, VL) or Haswell, and the log says so;
    otherwise core_chosen_by_library is '' (the library's choice kept);
  - OPENBLAS_CORETYPE=Prescott (the user's choice) is never overridden: core
    'Prescott', core_chosen_by_library '';
  - OPENBLAS_CORETYPE=Haswell on a CPU with AVX2 and FMA: core 'Haswell' (a
    build that chooses its kernels at run time), and then the default run must
    not be left on Prescott.
Exit status 0 when every check passes.

`--part threads` runs the FETICONTACT_BLAS_THREADS=2 case alone, as its own CTest test: with a
single-threaded BLAS it checks that 1 thread is reported and then exits 77 (CTest: skipped,
naming the BLAS), so that a check that could not be made is never counted as passed. The
default part runs everything else. A part of the kernel checks that the CPU or the library
cannot exercise is listed as skipped in the summary line.
"""
import argparse
import json
import os
import subprocess
import sys

# variables a BLAS reads for its thread count (removed for the default run)
THREAD_VARIABLES = ["FETICONTACT_BLAS_THREADS", "OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "BLIS_NUM_THREADS",
                    "MKL_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_CORETYPE"]
FAILURES = []
PASSED = []
SKIPPED = []


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
    # the program's whole log (run_case.py prints only its tail; the BLAS line is near the top)
    try:
        with open(os.path.join(workdir, "log.txt")) as f:
            return workdir, f.read()
    except OSError:
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
    for key, kind in [("library", str), ("path", str), ("threads", int), ("source", str), ("multithreaded", bool),
                      ("core", str), ("core_chosen_by_library", str)]:
        check(isinstance(blas.get(key), kind), "%s: blas.%s is a %s" % (name, key, kind.__name__))
    return blas


def cpu_flags():
    """The instruction-set flags of the first CPU in /proc/cpuinfo (empty set when unreadable)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def check_kernels(args, blas, out):
    """OpenBLAS's kernel table: chosen again only from the generic one, never against the user."""
    if not blas.get("library", "").startswith("OpenBLAS"):
        check(blas["core"] == "", "default: blas.core is empty for %s (got %r)" % (blas["library"], blas["core"]))
        return
    flags = cpu_flags()
    avx512 = {"avx512f", "avx512cd", "avx512dq", "avx512bw", "avx512vl"} <= flags
    avx2 = {"avx2", "fma"} <= flags
    core, before = blas["core"], blas["core_chosen_by_library"]
    print("OpenBLAS kernels: %r (chosen by the library: %r); CPU AVX2+FMA %s, AVX-512 %s" % (core, before, avx2, avx512))
    check(core != "", "default: blas.core names OpenBLAS's kernels")
    check(("kernels " + core) in out, "default: the log's BLAS line names the kernels %s" % core)
    if before:
        check(before == "Prescott", "default: chosen again only from the generic Prescott (got %r)" % before)
        check(core == ("SkylakeX" if avx512 else "Haswell"),
              "default: the kernels chosen again match the CPU (got %r, AVX-512 %s)" % (core, avx512))
        check("OpenBLAS chose its generic Prescott kernels" in out, "default: the log says the kernels were chosen again")

    # the user's OPENBLAS_CORETYPE is kept, even the generic one
    workdir, out = run(args, "user_prescott", {"OPENBLAS_CORETYPE": "Prescott"}, ["--check", "report"])
    user = blas_of(workdir, "user_prescott")
    if user:
        check(user["core"] == "Prescott" and user["core_chosen_by_library"] == "",
              "user_prescott: OPENBLAS_CORETYPE=Prescott kept (core %r, chosen again from %r)"
              % (user["core"], user["core_chosen_by_library"]))
    if not avx2:
        SKIPPED.append("OPENBLAS_CORETYPE=Haswell and the default's kernels: the CPU has no AVX2 and FMA")
        return
    workdir, out = run(args, "user_haswell", {"OPENBLAS_CORETYPE": "Haswell"}, ["--check", "report"])
    user = blas_of(workdir, "user_haswell")
    if user and user["core"] == "Haswell":
        # the library chooses its kernels at run time: the default must not be the generic table
        check(core != "Prescott", "default: a CPU with AVX2 and FMA does not run the generic Prescott kernels")
    elif user:
        SKIPPED.append("the default's kernels: OPENBLAS_CORETYPE=Haswell gave %r (a build without run-time "
                       "choice)" % user["core"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--run-case", required=True)
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--input", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--timeout", type=int, default=300)
    ap.add_argument("--part", choices=["main", "threads"], default="main")
    args = ap.parse_args()
    if args.part == "threads":
        main_threads(args)

    # 1. default: one thread per rank, and the log line says so
    workdir, out = run(args, "default", {}, ["--check", "report"])
    blas = blas_of(workdir, "default")
    if blas:
        print("BLAS found: %s (%s), multithreaded: %s" % (blas["library"], blas["path"], blas["multithreaded"]))
        check(blas["threads"] == 1, "default: blas.threads == 1 (got %s)" % blas["threads"])
        check(blas["source"] == "default", "default: blas.source == 'default' (got %r)" % blas["source"])
    check("BLAS: " in out and "1 thread per rank (default" in out, "default: the log has the BLAS line")
    if blas:
        check_kernels(args, blas, out)

    # 2. an invalid value: exit status 2 from every rank, a message naming the variable
    run(args, "invalid", {"FETICONTACT_BLAS_THREADS": "abc"},
        ["--expect-exit", "2", "--expect-message", "FETICONTACT_BLAS_THREADS='abc' is not a positive integer"])

    for what in SKIPPED:
        print("skipped: " + what)
    print("%d passed, %d failed, %d skipped" % (len(PASSED), len(FAILURES), len(SKIPPED)))
    check(len(PASSED) > 0, "some checks ran")
    sys.exit(1 if FAILURES else 0)


def main_threads(args):
    """FETICONTACT_BLAS_THREADS=2: 2 threads where the BLAS can thread; else 1 reported, and skipped."""
    workdir, out = run(args, "threads2", {"FETICONTACT_BLAS_THREADS": "2"}, ["--check", "report"])
    blas = blas_of(workdir, "threads2")
    skipped = None
    if blas:
        check(blas["source"] == "FETICONTACT_BLAS_THREADS", "threads2: blas.source names the variable")
        if blas["multithreaded"]:
            check(blas["threads"] == 2, "threads2: blas.threads == 2 (got %s)" % blas["threads"])
        else:
            check(blas["threads"] == 1, "threads2: a single-threaded BLAS reports 1 thread (got %s)" % blas["threads"])
            skipped = ("blas.threads == 2 with FETICONTACT_BLAS_THREADS=2: the loaded BLAS is single-threaded: "
                       "%s (%s)" % (blas["library"], blas["path"]))
    print("%d passed, %d failed" % (len(PASSED), len(FAILURES)))
    if FAILURES or not PASSED:
        sys.exit(1)
    if skipped:
        print("SKIPPED: " + skipped)
        sys.exit(77)
    sys.exit(0)


if __name__ == "__main__":
    main()
