#!/usr/bin/env python3
"""Mutation testing on demand (not in CI): does the test suite catch deliberate one-line faults?

Each fault of a list (tools/mutations.txt: `label | file | exact text | replacement`, the exact
text occurring exactly once in the file) is applied alone to a scratch copy of the source tree,
the scratch build is rebuilt (incremental, Release by default), a chosen CTest selection runs,
and the file is restored. A fault is *caught* when a test of the selection that passes on the
unmutated tree fails with it; it *survives* otherwise; a fault that does not compile is reported
as such (not a valid fault). The scratch copy (default feticontact-mutate in the system's temporary folder) is made from the
files git tracks in the working tree (committed or not) and kept between runs, so that a second
run rebuilds only what a fault touches.

    tools/mutate.py -R 'app_reference|app_block_exact' --target feticontact
    tools/mutate.py --only 'feti_.*gap' -L app -LE cluster --report mutate.json
    tools/mutate.py --list                       # the faults, nothing run
    tools/mutate.py --stop-on-failure ...        # a fault's tests end at the first that fails

Writes a JSON report (--report) and prints one line per fault as it goes, then a table of the
caught faults (with the tests that caught each) and the survivors.
"""
import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def read_faults(path):
    faults = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            parts = [p.strip() for p in line.rstrip("\n").split(" | ")]
            if len(parts) != 4 or not all(parts[:3]):
                sys.exit("%s:%d: expected 'label | file | exact text | replacement'" % (path, number))
            faults.append(dict(label=parts[0], file=parts[1], find=parts[2], replace=parts[3], line=number))
    labels = [f["label"] for f in faults]
    dup = sorted({l for l in labels if labels.count(l) > 1})
    if dup:
        sys.exit("%s: labels used twice: %s" % (path, ", ".join(dup)))
    return faults


def check_faults(faults, root):
    """Every exact text occurs once in its file of `root` (else the list is stale)."""
    bad = []
    for f in faults:
        path = os.path.join(root, f["file"])
        if not os.path.isfile(path):
            bad.append("%s: no file %s" % (f["label"], f["file"]))
            continue
        with open(path) as h:
            n = h.read().count(f["find"])
        if n != 1:
            bad.append("%s: the text occurs %d times in %s" % (f["label"], n, f["file"]))
    return bad


def sync_scratch(scratch):
    """Copy the tracked files of the working tree into `scratch`, rewriting only those that
    differ (so the scratch build stays incremental)."""
    files = subprocess.run(["git", "-C", REPO, "ls-files", "-z"], check=True, capture_output=True).stdout
    copied = 0
    for rel in files.decode().split("\0"):
        if not rel:
            continue
        src = os.path.join(REPO, rel)
        dst = os.path.join(scratch, rel)
        if not os.path.isfile(src):
            continue
        with open(src, "rb") as h:
            data = h.read()
        if os.path.isfile(dst):
            with open(dst, "rb") as h:
                if h.read() == data:
                    continue
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        shutil.copyfile(src, dst)           # a new mtime: the build sees the change
        copied += 1
    return copied


def run(cmd, log, timeout=None, cwd=None):
    with open(log, "a") as out:
        out.write("\n$ %s\n" % " ".join(cmd))
        out.flush()
        try:
            r = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, timeout=timeout, cwd=cwd)
            return r.returncode
        except subprocess.TimeoutExpired:
            out.write("timed out after %s s\n" % timeout)
            return 124


