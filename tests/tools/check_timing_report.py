#!/usr/bin/python3
"""CTest check of what a user reads around the numbers of a run: the timing
table and its JSON, the memory table, tools/campaign.py's set-up column and
where tools/plots.py writes its figures.

    check_timing_report.py --program feticontact --mpiexec mpiexec --workdir DIR [--ranks 2]

Runs inputs/cube.nml (the default case) once, its output in DIR, and checks:
- report.json timings: the flat members (min <= mean <= max) and the tree under
  "total": at every level the parts and "other" add up to their parent and the
  top-level shares to 1; a name's flat mean is the sum of its rows in the tree;
- the log's timing table: the top-level shares add up to 100 % (within the
  rounding of the printed shares), 'total' last at 100.0 %, parts indented; the
  memory table with a row per memory mark of report.json;
- tools/campaign.py: the CSV row of the run has a set-up time that includes
  'explicit F' (and every other top-level set-up phase), also for a report
  without the tree (older runs);
- tools/plots.py without --figures writes next to the data (hertz: the run's
  folder; weak: the campaign folder), run from another folder by its absolute
  path, and leaves docs/figures alone; its Hertz table counts the nodes in
  contact as the log does.
Exit 0 when all pass.
"""
import argparse
import csv
import hashlib
import json
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
TOOLS = os.path.join(ROOT, "tools")
FIGURES = os.path.join(ROOT, "docs", "figures")
FAILURES = []

sys.path.insert(0, TOOLS)
import campaign  # noqa: E402


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    if not condition:
        FAILURES.append(what)


def close(a, b, rel=1e-9):
    return abs(a - b) <= rel * max(abs(a), abs(b), 1e-300)


def figures_state():
    """{file: sha256} of docs/figures."""
    out = {}
    if os.path.isdir(FIGURES):
        for f in sorted(os.listdir(FIGURES)):
            with open(os.path.join(FIGURES, f), "rb") as fh:
                out[f] = hashlib.sha256(fh.read()).hexdigest()
    return out


def tree_rows(node, path=()):
    """(path, node) of every node below `node` (its "children", depth first)."""
    for c in node.get("children", []):
        yield path + (c["name"],), c
        yield from tree_rows(c, path + (c["name"],))


def check_json(report):
    t = report.get("timings", {})
    for name, s in t.items():
        check(isinstance(s, dict) and s["min"] <= s["mean"] * (1 + 1e-12) and s["mean"] <= s["max"] * (1 + 1e-12),
              "timings.%s: min <= mean <= max" % name)
    total = t.get("total", {})
    children = total.get("children", [])
    check(len(children) >= 3 and children[-1]["name"] == "other", "timings.total.children: the phases, then other")
    check(close(sum(c["mean"] for c in children), total["mean"]),
          "top-level phases + other add up to the total (%.9f vs %.9f)" % (sum(c["mean"] for c in children),
                                                                         total["mean"]))
    check(close(sum(c["share"] for c in children), 1.0), "top-level shares add up to 1")
    check(all(c["mean"] >= -1e-12 for c in children), "no negative top-level row")
    for path, node in tree_rows(total):
        if node.get("children"):
            parts = sum(c["mean"] for c in node["children"])
            check(close(parts, node["mean"], 1e-9) and node["children"][-1]["name"] == "other",
                  "parts of %s + other add up to it" % " > ".join(path))
    names = {}
    for path, node in tree_rows(total):
        if node["name"] != "other" and node["name"] not in path[:-1]:
            names[node["name"]] = names.get(node["name"], 0.0) + node["mean"]
    for name, mean in names.items():
        if name in t:
            check(close(mean, t[name]["mean"], 1e-9), "flat %s = the sum of its rows in the tree" % name)
    where = {}
    for path, node in tree_rows(total):
        where.setdefault(node["name"], []).append(" > ".join(path[:-1]) or "total")
    two = {n: w for n, w in where.items() if n != "other" and len(w) > 1}
    print("names under more than one parent:", two)
    top = [c["name"] for c in children]
    for phase in ("mesh", "assembly", "factorization", "solve", "output"):
        check(phase in top, "%s is a top-level phase" % phase)
    check("F action" not in top and "coarse solve" not in top, "F action and coarse solve are parts, not phases")
    return children


