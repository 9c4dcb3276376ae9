#!/usr/bin/python3
"""The limits written in docs/INPUT.md are the ones the program enforces.

    check_documented_limits.py --program feticontact --docs docs/INPUT.md --workdir DIR

Reads the "allowed" column of every table row "| `name` | meaning | default | allowed |" under
"## &group" headings and, for the forms it knows (`> a`, `>= a`, `each > a`, `each >= a`,
`(a, b)`, `[a, b)`, `(a, b]`, `[a, b]`, `a ... b`, `>= a Lz`, a list of quoted strings), probes the
boundary with `feticontact --check` (the checks of a run, no solve), started directly (an MPI
singleton):
- just outside each documented bound (the bound itself where it is excluded, bound -/+ delta where
  it is included; delta = 1e-6 max(|bound|, 1), 1 for integers), and an unknown string, one run
  each: exit status 2 and a message naming "group &G, variable V";
- just inside every bound, all in one input: exit status 0.
Rows of other forms (any, logical, conditions on other variables) are listed as not probed; at
least MIN_PROBED rows must be probed, so a rewrite of the table cannot pass vacuously.
"""
import argparse
import concurrent.futures
import os
import re
import subprocess
import sys

MIN_PROBED = 40
# integer variables (an integer bound is probed with +-1)
INTEGERS = {"nsub", "nel", "distortion_seed", "seed", "nsteps", "max_outer", "max_hessian", "rho_window",
            "lanczos_steps", "lanczos_setup_steps", "polish_window", "polish_rounds", "polish_max", "polish_predict", "coarse_ranks",
            "metis_block", "cluster"}
VECTORS = {"nsub", "nel", "lengths", "cluster", "top_displacement"}
# not namelist variables (environment rows), and the lists of &history whose limits need other
# variables set (tests/app/check_history.py `bad` refuses each)
SKIP_GROUPS = {"reconstruction": {"FETICONTACT_BLAS_THREADS", "OPENBLAS_CORETYPE"},
               "history": {"load_factors", "gaps"}}
NUM = r"(-?[0-9.]+(?:e-?[0-9]+)?)"

FAILURES = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        FAILURES.append(what)