def ctest(build, selection, jobs, timeout, log, stop=False):
    """Run the selection; returns (names of the tests run, names of those that failed)."""
    junit = os.path.join(build, "mutate-junit.xml")
    if os.path.exists(junit):
        os.remove(junit)
    cmd = ["ctest", "--test-dir", build, "-j", str(jobs), "--timeout", str(timeout), "--output-junit", junit]
    cmd += selection + (["--stop-on-failure"] if stop else [])
    run(cmd, log)
    ran, failed = [], []
    if os.path.exists(junit):
        text = open(junit).read()
        for m in re.finditer(r'<testcase name="([^"]+)"[^>]*status="(\w+)"', text):
            ran.append(m.group(1))
            if m.group(2) == "fail":            # CTest's JUnit: "run" passed, "notrun"/"disabled" skipped
                failed.append(m.group(1))
    return ran, failed


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mutations", default=os.path.join(HERE, "mutations.txt"))
    ap.add_argument("--only", help="regex: only the faults whose label matches")
    ap.add_argument("--list", action="store_true", help="list the faults and check them, run nothing")
    ap.add_argument("--scratch", default=os.path.join(tempfile.gettempdir(), "feticontact-mutate"),
                    help="scratch copy of the tree")
    ap.add_argument("--build-type", default="Release")
    ap.add_argument("--target", action="append", default=[], help="build only these targets (repeatable)")
    ap.add_argument("--jobs", type=int, default=2, help="build jobs")
    ap.add_argument("--ctest-jobs", type=int, default=2)
    ap.add_argument("--timeout", type=int, default=300, help="per test [s]")
    ap.add_argument("-R", dest="R"), ap.add_argument("-E", dest="E")
    ap.add_argument("-L", dest="L"), ap.add_argument("-LE", dest="LE")
    ap.add_argument("--stop-on-failure", action="store_true",
                    help="end a fault's CTest run at its first failing test (faster; names one catcher)")
    ap.add_argument("--report", default=None, help="JSON report (default <scratch>/mutate-report.json)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the unmutated run (assume all pass)")
    args = ap.parse_args()

    # SIGTERM (and SIGINT, which a background job ignores otherwise) end the run through the
    # `finally` that restores the mutated file; a copy left mutated is restored by the next sync
    def stop(signum, frame):
        raise KeyboardInterrupt("signal %d" % signum)
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    faults = read_faults(args.mutations)
    if args.only:
        faults = [f for f in faults if re.search(args.only, f["label"])]
    bad = check_faults(faults, REPO)
    if args.list or bad:
        for f in faults:
            print("%-32s %s" % (f["label"], f["file"]))
        folders = sorted({f["file"].split("/")[1] for f in faults})
        print("%d faults over %d src folders: %s" % (len(faults), len(folders), " ".join(folders)))
        for b in bad:
            print("STALE: " + b)
        sys.exit(1 if bad else 0)

    selection = []
    for opt in ("R", "E", "L", "LE"):
        if getattr(args, opt):
            selection += ["-" + opt, getattr(args, opt)]
    scratch = os.path.abspath(args.scratch)
    build = os.path.join(scratch, "build-" + args.build_type.lower())
    os.makedirs(scratch, exist_ok=True)
    log = os.path.join(scratch, "mutate.log")
    report_path = args.report or os.path.join(scratch, "mutate-report.json")
    print("scratch %s: %d files copied" % (scratch, sync_scratch(scratch)), flush=True)
    if not os.path.exists(os.path.join(build, "CMakeCache.txt")):
        rc = run(["cmake", "-S", scratch, "-B", build, "-G", "Ninja", "-DCMAKE_BUILD_TYPE=" + args.build_type,
                  "-DFETICONTACT_TESTS=ON"], log)
        if rc:
            sys.exit("configure failed, see " + log)
    build_cmd = ["cmake", "--build", build, "-j", str(args.jobs)]
    for t in args.target:
        build_cmd += ["--target", t]
    t0 = time.time()
    if run(build_cmd, log):
        sys.exit("the unmutated scratch tree does not build, see " + log)
    print("unmutated build %.0f s" % (time.time() - t0), flush=True)
    baseline_failed = []
    if not args.no_baseline:
        t0 = time.time()
        ran, baseline_failed = ctest(build, selection, args.ctest_jobs, args.timeout, log)
        if not ran:
            sys.exit("the selection %s runs no test" % selection)
        print("baseline: %d tests, %d failing (%s), %.0f s" % (len(ran), len(baseline_failed),
              " ".join(baseline_failed), time.time() - t0), flush=True)

    results = []
    for f in faults:
        path = os.path.join(scratch, f["file"])
        with open(path) as h:
            original = h.read()
        if original.count(f["find"]) != 1:
            sys.exit("%s: the scratch copy of %s is not pristine" % (f["label"], f["file"]))
        t0 = time.time()
        try:
            with open(path, "w") as h:
                h.write(original.replace(f["find"], f["replace"]))
            if run(build_cmd, log):
                status, caught_by, ran = "does not compile", [], []
            else:
                ran, failed = ctest(build, selection, args.ctest_jobs, args.timeout, log, args.stop_on_failure)
                caught_by = [t for t in failed if t not in baseline_failed]
                status = "caught" if caught_by else "survived"
        finally:
            with open(path, "w") as h:
                h.write(original)
        res = dict(f, status=status, caught_by=caught_by, tests_run=len(ran), seconds=round(time.time() - t0, 1))
        results.append(res)
        print("%-32s %-16s %5.0f s  %s" % (f["label"], status, res["seconds"], " ".join(caught_by)), flush=True)
        with open(report_path, "w") as h:
            json.dump(dict(selection=selection, baseline_failed=baseline_failed, results=results), h, indent=1)
    run(build_cmd, log)                          # leave the scratch build unmutated

    caught = [r for r in results if r["status"] == "caught"]
    survived = [r for r in results if r["status"] == "survived"]
    print("\n%d faults: %d caught, %d survived, %d do not compile (selection %s)"
          % (len(results), len(caught), len(survived), len(results) - len(caught) - len(survived),
             " ".join(selection) or "all"))
    for r in survived:
        print("SURVIVED %-32s %s: %s -> %s" % (r["label"], r["file"], r["find"], r["replace"]))
    print("report: " + report_path)


if __name__ == "__main__":
    main()