def check_log(log, report):
    lines = log.splitlines()
    head = [i for i, ln in enumerate(lines) if re.match(r"phase\s+min \[s\]\s+max \[s\]\s+mean \[s\]\s+share", ln)]
    check(len(head) == 1, "one timing table in the log")
    if not head:
        return
    rows, i = [], head[0] + 1
    while i < len(lines) and not lines[i].startswith("-----"):
        rows.append(lines[i])
        i += 1
    total_line = lines[i + 1] if i + 1 < len(lines) else ""
    print("\n".join(lines[head[0]:i + 3]))
    top = [ln for ln in rows if not ln.startswith(" ")]
    shares = [float(ln.rsplit(None, 1)[-1].rstrip("%")) for ln in top]
    check(abs(sum(shares) - 100.0) <= 0.05 * len(shares) + 1e-9,
          "printed top-level shares add up to 100 %% (%.1f over %d rows)" % (sum(shares), len(shares)))
    check(top and top[-1].startswith("other "), "the last top-level row is other")
    check(total_line.startswith("total ") and total_line.endswith("100.0%"), "total last, 100.0%")
    check(any(ln.startswith("  ") for ln in rows), "parts indented under their phase")
    marks = [m["name"] for m in report.get("memory", {}).get("phases", [])]
    mem = [i for i, ln in enumerate(lines) if ln.startswith("Memory at the end of each phase")]
    check(len(mem) == 1, "the memory table in the log")
    if mem and marks:
        table = lines[mem[0] + 2:mem[0] + 2 + len(marks)]
        check([ln[:len(m)] for ln, m in zip(table, marks)] == marks, "a memory row per mark, in order")
        peak = {m["name"]: m["peak_max"] for m in report["memory"]["phases"]}
        for ln, m in zip(table, marks):
            logged = float(ln[len(m):].split()[0])
            check(abs(logged - peak[m] / 2**20) <= 0.051, "memory %s: log %.1f MiB = report.json" % (m, logged))


def check_campaign_setup(report, children):
    row = campaign.with_setup(campaign.report_row(report))
    top = {c["name"]: c for c in children}
    check("explicit F" in top, "explicit F is a top-level phase of the default case")
    setup = float(row.get("setup") or "nan")
    expected = sum(top[p]["max"] for p in campaign.setup_phases(report))
    check("explicit F" in campaign.setup_phases(report), "campaign's set-up phases include explicit F")
    check(close(setup, expected, 1e-6), "campaign setup = the sum of the set-up phases (%g vs %g)" % (setup, expected))
    if "explicit F" in top:
        check(setup >= top["explicit F"]["max"], "campaign setup >= explicit F")
    # a report without the tree (before it existed): the flat phases, explicit F included
    flat = json.loads(json.dumps(report))
    flat["timings"]["total"].pop("children", None)
    row = campaign.with_setup(campaign.report_row(flat))
    t = flat["timings"]
    expected = sum(t[p]["max"] for p in campaign.SETUP_PHASES if p in t)
    check(close(float(row.get("setup") or "nan"), expected, 1e-6) and "explicit F" in campaign.SETUP_PHASES,
          "without the tree: setup = the flat set-up phases, explicit F included")
    return row


