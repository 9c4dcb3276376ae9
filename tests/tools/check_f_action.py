#!/usr/bin/python3
"""tools/f_action_breakeven.py on two small distorted cubes (1 rank, 1 repetition) and, through
it, `f_action = 'auto'`'s deferred build end to end: a run that makes fewer F actions than the
model's break-even estimate N = round(ratio) stays implicit, one that makes more switches to the
explicit operators after N actions (report.json performance.f_explicit_after; N within the
table's rounding of the ratio), and both converge with either f_action. The table's numbers are the tool's arithmetic on the reports.
"""
import argparse
import os
import shutil
import re
import subprocess
import sys

ap = argparse.ArgumentParser()
ap.add_argument("--program", required=True)
ap.add_argument("--mpiexec", default="mpiexec")
ap.add_argument("--workdir", required=True)
args = ap.parse_args()
shutil.rmtree(args.workdir, ignore_errors=True)   # no stale outputs of an earlier run
os.makedirs(args.workdir)
root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
base = os.path.join(root, "inputs", "hard", "distortion_02.nml")
cases = ["short=%s@mesh:nsub=2,2,2@mesh:nel=6,6,6" % base,
         # nearly incompressible and a tight tolerance: many more F actions than N
         "long=%s@mesh:nsub=2,2,2@mesh:nel=4,4,4@material:poisson=0.499@solver:tol=1e-10@solver:preconditioner='none'" % base]
p = subprocess.run([sys.executable, os.path.join(root, "tools", "f_action_breakeven.py"), "--ranks", "1",
                    "--reps", "1", "--program", args.program, "--mpiexec", args.mpiexec,
                    "--out", args.workdir] + cases, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
print(p.stdout)
failures = []
if p.returncode != 0:
    failures.append("the tool exited %d (a run did not converge)" % p.returncode)
rows = {}
for line in p.stdout.splitlines():
    cells = [c.strip() for c in line.strip().strip("|").split("|")]
    if len(cells) == 11 and cells[0] in ("short", "long"):
        rows[cells[0]] = cells
for name in ("short", "long"):
    if name not in rows:
        failures.append("no row for %s" % name)
        continue
    c = rows[name]
    ratio, actions, auto = float(c[1]), int(c[3]), c[9]
    n = max(1, round(ratio))
    # the auto run may differ from the implicit one by an action or two after the switch
    if abs(actions - n) <= 5:
        failures.append("%s: %d F actions, too close to N = %d to tell" % (name, actions, n))
    elif actions < n:
        if auto != "implicit":
            failures.append("%s: %d F actions <= N = %d, but 'auto' did %r" % (name, actions, n, auto))
    else:
        # N = nint(ratio) in the program; the table prints ratio to one decimal
        m = re.match(r"explicit after (\d+) actions", auto)
        if not m or abs(int(m.group(1)) - max(1.0, ratio)) > 0.55:
            failures.append("%s: %d F actions > N = %d, but 'auto' did %r" % (name, actions, n, auto))
    if not float(c[7]) > 0:
        failures.append("%s: no positive build time" % name)
if "short" in rows and not int(rows["short"][3]) < max(1, round(float(rows["short"][1]))):
    failures.append("the short case made no fewer F actions than N: it does not test the implicit path")
if "long" in rows and not int(rows["long"][3]) > max(1, round(float(rows["long"][1]))):
    failures.append("the long case made no more F actions than N: it does not test the switch")
for f in failures:
    print("FAIL:", f)
print("%d passed, %d failed" % (1 if not failures else 0, 1 if failures else 0))
sys.exit(1 if failures else 0)
