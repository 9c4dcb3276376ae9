#!/usr/bin/python3
"""Run a family of feticontact inputs and collect every report.json into one CSV.

    tools/campaign.py [options] INPUT [INPUT ...]     run a campaign
    tools/campaign.py --summary DIR_OR_CSV            print the per-member medians again

INPUT is a namelist file or a glob pattern (quote it: 'inputs/weak/cube_h4_n*.nml');
members run in natural order (n8 before n64 before n512). Each run gets its own
directory DIR/runs/<member>/np<P>/rep<k>/ holding the merged input (case.nml),
the program's output (log.txt) and its outputs (out/: report.json, .h5, .xdmf).
The input is copied with the --set/--sweep overrides merged into its groups and
&output directory pointing into that run directory; the original file is never
changed. After every run, DIR/campaign.csv is rewritten with one row per run
(also failed runs: their exit status is recorded, nothing is dropped), and at
the end the medians per member are printed as a Markdown table.

Examples (from the repository root):
    tools/campaign.py --ranks 2 --reps 3 --out output/campaigns/weak_h4 \\
        inputs/weak/cube_h4_n8.nml inputs/weak/cube_h4_n64.nml inputs/weak/cube_h4_n512.nml
    tools/campaign.py --ranks 2 --out output/campaigns/tol_block --set mesh:nel=2,2,2 \\
        --sweep "solver:tol=1e-2,1e-4,1e-6,1e-8,1e-10" inputs/block.nml

Exit status: 0 when every run exited 0, 1 when some run failed, 2 on bad arguments.
Python: /usr/bin/python3 (only the standard library is needed here).
"""
import argparse
import csv
import datetime
import glob
import itertools
import json
import math
import os
import re
import shlex
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Phases in the order the program runs them; phases not listed here (a timer
# added later) get columns too, after these.
KNOWN_PHASES = ["total", "mesh", "assembly", "factorization", "B and G", "coarse setup", "dual setup", "solve",
                "dual gradient", "rec new", "rec standard", "primal", "kkt", "output",
                "F action", "coarse solve"]  # the last two are nested in dual setup, solve, ...

# Columns before the timing columns, in CSV order: (column, path in report.json or None).
RUN_COLUMNS = ["campaign", "member", "input", "overrides", "ranks", "rep", "exit_status", "status", "wall_seconds",
               "started", "load_before", "run_dir", "h5"]
REPORT_COLUMNS = [
    ("case", ("case", "output", "run_name")),
    ("shape", ("case", "obstacle", "shape")),
    ("nsub", ("case", "mesh", "nsub")),
    ("nel", ("case", "mesh", "nel")),
    ("decomposition", ("case", "mesh", "decomposition")),
    ("tol", ("case", "solver", "tol")),
    ("coarse", ("case", "solver", "coarse")),
    ("subdomains", ("sizes", "subdomains")),
    ("ranks_reported", ("sizes", "ranks")),
    ("primal_dofs", ("sizes", "primal_dofs")),
    ("dual_dofs", ("sizes", "dual_dofs")),
    ("coarse_dim", ("sizes", "coarse_dim")),
    ("contact_rows", ("sizes", "contact_rows")),
    ("active_contact", ("sizes", "active_contact")),
    ("gluing_rows", ("sizes", "gluing_rows")),
    ("dirichlet_rows", ("sizes", "dirichlet_rows")),
    ("converged", ("solver", "converged")),
    ("solver_status", ("solver", "status")),
    ("outer_iterations", ("solver", "outer_iterations")),
    ("inner_iterations", ("solver", "inner_iterations")),
    ("hessian_multiplications", ("solver", "hessian_multiplications")),
    ("cg_steps", ("solver", "cg_steps")),
    ("expansion_steps", ("solver", "expansion_steps")),
    ("proportioning_steps", ("solver", "proportioning_steps")),
    ("m_updates", ("solver", "m_updates")),
    ("projected_gradient", ("solver", "projected_gradient")),
    ("equality_residual", ("solver", "equality_residual")),
    ("norm_b", ("solver", "norm_b")),
    ("rho", ("solver", "rho")),
    ("norm_pfp", ("solver", "norm_pfp")),
    ("f_applications", ("solver", "f_applications")),
    ("coarse_solves", ("solver", "coarse_solves")),
    ("kkt_equilibrium", ("kkt", "equilibrium")),
    ("kkt_equality", ("kkt", "equality")),
    ("kkt_feasibility", ("kkt", "feasibility")),
    ("kkt_dual_feasibility", ("kkt", "dual_feasibility")),
    ("kkt_complementarity", ("kkt", "complementarity")),
    ("kkt_max", None),
    ("kkt_passed", ("kkt", "passed")),
    ("rec_method", ("reconstruction", "method")),
    ("alpha_difference", ("reconstruction", "alpha_difference")),
    ("rec_new_seconds", ("reconstruction", "new", "seconds")),
    ("rec_standard_seconds", ("reconstruction", "standard", "seconds")),
    ("rec_standard_assembly", ("reconstruction", "standard", "assembly")),
    ("rec_standard_factorization", ("reconstruction", "standard", "factorization")),
    ("rec_standard_solve", ("reconstruction", "standard", "solve")),
    ("rec_standard_active_rows", ("reconstruction", "standard", "active_contact_rows")),
    ("contact_total_force", ("contact", "total_force")),
    ("contact_max_pressure", ("contact", "max_pressure")),
    ("contact_active_nodes", ("contact", "active_nodes")),
    ("contact_radius", ("contact", "contact_radius")),
    ("peak_rss_max_bytes", ("memory", "peak_rss_bytes", "max")),
    ("peak_rss_sum_bytes", ("memory", "peak_rss_bytes", "sum")),
]
KKT_KEYS = ["kkt_equilibrium", "kkt_equality", "kkt_feasibility", "kkt_dual_feasibility", "kkt_complementarity"]
EXIT_MEANING = {0: "ok", 2: "bad input", 3: "not converged", 4: "KKT failed", 5: "internal error"}
TIMEOUT_STATUS = 124  # as coreutils timeout(1)


def phase_column(phase, stat):
    """'B and G', 'mean' -> 't_b_and_g_mean'."""
    return "t_%s_%s" % (re.sub(r"[^a-z0-9]+", "_", phase.lower()).strip("_"), stat)


# ---------------------------------------------------------------- namelists
def _strip_comment(line):
    """The line without its '!' comment; quotes protect '!'."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "!":
            return line[:i]
    return line


def _split_top(body, start_re):
    """Split `body` before every position outside quotes where start_re matches."""
    cuts, quote = [], None
    for i, ch in enumerate(body):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif start_re.match(body, i):
            cuts.append(i)
    return [body[a:b] for a, b in zip([0] + cuts, cuts + [len(body)])]


def parse_namelist(text):
    """Groups of a namelist file as {group: [(variable, raw value text)]}, in file order.

    Comments ('!' outside quotes) are dropped; values keep their raw text
    (lists like `2, 2, 2`, quoted strings with '/' or '=' inside)."""
    text = "\n".join(_strip_comment(line) for line in text.splitlines())
    groups, i, quote = {}, 0, None
    while True:
        m = re.compile(r"&(\w+)").search(text, i)
        if not m:
            break
        j = m.end()
        quote = None
        while j < len(text):  # the closing '/' outside quotes
            ch = text[j]
            if quote:
                if ch == quote:
                    quote = None
            elif ch in "'\"":
                quote = ch
            elif ch == "/":
                break
            j += 1
        if j >= len(text):
            raise ValueError("group &%s has no closing '/'" % m.group(1))
        body = text[m.end():j]
        i = j + 1
        # an assignment starts at `name =` or `name(...) =` outside quotes
        items = []
        parts = _split_top(body, re.compile(r"(?:^|(?<=[\s,]))\w+(?:\([^)]*\))?\s*="))
        for piece in parts:
            piece = piece.strip().rstrip(",").strip()
            if not piece:
                continue
            name, value = piece.split("=", 1)
            items.append((name.strip().lower(), value.strip()))
        groups[m.group(1).lower()] = items
    return groups


def write_namelist(groups, path, header=""):
    with open(path, "w") as f:
        f.write(header)
        for g, items in groups.items():
            f.write("&%s %s /\n" % (g, ", ".join("%s = %s" % kv for kv in items)))


def parse_override(text):
    """'group:variable=value' -> (group, variable, value)."""
    m = re.match(r"^\s*(\w+)\s*:\s*(\w+(?:\([^)]*\))?)\s*=(.*)$", text, re.S)
    if not m or not m.group(3).strip():
        raise argparse.ArgumentTypeError("expected group:variable=value, got %r" % text)
    return m.group(1).lower(), m.group(2).lower(), m.group(3).strip()


def merge_overrides(groups, overrides):
    groups = {g: list(items) for g, items in groups.items()}
    for g, v, value in overrides:
        groups[g] = [kv for kv in groups.get(g, []) if kv[0] != v] + [(v, value)]
    return groups


# ---------------------------------------------------------------- members
def natural_key(s):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", s)]


def expand_inputs(patterns):
    files = []
    for p in patterns:
        hits = sorted(glob.glob(p), key=natural_key) if any(c in p for c in "*?[") else [p]
        if not hits:
            sys.exit("campaign: no input matches %r" % p)
        for h in hits:
            if not os.path.isfile(h):
                sys.exit("campaign: no such input file %r" % h)
            if os.path.abspath(h) not in [os.path.abspath(f) for f in files]:
                files.append(h)
    return files


def parse_sweep(text):
    """'group:variable=v1,v2,...' -> [(group, variable, v1), ...]. Values are split at ','
    or, when the text has a ';', at ';' (for list values: mesh:nel=2,2,2;4,4,4)."""
    g, v, values = parse_override(text)
    sep = ";" if ";" in values else ","
    return [(g, v, x.strip()) for x in values.split(sep) if x.strip()]


def slug(text):
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text).strip("_")


def build_members(inputs, sweeps):
    """One member per (input, combination of sweep values)."""
    members = []
    combos = list(itertools.product(*sweeps)) if sweeps else [()]
    for path in inputs:
        stem = os.path.splitext(os.path.basename(path))[0]
        for combo in combos:
            tag = ",".join("%s=%s" % (v, value) for g, v, value in combo)
            name = stem + ("[%s]" % tag if tag else "")
            members.append({"name": name, "input": path, "sweep": list(combo)})
    return members


# ---------------------------------------------------------------- running
def fmt_duration(seconds):
    seconds = int(round(seconds))
    return "%d:%02d:%02d" % (seconds // 3600, seconds // 60 % 60, seconds % 60)


class Progress:
    """One status line on stderr; rewritten in place on a terminal, else one line per event."""

    def __init__(self):
        self.tty = sys.stderr.isatty()
        self.width = 0

    def show(self, text, final=False):
        if self.tty:
            pad = max(0, self.width - len(text))
            sys.stderr.write("\r" + text + " " * pad + ("\n" if final else ""))
            self.width = 0 if final else len(text)
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()


class Terminated(Exception):
    """SIGTERM arrived: stop the current run, then exit (like Ctrl-C; a job started in the
    background by a script ignores SIGINT, so stop it with `kill PID`)."""


def _terminate(signum, frame):
    raise Terminated(signal.Signals(signum).name)


def run_one(cmd, log_path, timeout, env, on_tick):
    """Run cmd with stdout+stderr to log_path; returns (exit status, wall seconds)."""
    t0 = time.monotonic()
    with open(log_path, "w") as log:
        log.write("# " + " ".join(shlex.quote(c) for c in cmd) + "\n")
        log.flush()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)

        def stop():  # the run's own process group (its own session), nothing else
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()

        while True:
            try:
                status = proc.wait(timeout=1.0)
                break
            except subprocess.TimeoutExpired:
                on_tick(time.monotonic() - t0)
                if timeout and time.monotonic() - t0 > timeout:
                    stop()
                    log.write("\n# campaign: killed after %.0f s (--timeout)\n" % timeout)
                    status = TIMEOUT_STATUS
                    break
            except (KeyboardInterrupt, Terminated):
                stop()
                log.write("\n# campaign: interrupted\n")
                raise
    return status, time.monotonic() - t0


def dig(obj, path):
    for key in path:
        if not isinstance(obj, dict) or key not in obj:
            return None
        obj = obj[key]
    return obj


def cell(value):
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "x".join(str(v) for v in value)
    if isinstance(value, float):
        return repr(value)
    return str(value)


def report_row(report):
    """The CSV fields of one report.json (missing entries stay empty)."""
    row = {}
    for col, path in REPORT_COLUMNS:
        if path is not None:
            row[col] = cell(dig(report, path))
    kkt = [dig(report, ("kkt", k[4:])) for k in KKT_KEYS]
    kkt = [v for v in kkt if isinstance(v, (int, float))]
    row["kkt_max"] = cell(max(kkt)) if kkt else ""
    for phase, stat in (report.get("timings") or {}).items():
        for s in ("mean", "max"):
            if isinstance(stat, dict) and s in stat:
                row[phase_column(phase, s)] = cell(stat[s])
    return row


def columns_for(rows):
    phases = list(KNOWN_PHASES)
    seen = set()
    for r in rows:
        seen.update(k for k in r if k.startswith("t_"))
    cols = RUN_COLUMNS + [c for c, _ in REPORT_COLUMNS]
    tcols = [phase_column(p, s) for p in phases for s in ("mean", "max")]
    extra = sorted(seen - set(tcols))
    return cols + tcols + extra


def write_csv(path, rows):
    cols = columns_for(rows)
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in cols})
    os.replace(tmp, path)


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def git_commit():
    try:
        out = subprocess.run(["git", "-C", ROOT, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
        return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return ""


# ---------------------------------------------------------------- medians
def num(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def median_of(rows, col):
    vals = [num(r.get(col)) for r in rows]
    vals = [v for v in vals if v is not None]
    return statistics.median(vals) if vals else None


def spread_of(rows, col):
    """(max - min) / median of a column over runs, the noise of a time."""
    vals = [num(r.get(col)) for r in rows]
    vals = [v for v in vals if v is not None]
    if len(vals) < 2 or statistics.median(vals) <= 0:
        return None
    return (max(vals) - min(vals)) / statistics.median(vals)


def group_rows(rows):
    groups = {}
    for r in rows:
        groups.setdefault((r["member"], r["ranks"]), []).append(r)
    return groups


def fmt(v, kind):
    if v is None:
        return "-"
    if kind == "int":
        return "%d" % round(v)
    if kind == "s":
        return "%.3g" % v if v < 1 else "%.2f" % v
    if kind == "e":
        return "%.1e" % v
    if kind == "pct":
        return "%.0f%%" % (100 * v)
    if kind == "f1":
        return "%.1f" % v
    if kind == "mib":
        return "%.0f" % (v / 2**20)
    return str(v)


SUMMARY = [  # header, column, kind
    ("subdomains", "subdomains", "int"), ("primal dofs", "primal_dofs", "int"), ("dual dofs", "dual_dofs", "int"),
    ("active", "active_contact", "int"), ("outer", "outer_iterations", "int"),
    ("Hessian", "hessian_multiplications", "int"), ("KKT max", "kkt_max", "e"),
    ("total [s]", "t_total_max", "s"), ("spread", None, "pct"), ("setup [s]", "setup", "s"),
    ("dual setup [s]", "t_dual_setup_max", "s"), ("solve [s]", "t_solve_max", "s"),
    ("rec new [s]", "rec_new_seconds", "s"), ("rec std [s]", "rec_standard_seconds", "s"),
    ("RSS max [MiB]", "peak_rss_max_bytes", "mib"), ("RSS sum [MiB]", "peak_rss_sum_bytes", "mib"),
    ("load", "load_before", "f1"),
]
SETUP_PHASES = ["mesh", "assembly", "factorization", "B and G", "coarse setup"]


def with_setup(r):
    vals = [num(r.get(phase_column(p, "max"))) for p in SETUP_PHASES]
    r = dict(r)
    r["setup"] = cell(sum(vals)) if all(v is not None for v in vals) else ""
    return r


def summary_table(rows):
    """Markdown table of the medians per (member, ranks) over the runs that exited 0."""
    head = ["member", "ranks", "runs (ok)"] + [h for h, _, _ in SUMMARY]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    for (member, ranks), runs in group_rows(rows).items():
        ok = [with_setup(r) for r in runs if r.get("exit_status") == "0"]
        cells = [member, ranks, "%d (%d)" % (len(runs), len(ok))]
        for _, col, kind in SUMMARY:
            v = spread_of(ok, "t_total_max") if col is None else median_of(ok, col)
            cells.append(fmt(v, kind))
        lines.append("| " + " | ".join(cells) + " |")
    failed = [r for r in rows if r.get("exit_status") != "0"]
    notes = ["", "Medians over the runs that exited 0; times are the max over ranks (the critical path);",
             "setup = mesh + assembly + factorization + B and G + coarse setup; spread = (max - min)/median",
             "of the total time over the repetitions; rec new/std: the two reconstructions (Eq. 24 / Eq. 10);",
             "load: the 1-minute load average before the run (above the rank count: other jobs shared the cores)."]
    for r in failed:
        notes.append("FAILED: %s np%s rep %s: exit %s (%s), see %s" % (r["member"], r["ranks"], r["rep"],
                                                                      r["exit_status"], r["status"], r["run_dir"]))
    return "\n".join(lines + notes)


# ---------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], epilog=__doc__.split("\n", 2)[2],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", help="namelist files or quoted glob patterns")
    ap.add_argument("--out", default="output/campaign",
                    help="campaign directory: campaign.csv, campaign.json, runs/ (default %(default)s)")
    ap.add_argument("--ranks", default="2", help="MPI ranks, or a comma list to run every member on each")
    ap.add_argument("--reps", type=int, default=1, help="repetitions of every member (default 1)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], type=parse_override,
                    metavar="GROUP:VAR=VALUE", help="namelist override merged into every input (repeatable)")
    ap.add_argument("--sweep", action="append", default=[], type=parse_sweep, metavar="GROUP:VAR=V1,V2,...",
                    help="one member per value (repeatable: the product); separate list values by ';'")
    ap.add_argument("--program", default=os.path.join(ROOT, "build", "bin", "feticontact"),
                    help="feticontact executable (default %(default)s)")
    ap.add_argument("--mpiexec", default=shutil.which("mpirun") or "mpirun", help="MPI launcher (default mpirun)")
    ap.add_argument("--mpi-args", default="--oversubscribe --bind-to none",
                    help="launcher flags before -n (default %(default)r)")
    ap.add_argument("--timeout", type=float, default=0, help="kill a run after this many seconds (0: never)")
    ap.add_argument("--max-load", type=float, default=0,
                    help="before each run, wait until the 1-minute load average is below this (0: do not wait); "
                         "the runs' own ranks count too, so use about cores + 0.5")
    ap.add_argument("--max-wait", type=float, default=600, help="longest wait for --max-load per run [s]")
    ap.add_argument("--interleave", action="store_true",
                    help="run repetition 1 of every member, then repetition 2, ... (spreads machine drift)")
    ap.add_argument("--append", action="store_true", help="add rows to an existing campaign.csv in --out")
    ap.add_argument("--dry-run", action="store_true",
                    help="write the merged inputs under DIR/dry-run/, print the commands, run nothing")
    ap.add_argument("--summary", metavar="DIR_OR_CSV", help="only print the medians of an existing campaign")
    args = ap.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `| head` ends quietly

    if args.summary:
        path = os.path.join(args.summary, "campaign.csv") if os.path.isdir(args.summary) else args.summary
        print(summary_table(read_csv(path)))
        return 0
    if not args.inputs:
        ap.error("no inputs given")
    if args.reps < 1:
        ap.error("--reps must be >= 1")
    try:
        ranks = [int(r) for r in args.ranks.split(",")]
        assert all(r >= 1 for r in ranks)
    except (ValueError, AssertionError):
        ap.error("--ranks: expected positive integers, got %r" % args.ranks)
    program = os.path.abspath(args.program)
    if not args.dry_run and not os.access(program, os.X_OK):
        ap.error("--program %s is not an executable (build it first, see README.md)" % program)

    inputs = expand_inputs(args.inputs)
    members = build_members(inputs, args.sweep)
    out = os.path.abspath(args.out)
    csv_path = os.path.join(out, "campaign.csv")
    os.makedirs(out, exist_ok=True)
    rows = read_csv(csv_path) if args.append and os.path.exists(csv_path) else []
    if not args.append and os.path.exists(csv_path) and not args.dry_run:
        os.replace(csv_path, csv_path + ".previous")
        print("campaign: moved the existing %s to campaign.csv.previous" % csv_path, file=sys.stderr)
    first_rep = {}
    for r in rows:
        key = (r["member"], r["ranks"])
        first_rep[key] = max(first_rep.get(key, 0), int(r.get("rep") or 0))

    env = dict(os.environ)
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")

    meta = {"command": [sys.argv[0]] + sys.argv[1:], "cwd": os.getcwd(), "program": program,
            "program_mtime": datetime.datetime.fromtimestamp(os.path.getmtime(program)).isoformat(timespec="seconds")
            if os.path.exists(program) else None,
            "git_commit": git_commit(), "host": socket.gethostname(), "cpus": os.cpu_count(),
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "inputs": inputs, "ranks": ranks, "reps": args.reps}
    if not args.dry_run:  # campaign.json: this invocation; invocations.jsonl: all of them (--append)
        if not args.append or not os.path.exists(os.path.join(out, "campaign.json")):
            with open(os.path.join(out, "campaign.json"), "w") as f:
                json.dump(meta, f, indent=2)
        with open(os.path.join(out, "invocations.jsonl"), "a") as f:
            f.write(json.dumps(meta) + "\n")

    plan = []  # (member, ranks, rep)
    if args.interleave:
        for k in range(args.reps):
            plan += [(m, p, k) for m in members for p in ranks]
    else:
        plan = [(m, p, k) for m in members for p in ranks for k in range(args.reps)]

    signal.signal(signal.SIGTERM, _terminate)
    progress = Progress()
    t_start = time.monotonic()
    last = "-"
    failures = 0
    campaign_name = os.path.basename(out)
    for i, (member, np_, k) in enumerate(plan, start=1):
        rep = first_rep.get((member["name"], str(np_)), 0) + k + 1
        run_dir = os.path.join(out, "dry-run" if args.dry_run else "runs", slug(member["name"]), "np%d" % np_,
                               "rep%d" % rep)
        if os.path.isdir(run_dir):
            shutil.rmtree(run_dir)  # never read a stale report.json
        os.makedirs(run_dir)
        overrides = list(args.overrides) + list(member["sweep"])
        with open(member["input"]) as f:
            groups = parse_namelist(f.read())
        groups = merge_overrides(groups, overrides + [("output", "directory", "'%s'" % os.path.join(run_dir, "out"))])
        case_nml = os.path.join(run_dir, "case.nml")
        header = "! %s with %s (tools/campaign.py)\n" % (member["input"], " ".join(
            "%s:%s=%s" % o for o in overrides) or "no overrides")
        write_namelist(groups, case_nml, header)
        cmd = [args.mpiexec] + shlex.split(args.mpi_args) + ["-n", str(np_), program, case_nml]
        label = "[%d/%d] %s np%d rep %d/%d" % (i, len(plan), member["name"], np_, rep,
                                              first_rep.get((member["name"], str(np_)), 0) + args.reps)
        if args.dry_run:
            print(" ".join(shlex.quote(c) for c in cmd))
            continue

        def tick(t, label=label):
            if progress.tty:
                progress.show("%s | running %s | campaign elapsed %s | last run %s" % (
                    label, fmt_duration(t), fmt_duration(time.monotonic() - t_start), last))

        if args.max_load > 0:
            t_wait = time.monotonic()
            while os.getloadavg()[0] >= args.max_load and time.monotonic() - t_wait < args.max_wait:
                progress.show("%s | waiting for load %.1f < %.1f (%.0f s)" % (
                    label, os.getloadavg()[0], args.max_load, time.monotonic() - t_wait), final=not progress.tty)
                time.sleep(5 if progress.tty else 30)
        progress.show("%s | started | campaign elapsed %s | last run %s" % (
            label, fmt_duration(time.monotonic() - t_start), last), final=not progress.tty)
        started = datetime.datetime.now().isoformat(timespec="seconds")
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")  # other jobs: noisy times
        status, wall = run_one(cmd, os.path.join(run_dir, "log.txt"), args.timeout, env, tick)

        row = {"campaign": campaign_name, "member": member["name"], "input": os.path.relpath(member["input"], ROOT)
               if os.path.abspath(member["input"]).startswith(ROOT) else member["input"],
               "overrides": " ".join("%s:%s=%s" % o for o in overrides), "ranks": str(np_), "rep": str(rep),
               "exit_status": str(status), "wall_seconds": "%.3f" % wall, "started": started,
               "load_before": "%.2f" % load, "run_dir": run_dir}
        report_path = os.path.join(run_dir, "out", "report.json")
        if os.path.exists(report_path):
            try:
                with open(report_path) as f:
                    row.update(report_row(json.load(f)))
            except (OSError, ValueError) as e:
                row["status"] = "unreadable report.json: %s" % e
        h5 = sorted(glob.glob(os.path.join(run_dir, "out", "*.h5")))
        row["h5"] = h5[0] if h5 else ""
        if status == TIMEOUT_STATUS:
            row["status"] = "timeout"
        elif not row.get("status"):
            row["status"] = EXIT_MEANING.get(status, "exit %d" % status) + (
                "" if os.path.exists(report_path) else ", no report.json")
        if status != 0:
            failures += 1
        rows.append(row)
        write_csv(csv_path, rows)
        last = "%.1f s (%s)" % (wall, row["status"])
        progress.show("%s | done | campaign elapsed %s | this run %s" % (
            label, fmt_duration(time.monotonic() - t_start), last), final=True)

    if args.dry_run:
        return 0
    print("\ncampaign: %d runs, %d failed, %s; CSV %s\n" % (len(plan), failures,
                                                        fmt_duration(time.monotonic() - t_start), csv_path))
    print(summary_table(rows))
    return 1 if failures else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (KeyboardInterrupt, Terminated) as e:
        sys.exit("campaign: stopped (%s); the CSV has the runs that finished" % (e or "interrupt"))
