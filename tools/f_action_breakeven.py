#!/usr/bin/python3
"""Break-even count of the explicit local dual operators (`&solver f_action`).

    tools/f_action_breakeven.py [--ranks P] [--reps R] [--program BIN] [--out DIR] CASE [CASE ...]

CASE is NAME=INPUT[@group:variable=value[@...]]: a namelist file and settings merged into
it (as tools/campaign.py --set does), e.g.

    d2_n6=inputs/hard/distortion_02.nml@mesh:nel=6,6,6

Every case runs with f_action = 'implicit' and 'explicit', interleaved (rep 1: implicit,
explicit; rep 2: ...), from its own folder DIR/<name>_<f_action>_<rep>/, and the medians
over the repetitions give one Markdown row per case:

- ratio: the 'auto' cost model's build flops / bytes saved per action, from the log line
  `F action (auto): ...` of the run with the default setting (- where the subdomains are
  shared per class: the model of that path has no ratio);
- F actions: report.json solver.f_applications (set-up, solve and reconstruction);
- the totals and the F action times of the two runs and the time of the build
  (timer 'explicit F' of the explicit run);
- break-even: build time / saving per action, saving = (implicit - explicit F action
  time) / F actions: the number of F actions after which the build has paid for itself;
- what `f_action = 'auto'` does: the program's own choice in a third run with the
  default setting (report.json performance.f_action and f_explicit_after), and that
  run's total time (one run, after the repetitions of the two others).

Example (docs/RESULTS.md "Deferred explicit F"):
    tools/f_action_breakeven.py --reps 3 --out output/f_action \\
        d2_n4=inputs/hard/distortion_02.nml d2_n6=inputs/hard/distortion_02.nml@mesh:nel=6,6,6

Python: /usr/bin/python3, standard library only. Exit status 0 when every run converged.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from campaign import merge_overrides, parse_namelist, parse_override, write_namelist  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def parse_case(text):
    """'NAME=INPUT[@g:v=x[@...]]' -> (name, input path, [(g, v, x), ...])."""
    name, sep, rest = text.partition("=")
    if not sep or not re.match(r"^[A-Za-z0-9_.-]+$", name):
        raise argparse.ArgumentTypeError("expected NAME=INPUT[@group:variable=value...], got %r" % text)
    parts = rest.split("@")
    return name, parts[0], [parse_override(p) for p in parts[1:]]


def run(program, mpiexec, ranks, input_path, overrides, run_dir):
    """One run in run_dir; returns (report or None, log text, exit status)."""
    os.makedirs(run_dir, exist_ok=True)
    with open(input_path) as f:
        groups = parse_namelist(f.read())
    groups = merge_overrides(groups, overrides + [("output", "directory", "'out'"),
                                                  ("output", "write_hdf5", ".false.")])
    write_namelist(groups, os.path.join(run_dir, "case.nml"))
    cmd = [mpiexec, "--oversubscribe", "-n", str(ranks), program, "case.nml"]
    p = subprocess.run(cmd, cwd=run_dir, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with open(os.path.join(run_dir, "log.txt"), "w") as f:
        f.write(p.stdout)
    report = None
    path = os.path.join(run_dir, "out", "report.json")
    if os.path.exists(path):
        with open(path) as f:
            report = json.load(f)
    return report, p.stdout, p.returncode


def timer(report, name):
    return report["timings"].get(name, {}).get("max", 0.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("cases", nargs="+", type=parse_case, metavar="CASE")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--program", default=os.path.join(ROOT, "build-release", "bin", "feticontact"))
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--out", default="output/f_action_breakeven")
    args = ap.parse_args()
    if not os.path.exists(args.program):
        ap.error("no program %s (build it, or give --program)" % args.program)
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    out = os.path.abspath(args.out)
    status = 0
    rows = []
    for name, input_path, overrides in args.cases:
        input_path = os.path.abspath(input_path)
        runs = {"implicit": [], "explicit": []}
        ratio = None
        for rep in range(1, args.reps + 1):
            for fa in ("implicit", "explicit"):
                report, log, rc = run(args.program, args.mpiexec, args.ranks, input_path,
                                      overrides + [("solver", "f_action", "'%s'" % fa)],
                                      os.path.join(out, "%s_%s_%d" % (name, fa, rep)))
                if rc != 0 or report is None or not report["solver"]["converged"]:
                    print("%s (%s, rep %d): exit %d" % (name, fa, rep, rc), file=sys.stderr)
                    status = 1
                    continue
                runs[fa].append(report)
        report, log, rc = run(args.program, args.mpiexec, args.ranks, input_path, overrides,
                              os.path.join(out, "%s_auto" % name))
        m = re.search(r"build/saving\s+([0-9.]+)", log)
        if m:
            ratio = float(m.group(1))
        auto_total = float("nan")
        if rc != 0 or report is None:
            status = 1
            auto = "exit %d" % rc
        else:
            auto_total = timer(report, "total")
            after = report["performance"].get("f_explicit_after", -1)
            if report["performance"]["f_action"] == "explicit":
                auto = "explicit after %d actions" % after if after >= 0 else "explicit from the start"
            else:
                auto = "implicit"
        if not runs["implicit"] or not runs["explicit"]:
            continue
        med = lambda fa, f: statistics.median(f(r) for r in runs[fa])  # noqa: E731
        acts = med("implicit", lambda r: r["solver"]["f_applications"])
        t_i, t_e = med("implicit", lambda r: timer(r, "total")), med("explicit", lambda r: timer(r, "total"))
        f_i, f_e = med("implicit", lambda r: timer(r, "F action")), med("explicit", lambda r: timer(r, "F action"))
        build = med("explicit", lambda r: timer(r, "explicit F"))
        saving = (f_i - f_e)/acts
        breakeven = build/saving if saving > 0 else float("inf")
        rows.append("| %s | %s | %d | %d | %.3f / %.3f | %.4f / %.4f | %.3f | %.0f | %s | %s | %.3f |" % (
            name, "%.1f" % ratio if ratio else "-", runs["implicit"][0]["solver"]["hessian_multiplications"],
            acts, t_i, t_e, f_i, f_e, build, breakeven,
            "%.2f" % (breakeven/ratio) if ratio else "-", auto, auto_total))
    print("| case | ratio [flop/byte] | Hessian | F actions | total implicit / explicit [s] | "
          "F action implicit / explicit [s] | build [s] | break-even [actions] | break-even / ratio | 'auto' | "
          "'auto' total [s] (one run) |")
    print("|---|---:|---:|---:|---|---|---:|---:|---:|---|---:|")
    for r in rows:
        print(r)
    return status


if __name__ == "__main__":
    sys.exit(main())