def check_plots(args, out, report, row):
    before = figures_state()
    elsewhere = os.path.join(args.workdir, "elsewhere")
    os.makedirs(elsewhere, exist_ok=True)
    png = os.path.join(out, "hertz.png")
    if os.path.exists(png):
        os.remove(png)
    p = subprocess.run(["/usr/bin/python3", os.path.join(TOOLS, "plots.py"), "hertz", out], cwd=elsewhere,
                       capture_output=True, text=True, timeout=120)
    print(p.stdout[-3000:], p.stderr[-2000:])
    check(p.returncode == 0, "plots.py hertz exits 0 from another folder")
    check(os.path.exists(png) and os.path.getsize(png) > 1000, "hertz.png written next to the run's data")
    check(not os.path.exists(os.path.join(elsewhere, "hertz.png")), "nothing written in the current folder")
    m = re.search(r"\| nodes in contact \(p > 0\) \| \| (\d+) \|", p.stdout)
    active = report["contact"]["active_nodes"]
    check(m is not None and int(m.group(1)) == active,
          "plots.py counts the nodes in contact as the log does (%s vs %d)" % (m.group(1) if m else None, active))

    camp = os.path.join(args.workdir, "campaign")
    os.makedirs(camp, exist_ok=True)
    rows = [dict(row, member="cube", ranks=str(args.ranks), rep=str(k), exit_status="0") for k in (1, 2)]
    cols = list(dict.fromkeys(k for r in rows for k in r))
    with open(os.path.join(camp, "campaign.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    for name in ("weak_iterations.png", "weak_times.png"):
        if os.path.exists(os.path.join(camp, name)):
            os.remove(os.path.join(camp, name))
    p = subprocess.run(["/usr/bin/python3", os.path.join(TOOLS, "plots.py"), "weak", camp], cwd=elsewhere,
                       capture_output=True, text=True, timeout=120)
    print(p.stdout[-3000:], p.stderr[-2000:])
    check(p.returncode == 0, "plots.py weak exits 0")
    for name in ("weak_iterations.png", "weak_times.png"):
        check(os.path.exists(os.path.join(camp, name)), "%s written next to the campaign" % name)
    head = [ln for ln in p.stdout.splitlines() if ln.startswith("| family |")]
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("| campaign |")]
    check(bool(head) and bool(line), "plots.py weak prints its table")
    if head and line:
        cells = dict(zip([c.strip() for c in head[0].split("|")], [c.strip() for c in line[0].split("|")]))
        # the set-up column leaves the factorization to its own column: the two add up to the
        # campaign's set-up (explicit F included), and the rows before the total are disjoint
        setup = [v for k, v in cells.items() if k.startswith("set-up") and "explicit F" in k]
        fact = [v for k, v in cells.items() if k.startswith("factorization")]
        both = float(setup[0]) + float(fact[0]) if setup and fact else None
        check(both is not None and abs(both - float(row["setup_max"])) <= 0.01 * float(row["setup_max"]),
              "the set-up and factorization columns add up to campaign's setup, explicit F included (%s + %s vs %s)"
              % (setup, fact, row["setup_max"]))
    check(figures_state() == before, "docs/figures unchanged")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--ranks", type=int, default=2)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    out = os.path.join(args.workdir, "cube")
    with open(os.path.join(ROOT, "inputs", "cube.nml")) as f:
        text = f.read()
    text = re.sub(r"directory = '[^']*'", "directory = '%s'" % out, text)
    nml = os.path.join(args.workdir, "cube.nml")
    with open(nml, "w") as f:
        f.write(text)
    cmd = [args.mpiexec, "--oversubscribe", "--bind-to", "none", "-n", str(args.ranks), args.program, nml]
    print("running:", " ".join(cmd))
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=args.workdir)
    print(run.stdout[-2000:], run.stderr[-2000:])
    check(run.returncode == 0, "the cube run exits 0 (got %d)" % run.returncode)
    report_path = os.path.join(out, "report.json")
    if run.returncode != 0 or not os.path.exists(report_path):
        print("%d failed" % len(FAILURES))
        return 1
    with open(report_path) as f:
        report = json.load(f)
    children = check_json(report)
    check_log(run.stdout, report)
    row = check_campaign_setup(report, children)
    check_plots(args, out, report, row)
    print("%d failed" % len(FAILURES))
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