def documented_rows(path):
    group, rows = None, []
    for line in open(path):
        m = re.match(r"## &(\w+)", line)
        if m:
            group = m.group(1)
            continue
        if line.startswith("## "):
            group = None
        if group and line.startswith("| `"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            name = cells[0].strip("`")
            if len(cells) >= 4 and name not in SKIP_GROUPS.get(group, ()):
                rows.append((group, name, cells[-1]))
    return rows


def bounds(rule):
    """[(value, 'lower'|'upper', included)] of a numeric rule, or None; or ('strings', [...])."""
    r = rule.split(";")[0].replace("each ", "").strip()     # "; ..." adds a condition on other variables
    r = re.sub(r"\s*\((deeper exits 2|at most \d+ subdomains)\)", "", r)
    m = re.fullmatch(r"(>=?)\s*" + NUM + r"(\s*Lz)?", r)
    if m:
        return [(float(m.group(2)), "lower", m.group(1) == ">=")]
    m = re.fullmatch(r"([\[(])" + NUM + r",\s*" + NUM + r"([\])])", r)
    if m:
        return [(float(m.group(2)), "lower", m.group(1) == "["), (float(m.group(3)), "upper", m.group(4) == "]")]
    m = re.fullmatch(NUM + r"\s*\.\.\.\s*" + NUM, r)
    if m:
        return [(float(m.group(1)), "lower", True), (float(m.group(2)), "upper", True)]
    if re.fullmatch(r"`'[\w]+'`(,\s*`'[\w]+'`)*", r):
        return ("strings", re.findall(r"'(\w+)'", r))
    return None


def fmt(name, value):
    if name in INTEGERS:
        v = "%d" % round(value)
    else:
        v = repr(float(value))
    return ", ".join([v] * 3) if name in VECTORS else v


def run(program, path):
    p = subprocess.run([program, "--check", path], capture_output=True, text=True, timeout=120)
    return p.returncode, p.stdout + p.stderr


def write(path, groups):
    """groups: {group: [assignment, ...]}"""
    with open(path, "w") as f:
        for g, items in groups.items():
            f.write("&%s %s /\n" % (g, ", ".join(items)))
    return path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--docs", required=True)
    ap.add_argument("--workdir", required=True)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    out = os.path.join(args.workdir, "out")
    base = {"output": ["directory = '%s'" % out]}
    inside, alone = {}, []
    probed, skipped = 0, []
    jobs = []                                    # (path, group, name, value, rule)
    for k, (group, name, rule) in enumerate(documented_rows(args.docs)):
        b = bounds(rule)
        if b is None:
            skipped.append("&%s %s (%s)" % (group, name, rule))
            continue
        probed += 1
        refusals = []
        if isinstance(b, tuple):
            refusals.append("'bogus'")
        else:
            for value, side, included in b:
                delta = 1 if name in INTEGERS else 1e-6 * max(abs(value), 1)
                sign = -1 if side == "lower" else 1
                refusals.append(fmt(name, value + sign * delta if included else value))
                accepted = "%s = %s" % (name, fmt(name, value if included else value - sign * delta))
                if "Lz" in rule:                 # relative to &mesh lengths: probed alone
                    alone.append((group, accepted, rule))
                else:
                    inside.setdefault(group, []).append(accepted)
        for j, v in enumerate(refusals):
            groups = dict(base)
            groups[group] = groups.get(group, []) + ["%s = %s" % (name, v)]
            jobs.append((write(os.path.join(args.workdir, "refuse_%d_%d.nml" % (k, j)), groups), group, name, v, rule))
    with concurrent.futures.ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(lambda job: run(args.program, job[0]), jobs))
    for (path, group, name, v, rule), (status, log) in zip(jobs, results):
        named = "group &%s, variable %s" % (group, name)
        check(status == 2 and named in log,
              "&%s %s = %s (allowed: %s): exit %d%s" % (group, name, v, rule, status,
                                                      ", names it" if named in log else ", message: " + log[-300:]))
    for k, (group, accepted, rule) in enumerate(alone):
        groups = dict(base)
        groups[group] = groups.get(group, []) + [accepted]
        status, log = run(args.program, write(os.path.join(args.workdir, "alone_%d.nml" % k), groups))
        check(status == 0, "&%s %s (allowed: %s) accepted: exit %d %s" % (group, accepted, rule, status,
                                                                          "" if status == 0 else log[-300:]))
    # every value just inside its bounds, in one input (an interval variable appears with its
    # lower bound; a second assignment of the same variable would be refused as given twice)
    groups = dict(base)
    for g, items in inside.items():
        seen, keep = set(), []
        for item in items:
            n = item.split("=")[0].strip()
            if n not in seen:
                seen.add(n)
                keep.append(item)
        groups[g] = groups.get(g, []) + keep
    status, log = run(args.program, write(os.path.join(args.workdir, "inside_lower.nml"), groups))
    check(status == 0, "every variable at its lower bound (inside) accepted: exit %d %s"
          % (status, "" if status == 0 else log[-600:]))
    groups = dict(base)
    for g, items in inside.items():
        last = {}
        for item in items:
            last[item.split("=")[0].strip()] = item
        groups[g] = groups.get(g, []) + list(last.values())
    status, log = run(args.program, write(os.path.join(args.workdir, "inside_upper.nml"), groups))
    check(status == 0, "every variable at its upper bound (inside) accepted: exit %d %s"
          % (status, "" if status == 0 else log[-600:]))
    print("probed %d documented rows; not probed (other forms): %s" % (probed, "; ".join(skipped)))
    check(probed >= MIN_PROBED, "at least %d rows probed (%d)" % (MIN_PROBED, probed))
    print("%d failed" % len(FAILURES))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
