#!/usr/bin/python3
"""The defaults written in docs/INPUT.md are the program's.

    check_input_defaults.py --program feticontact --mpiexec mpiexec --docs docs/INPUT.md --workdir DIR

Runs `feticontact --check` on an input that sets nothing (every group takes its
defaults), parses the settings it echoes, and parses the tables of docs/INPUT.md
(rows "| `name` | meaning | default | allowed |" under "## &group" headings).
Fails when a documented default differs from the echoed value, when a documented
variable is not echoed, or when an echoed variable is not documented: a default
changed in one place only. The other pages (`--pages`: docs/*.md, README.md) are
searched for "`&group variable = value` (the default" and ", the default": each
such statement must also give the echoed value. The one exception is a variable the program resolves
at start and echoes resolved (`&mesh cluster`: 0, 0, 0 means "chosen at start"; `&obstacle axis`: the face centre of the body).
Exit status 0 when every check passes.
"""
import argparse
import os
import re
import subprocess
import sys

# documented default -> what the echo shows instead, because the program resolves it at start
RESOLVED_AT_START = {("mesh", "cluster"), ("obstacle", "axis")}
# lists without a default value: the echo holds them only when given
EMPTY_UNLESS_GIVEN = {("history", "gaps"), ("history", "load_factors")}

FAILURES = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    if not condition:
        FAILURES.append(what)


def doc_defaults(path):
    """{(group, variable): default cell text} from the tables of docs/INPUT.md."""
    found = {}
    group = None
    with open(path) as f:
        for line in f:
            m = re.match(r"## &(\w+)", line)
            if m:
                group = m.group(1).lower()
                continue
            if line.startswith("#"):
                group = None
                continue
            m = re.match(r"\| `(\w+)` \|", line)
            if m and group:
                cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]   # "\|" is text
                found[(group, m.group(1).lower())] = cells[2]
    return found


def echo_values(text):
    """{(group, variable): value text} from the echoed namelist lines ("&group a = 1, b = 'x' /")."""
    found = {}
    for line in text.splitlines():
        m = re.match(r"&(\w+) (.*) /$", line.strip())
        if not m:
            continue
        for a in re.finditer(r"(\w+) = ((?:'[^']*'|\"[^\"]*\"|[^,'\"])*)(?:, |$)", m.group(2)):
            found[(m.group(1).lower(), a.group(1).lower())] = a.group(2).strip()
    return found


def page_defaults(paths):
    """[(file:line, group, variable, value)] of the statements "`&group var = value` (the default"
    or "`&group var = value`, the default" in other pages."""
    found = []
    pattern = re.compile(r"`&(\w+) (\w+) = ([^`]+)`,? \(?the default")
    for path in paths:
        with open(path) as f:
            for number, line in enumerate(f, 1):
                for m in pattern.finditer(line):
                    found.append(("%s:%d" % (os.path.basename(path), number), m.group(1).lower(),
                                  m.group(2).lower(), m.group(3)))
    return found


def values(text):
    """A default or an echoed value as a list of normalized items: floats, True/False, strings."""
    text = text.strip().strip("`")
    if text.startswith("'") or text.startswith('"'):
        return [text.strip("'\"").lower()]
    items = [t for t in re.split(r"[,\s]+", text) if t]
    out = []
    for t in items:
        low = t.lower()
        if low in (".true.", "t", "true"):
            out.append(True)
        elif low in (".false.", "f", "false"):
            out.append(False)
        else:
            try:
                out.append(float(low.replace("d", "e")))
            except ValueError:
                out.append(low)
    return out


def same(a, b):
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if isinstance(x, float) and isinstance(y, float):
            if abs(x - y) > 1e-5 * max(abs(x), abs(y)):     # the echo keeps 6 significant digits
                return False
        elif x != y:
            return False
    return True


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--docs", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--pages", nargs="*", default=[])
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    path = os.path.join(args.workdir, "defaults.nml")
    with open(path, "w") as f:
        f.write("! every group takes its defaults\n&mesh /\n")
    run = subprocess.run([args.mpiexec, "-n", "1", args.program, "--check", path], capture_output=True, text=True,
                         timeout=120)
    check(run.returncode == 0, "feticontact --check exits 0 (got %d)" % run.returncode)
    echoed = echo_values(run.stdout)
    documented = doc_defaults(args.docs)
    check(len(echoed) > 50 and len(documented) > 50, "parsed %d echoed and %d documented variables"
          % (len(echoed), len(documented)))
    for key, default in sorted(documented.items()):
        name = "&%s %s" % key
        if key not in echoed:
            if key in EMPTY_UNLESS_GIVEN:
                print("skip %s: a list without a default, echoed only when given" % name)
                continue
            check(False, "%s: documented, not echoed by --check" % name)
            continue
        if key in RESOLVED_AT_START:
            print("skip %s: resolved at start (docs %s, echo %s)" % (name, default, echoed[key]))
            continue
        check(same(values(default), values(echoed[key])), "%s: docs default %s, --check echoes %s"
              % (name, default, echoed[key]))
    for key in sorted(set(echoed) - set(documented)):
        check(False, "&%s %s: echoed by --check, not documented in docs/INPUT.md" % key)
    for where, group, name, value in page_defaults(args.pages):
        key = (group, name)
        if key not in echoed:
            check(False, "%s: &%s %s is not a variable --check echoes" % (where, group, name))
        elif key not in RESOLVED_AT_START:
            check(same(values(value), values(echoed[key])), "%s: '&%s %s = %s, the default', --check echoes %s"
                  % (where, group, name, value, echoed[key]))
    print("%d failed" % len(FAILURES))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
