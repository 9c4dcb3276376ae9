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

Solver variants (tools/variants.py): --variant NAME:VAR=VALUE[;VAR=VALUE] (&solver settings,
repeatable) and --variants V1,V2 (&solver preconditioner = 'V1', ...; --variant-variable names
another variable) run every member once per variant, as member NAME@VARIANT with the column
`variant`; each variant is checked first with `feticontact --check` (a variable or value the
program rejects stops the campaign with its message), and a second table compares the
variants: outer and Hessian counts, products per outer iteration, the late contraction of
||C x|| per outer iteration, solve and total time, exit status and KKT pass/fail.

With --scheduler slurm the same run folders and merged inputs are written, but each member
and rank count becomes one sbatch job script (runs/<member>/np<P>/job.sh, its repetitions one
after the other inside it), submitted unless --dry-run; DIR/jobs.json records the job ids.
Then --status DIR shows every job and run (pending, running, completed, failed with its exit
status, timeout, cancelled), --collect DIR [--wait] writes campaign.csv from the finished runs
(the same columns as a local campaign) and prints the medians, and --resubmit failed --out DIR
sends the failed and timed-out runs again. Submitting the same campaign twice submits nothing
that is pending, running or done. Job states come from squeue and the files each job script
writes into its run folders (started.txt, exit.txt), never from Slurm accounting. See
docs/CLUSTER.md; tools/local_slurm.sh starts a one-node Slurm for trying it out.

Examples (from the repository root):
    tools/campaign.py --ranks 2 --reps 3 --out output/campaigns/weak_h4 \\
        inputs/weak/cube_h4_n8.nml inputs/weak/cube_h4_n64.nml inputs/weak/cube_h4_n512.nml
    tools/campaign.py --ranks 2 --out output/campaigns/tol_block --set mesh:nel=2,2,2 \\
        --sweep "solver:tol=1e-2,1e-4,1e-6,1e-8,1e-10" inputs/block.nml
    tools/campaign.py --ranks 2 --out output/campaigns/weak_variants --variants none,lumped,dirichlet \\
        'inputs/weak/cube_h4_n*.nml'
    tools/campaign.py --ranks 2 --out output/campaigns/rho --variant default \\
        --variant "rho2:rho_growth=2;m_no_step=keep" inputs/weak/cube_h4_n64.nml
    tools/campaign.py --scheduler slurm --ranks 256 --reps 3 --time 0:30:00 --mem-per-rank 1G \\
        --partition standard --out /scratch/$USER/paper inputs/weak/cube_h4_n4096.nml
    tools/campaign.py --status /scratch/$USER/paper
    tools/campaign.py --collect /scratch/$USER/paper --wait

Exit status: 0 when every run exited 0, 1 when some run failed, 2 on bad arguments; --collect:
3 when no run failed but some are not finished.
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

import variants as solver_variants  # tools/variants.py (this folder is on sys.path)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOL = os.path.abspath(__file__)  # hints name it absolutely: they work from any folder

# Phases in the order the program runs them; phases not listed here (a timer
# added later) get columns too, after these.
KNOWN_PHASES = ["total", "mesh", "assembly", "factorization", "B and G", "explicit F", "coarse setup", "dual setup",
                "preconditioner setup", "solve", "dual gradient", "rec new", "rec standard", "primal", "kkt",
                "output", "F action", "coarse solve"]  # the last two are nested in dual setup, solve, ...

# Columns before the timing columns, in CSV order: (column, path in report.json or None).
RUN_COLUMNS = ["campaign", "member", "variant", "input", "overrides", "ranks", "rep", "exit_status", "status", "message",
               "wall_seconds", "started", "load_before", "job_id", "run_dir", "h5"]
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
    ("solver_variant", ("solver", "variant")),
    ("hessian_per_outer", ("solver", "hessian_per_outer_mean")),
    ("contraction_median", ("solver", "contraction_median")),
    ("contraction_late", ("solver", "contraction_late")),
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
    ("setup_max", None),
    ("setup_mean", None),
    ("setup_phases", None),
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


def build_members(inputs, sweeps, variants=()):
    """One member per (input, combination of sweep values, solver variant): NAME[sweep]@VARIANT."""
    members = []
    combos = list(itertools.product(*sweeps)) if sweeps else [()]
    for path in inputs:
        stem = os.path.splitext(os.path.basename(path))[0]
        for combo in combos:
            tag = ",".join("%s=%s" % (v, value) for g, v, value in combo)
            name = stem + ("[%s]" % tag if tag else "")
            for variant in variants or [None]:
                if variant is None:
                    members.append({"name": name, "input": path, "sweep": list(combo), "variant": ""})
                else:
                    members.append({"name": name + "@" + variant["name"], "input": path,
                                    "sweep": list(combo) + list(variant["settings"]), "variant": variant["name"]})
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
    phases, seconds = setup_of(report)
    if phases:
        row["setup_max"], row["setup_mean"] = cell(seconds["max"]), cell(seconds["mean"])
        row["setup_phases"] = "+".join(phases)
    return row


def setup_phases(report):
    """The set-up phases of a run: the top-level phases of report.json's timing tree
    (timings.total.children) before the solve, except 'dual setup' (a column of its own);
    for a report without the tree, those of SETUP_PHASES it has."""
    t = report.get("timings") or {}
    children = (t.get("total") or {}).get("children")
    if not children:
        return [p for p in SETUP_PHASES if isinstance(t.get(p), dict)]
    names = []
    for c in children:
        if c.get("name") == "solve":
            break
        if c.get("name") not in SETUP_EXCLUDED:
            names.append(c["name"])
    return names


def setup_of(report):
    """(set-up phases, {"max": s, "mean": s}): the sums of their max and mean over ranks,
    from the tree's top-level rows (a phase that also ran later, inside the solve, counts
    its set-up part only) or, without the tree, the flat timings."""
    t = report.get("timings") or {}
    phases = setup_phases(report)
    rows = {c.get("name"): c for c in (t.get("total") or {}).get("children") or []} or t
    return phases, {s: sum(rows[p][s] for p in phases) for s in ("max", "mean")}


def columns_for(rows):
    phases = list(KNOWN_PHASES)
    seen = set()
    for r in rows:
        seen.update(k for k in r if k.startswith("t_"))
    cols = RUN_COLUMNS + [c for c, _ in REPORT_COLUMNS]
    tcols = [phase_column(p, s) for p in phases for s in ("mean", "max")]
    extra = sorted(seen - set(tcols))
    return cols + tcols + extra


# A load history (&history): report.json's `history` gives one CSV row per step, the run's
# columns kept (its report sections are those of the peak step, report.json `step`) and these added.
STEP_COLUMNS = [("step", "step"), ("step_load_factor", "load_factor"), ("step_gap", "gap"),
                ("step_total_force", "total_force"), ("step_active_nodes", "active_nodes"),
                ("step_contact_radius", "contact_radius"), ("step_max_pressure", "max_pressure"),
                ("step_outer", "outer_iterations"), ("step_hessian", "hessian_multiplications"),
                ("step_warm_start", "warm_start"), ("step_faces_reused", "faces_reused"),
                ("step_recycled_directions", "recycled_directions"),
                ("step_kkt_worst", "kkt_worst"), ("step_kkt_passed", "kkt_passed"),
                ("step_seconds", "seconds/step"), ("step_rhs_seconds", "seconds/rhs"),
                ("step_solve_seconds", "seconds/solve"), ("step_rec_new_seconds", "seconds/rec_new"),
                ("step_rec_standard_seconds", "seconds/rec_standard")]


def step_rows(rows):
    """Each row of a history run (its `_history`, from report.json) as one row per step."""
    out = []
    for r in rows:
        steps = r.get("_history")
        if not steps:
            out.append(r)
            continue
        for rec in steps:
            row = {k: v for k, v in r.items() if k != "_history"}
            row.update({col: cell(dig(rec, path.split("/"))) for col, path in STEP_COLUMNS})
            out.append(row)
    return out


def write_csv(path, rows):
    rows = step_rows(rows)
    cols = columns_for(rows)
    if any(r.get("step", "") != "" for r in rows):
        cols = cols + [c for c, _ in STEP_COLUMNS if c not in cols]
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
# Set-up phases of a report.json without the timing tree (setup_phases reads them from the tree).
SETUP_PHASES = ["mesh", "assembly", "factorization", "B and G", "explicit F", "coarse setup", "orthonormal coarse",
                "preconditioner setup"]
SETUP_EXCLUDED = ("dual setup", "other")


def with_setup(r):
    """The row with "setup": its setup_max, or for a CSV written before that column the sum
    of the flat set-up phases it has (explicit F included)."""
    r = dict(r)
    if num(r.get("setup_max")) is not None:
        r["setup"] = r["setup_max"]
        return r
    vals = [num(r.get(phase_column(p, "max"))) for p in SETUP_PHASES]
    vals = [v for v in vals if v is not None]
    r["setup"] = cell(sum(vals)) if vals else ""
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
             "setup = the phases before the solve except dual setup (mesh, assembly, factorization, B and G,",
             "explicit F, coarse setup, preconditioner setup; CSV setup_phases); spread = (max - min)/median",
             "of the total time over the repetitions; rec new/std: the two reconstructions (Eq. 24 / Eq. 10);",
             "load: the 1-minute load average before the run (above the rank count: other jobs shared the cores)."]
    for r in failed:
        what = "exit %s (%s)" % (r["exit_status"], r["status"]) if r.get("exit_status") else r.get("status")
        notes.append("FAILED: %s np%s rep %s: %s, see %s%s" % (r["member"], r["ranks"], r["rep"], what, r["run_dir"],
                                                               "\n  " + r["message"] if r.get("message") else ""))
    return "\n".join(lines + notes)


def variant_table(rows):
    """Markdown table comparing the solver variants: one row per (member without its variant,
    ranks, variant), medians over every run that left a report.json (not-converged runs too:
    their counts are what a variant costs), or the exit status alone."""
    groups = {}
    for r in rows:
        if not r.get("variant"):
            continue
        base = r["member"][:-len(r["variant"]) - 1] if r["member"].endswith("@" + r["variant"]) else r["member"]
        groups.setdefault((base, r["ranks"], r["variant"]), []).append(r)
    if not groups:
        return ""
    head = ["case", "ranks", "variant", "runs", "exit", "outer", "Hessian", "Hessian/outer", "contraction",
            "solve [s]", "total [s]", "KKT", "settings"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 3 + ["---:"] * 8 + ["---"] * 2) + "|"]
    for (base, ranks, variant), runs in sorted(groups.items(), key=lambda kv: (natural_key(kv[0][0]),
                                                                               int(kv[0][1]))):
        rep_rows = [r for r in runs if r.get("outer_iterations")]
        exits = sorted({r.get("exit_status") or "-" for r in runs})
        kkt = sorted({"pass" if r.get("kkt_passed") == "true" else "fail" for r in rep_rows}) or ["-"]
        settings = runs[0].get("solver_variant") or "-"
        lines.append("| " + " | ".join([
            base, str(ranks), variant, str(len(runs)), ",".join(exits),
            fmt(median_of(rep_rows, "outer_iterations"), "int"),
            fmt(median_of(rep_rows, "hessian_multiplications"), "int"),
            fmt(median_of(rep_rows, "hessian_per_outer"), "f1"),
            fmt(median_of(rep_rows, "contraction_late"), "s"),
            fmt(median_of(rep_rows, "t_solve_max"), "s"), fmt(median_of(rep_rows, "t_total_max"), "s"),
            "/".join(kkt), settings]) + " |")
    notes = ["", "Medians over the runs with a report.json; exit: the exit statuses seen (0 converged, 3 not",
             "converged, 4 KKT check failed); contraction: the geometric mean of ||C x_k|| / ||C x_(k-1)|| over",
             "the second half of the outer iterations (report.json solver.contraction_late); settings: the",
             "&solver settings that differ from the defaults (report.json solver.variant)."]
    return "\n".join(lines + notes)


# ---------------------------------------------------------------- runs (both back ends)
# A run is one execution of one member on one rank count, repetition k, in its own folder
# DIR/runs/<member>/np<P>/rep<k>/. Both back ends prepare it with prepare_run() and turn what it
# left there into a CSV row with run_row(); they differ only in how the program is launched
# (run_local: mpirun here, one run after the other; submit_slurm: one sbatch job per member and
# rank count whose script runs its repetitions one after the other).
def plan_runs(members, ranks, reps, interleave, first_rep):
    """[(member, ranks, rep number)] in running order; rep numbers continue after first_rep[(name, ranks)]."""
    if interleave:
        order = [(m, p, k) for k in range(reps) for m in members for p in ranks]
    else:
        order = [(m, p, k) for m in members for p in ranks for k in range(reps)]
    return [(m, p, first_rep.get((m["name"], p), 0) + k + 1) for m, p, k in order]


def prepare_run(out, member, np_, rep, overrides, area="runs"):
    """A fresh run folder with the merged input case.nml and run.json (the run's CSV fields that do
    not come from its results); returns that record."""
    run_dir = os.path.join(out, area, slug(member["name"]), "np%d" % np_, "rep%d" % rep)
    if os.path.isdir(run_dir):
        shutil.rmtree(run_dir)  # never read a stale report.json
    os.makedirs(run_dir)
    overrides = list(overrides) + list(member["sweep"])
    with open(member["input"]) as f:
        groups = parse_namelist(f.read())
    groups = merge_overrides(groups, overrides + [("output", "directory", "'%s'" % os.path.join(run_dir, "out"))])
    header = "! %s with %s (tools/campaign.py)\n" % (member["input"], " ".join(
        "%s:%s=%s" % o for o in overrides) or "no overrides")
    write_namelist(groups, os.path.join(run_dir, "case.nml"), header)
    inp = os.path.abspath(member["input"])
    record = {"campaign": os.path.basename(out), "member": member["name"], "variant": member.get("variant", ""),
              "input": os.path.relpath(inp, ROOT) if inp.startswith(ROOT + os.sep) else member["input"],
              "overrides": " ".join("%s:%s=%s" % o for o in overrides), "ranks": np_, "rep": rep, "run_dir": run_dir}
    with open(os.path.join(run_dir, "run.json"), "w") as f:
        json.dump(record, f, indent=1)
    return record


def read_record(run_dir):
    """run.json of a run folder (its run_dir is where it is now: an earlier attempt is moved)."""
    with open(os.path.join(run_dir, "run.json")) as f:
        record = json.load(f)
    record["run_dir"] = run_dir
    return record


def error_message(log_path):
    """The program's error message in a run's log (first line with ERROR), else the runner's note."""
    try:
        with open(log_path, errors="replace") as f:
            lines = [line.strip() for line in f]
    except OSError:
        return ""
    for line in lines:
        if "ERROR" in line:
            return line[:300]
    notes = [line for line in lines if line.startswith("# campaign:")]
    return notes[-1][2:][:300] if notes else ""


def run_row(record, outcome):
    """The CSV row of one finished run: its record (prepare_run), its outcome (exit_status: int, or
    None when it never started; optional status, wall_seconds, started, load_before, job_id) and
    what it left in its folder (report.json, the .h5 file, the program's error message)."""
    run_dir = record["run_dir"]
    code = outcome.get("exit_status")
    row = {k: str(record[k]) for k in ("campaign", "member", "input", "overrides", "ranks", "rep")}
    row["variant"] = str(record.get("variant", ""))
    row.update(run_dir=run_dir, exit_status="" if code is None else str(code),
               wall_seconds=outcome.get("wall_seconds", ""), started=outcome.get("started", ""),
               load_before=outcome.get("load_before", ""), job_id=outcome.get("job_id", ""))
    report_path = os.path.join(run_dir, "out", "report.json")
    if os.path.exists(report_path):
        try:
            with open(report_path) as f:
                report = json.load(f)
                row.update(report_row(report))
                if report.get("history"):
                    row["_history"] = report["history"]
        except (OSError, ValueError) as e:
            row["status"] = "unreadable report.json: %s" % e
    h5 = sorted(glob.glob(os.path.join(run_dir, "out", "*.h5")))
    row["h5"] = h5[0] if h5 else ""
    if outcome.get("status"):
        row["status"] = outcome["status"]
    elif not row.get("status"):
        row["status"] = EXIT_MEANING.get(code, "exit %s" % code) + (
            "" if os.path.exists(report_path) else ", no report.json")
    if code != 0:
        row["message"] = error_message(os.path.join(run_dir, "log.txt"))
    return row


def write_meta(out, meta, append):
    """campaign.json: this invocation; invocations.jsonl: all of them (--append, resubmissions)."""
    if not append or not os.path.exists(os.path.join(out, "campaign.json")):
        with open(os.path.join(out, "campaign.json"), "w") as f:
            json.dump(meta, f, indent=2)
    with open(os.path.join(out, "invocations.jsonl"), "a") as f:
        f.write(json.dumps(meta) + "\n")


# ---------------------------------------------------------------- local back end
def run_local(args, plan, out, program, rows):
    """Run the plan here, one run after the other; campaign.csv is rewritten after every run."""
    csv_path = os.path.join(out, "campaign.csv")
    mpiexec = args.mpiexec or shutil.which("mpirun") or "mpirun"
    mpi_args = shlex.split(LOCAL_MPI_ARGS if args.mpi_args is None else args.mpi_args)
    env = dict(os.environ)
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    signal.signal(signal.SIGTERM, _terminate)
    progress = Progress()
    t_start = time.monotonic()
    last = "-"
    failures = 0
    last_rep = {}
    for member, np_, rep in plan:
        last_rep[(member["name"], np_)] = max(rep, last_rep.get((member["name"], np_), 0))
    for i, (member, np_, rep) in enumerate(plan, start=1):
        record = prepare_run(out, member, np_, rep, args.overrides, "dry-run" if args.dry_run else "runs")
        cmd = [mpiexec] + mpi_args + ["-n", str(np_), program, os.path.join(record["run_dir"], "case.nml")]
        if args.dry_run:
            print(" ".join(shlex.quote(c) for c in cmd))
            continue
        label = "[%d/%d] %s np%d rep %d/%d" % (i, len(plan), member["name"], np_, rep, last_rep[(member["name"], np_)])

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
        status, wall = run_one(cmd, os.path.join(record["run_dir"], "log.txt"), args.timeout, env, tick)
        row = run_row(record, {"exit_status": status, "status": "timeout" if status == TIMEOUT_STATUS else None,
                               "wall_seconds": "%.3f" % wall, "started": started, "load_before": "%.2f" % load})
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
    table = variant_table(rows)
    if table:
        print("\n" + table)
    return 1 if failures else 0


# ---------------------------------------------------------------- Slurm back end
# DIR/jobs.json lists one entry per job script (member, ranks, repetitions, script, job id, earlier
# attempts). A job's script runs its repetitions one after the other; each writes started.txt when
# it starts and exit.txt when it ends (exit status, end time, wall time), so the state of a run
# comes from those files, and from squeue (-t all: also finished jobs, for MinJobAge) while Slurm
# still knows the job, and from slurmstepd's "CANCELLED ... DUE TO TIME LIMIT" line in the job's
# error file after that. Slurm accounting (sacct) is not used.
JOBS_FILE = "jobs.json"
LOCAL_MPI_ARGS = "--oversubscribe --bind-to none"
SLURM_MPI_ARGS = "--bind-to core"
ACTIVE = {"PENDING", "RUNNING", "CONFIGURING", "COMPLETING", "SUSPENDED", "REQUEUED", "REQUEUE_HOLD",
          "REQUEUE_FED", "RESIZING", "SIGNALING", "STAGE_OUT", "STOPPED", "RESV_DEL_HOLD"}
ENDED = {"COMPLETED": "lost", "TIMEOUT": "timeout", "DEADLINE": "timeout", "CANCELLED": "cancelled",
         "PREEMPTED": "cancelled", "REVOKED": "cancelled"}  # any other end state (FAILED, NODE_FAIL,
FINISHED = ("completed", "failed", "timeout", "cancelled", "lost")  # OUT_OF_MEMORY, ...): failed


def load_jobs(out):
    path = os.path.join(out, JOBS_FILE)
    if not os.path.exists(path):
        return {"jobs": []}
    with open(path) as f:
        return json.load(f)


def save_jobs(out, data):
    path = os.path.join(out, JOBS_FILE)
    with open(path + ".tmp", "w") as f:
        json.dump(data, f, indent=1)
    os.replace(path + ".tmp", path)


def read_kv(path):
    """key=value lines of started.txt / exit.txt ({} when the file is not there)."""
    try:
        with open(path) as f:
            return dict(line.rstrip("\n").split("=", 1) for line in f if "=" in line)
    except OSError:
        return {}


def squeue_states():
    """{job id: (STATE, reason, submit time, command)} of this user's jobs that Slurm still knows, or None
    without squeue."""
    try:
        p = subprocess.run(["squeue", "-h", "-t", "all", "-u", str(os.getuid()), "-o", "%i|%T|%r|%V|%o"],
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as e:
        print("campaign: squeue failed (%s): states from the exit files only" % e, file=sys.stderr)
        return None
    if p.returncode != 0:
        print("campaign: squeue failed (%s): states from the exit files only" % p.stderr.strip(), file=sys.stderr)
        return None
    states = {}
    for line in p.stdout.splitlines():
        parts = line.strip().split("|", 4)
        if len(parts) == 5:
            states[parts[0]] = tuple(parts[1:])
    return states


def killed_by_slurm(job_dir, job_id):
    """'timeout' or 'cancelled' from slurmstepd's line in the job's error file, else None."""
    try:
        with open(os.path.join(job_dir, "slurm-%s.err" % job_id), errors="replace") as f:
            text = f.read()
    except OSError:
        return None
    m = re.search(r"\*\*\* JOB %s ON \S+ CANCELLED AT \S+( DUE TO TIME LIMIT)?" % re.escape(str(job_id)), text)
    return None if not m else ("timeout" if m.group(1) else "cancelled")


def run_outcome(run_dir, job_id, states):
    """State of one run of a Slurm job: pending, running, completed, failed, timeout, cancelled,
    lost (ended without a trace), not submitted, unknown (no squeue); plus the outcome for run_row."""
    started, ended = read_kv(os.path.join(run_dir, "started.txt")), read_kv(os.path.join(run_dir, "exit.txt"))
    job_id = ended.get("job_id") or started.get("job_id") or job_id or ""
    out = {"job_id": job_id, "started": started.get("started", ""), "load_before": started.get("load_before", ""),
           "wall_seconds": ended.get("wall_seconds", "")}
    squeue = (states or {}).get(job_id)
    slurm_state = squeue[0].split()[0] if squeue else None

    def end_kind():  # how Slurm ended the job, when it did
        if slurm_state in ENDED:
            return ENDED[slurm_state]
        if slurm_state and slurm_state not in ACTIVE:
            return "failed"
        return killed_by_slurm(os.path.dirname(run_dir), job_id) if job_id else None

    if ended:
        try:
            code = int(ended.get("exit_status", ""))
        except ValueError:
            code = None
        if ended.get("signal"):  # the script's TERM trap: time limit or scancel
            kind = end_kind() if end_kind() in ("timeout", "cancelled") else "failed"
            if kind == "timeout":
                return dict(out, state="timeout", exit_status=TIMEOUT_STATUS, status="timeout")
            return dict(out, state=kind, exit_status=code,
                        status="cancelled" if kind == "cancelled" else "killed by SIG%s" % ended["signal"])
        return dict(out, state="completed" if code == 0 else "failed", exit_status=code)
    if not job_id:
        return dict(out, state="not submitted")
    if states is None:
        return dict(out, state="unknown")
    if slurm_state in ACTIVE:
        return dict(out, state="running" if started and slurm_state != "PENDING" else "pending",
                    reason=squeue[1] if slurm_state == "PENDING" else "")
    kind = end_kind() or "lost"
    detail = {"lost": "lost: no exit.txt", "failed": "failed (%s)" % slurm_state}.get(kind, kind)
    return dict(out, state=kind, exit_status=TIMEOUT_STATUS if kind == "timeout" and started else None,
                status=detail + ("" if started else ", not started"))


def job_runs(out, job):
    """[(run_dir, job id)] of a jobs.json entry: its current runs, then those of earlier attempts."""
    runs = [(os.path.join(out, d), job.get("job_id")) for d in job["run_dirs"]]
    for attempt in job.get("previous", []):
        runs += [(os.path.join(out, d), attempt.get("job_id")) for d in attempt["run_dirs"]]
    return runs


def job_state(outcomes):
    """One word for a job from the states of its current runs."""
    states = [o["state"] for o in outcomes]
    for s in ("running", "pending", "not submitted", "unknown"):
        if s in states:
            return s
    if all(s == "completed" for s in states):
        return "completed"
    for s in ("timeout", "cancelled", "failed", "lost"):
        if s in states:
            if s == "failed":
                codes = sorted({str(o.get("exit_status")) for o in outcomes if o["state"] == "failed"
                                and o.get("exit_status") is not None})
                return "failed (exit %s)" % ",".join(codes) if codes else "failed"
            return s
    return states[0] if states else "unknown"


def survey(out, data, states):
    """[(job entry, [outcome of each current run], job state)]; adopts the job id of a script that
    was submitted by hand (it writes $SLURM_JOB_ID into started.txt)."""
    result = []
    for job in data["jobs"]:
        if not job.get("job_id"):  # a script submitted by hand that has not started yet: squeue's command
            script = os.path.join(out, job["script"])
            written = datetime.datetime.fromtimestamp(int(os.path.getmtime(script))).isoformat() \
                if os.path.exists(script) else "9"
            ids = [i for i, st in (states or {}).items() if st[3].split(" ")[0] == script and st[2] >= written]
            if ids:
                job["job_id"] = max(ids, key=natural_key)
                job["submitted"] = "by hand"
        outcomes = [run_outcome(os.path.join(out, d), job.get("job_id"), states) for d in job["run_dirs"]]
        if not job.get("job_id"):  # it has started (its started.txt has the id), or has ended
            ids = [o["job_id"] for o in outcomes if o["job_id"]]
            if ids:
                job["job_id"] = ids[0]
                job["submitted"] = "by hand"
        result.append((job, outcomes, job_state(outcomes)))
    return result


def job_script(args, out, member_name, np_, records, program):
    """The text of the job script that runs `records` (the repetitions of one member on np_ ranks)."""
    job_dir = os.path.dirname(records[0]["run_dir"])
    reps = " ".join(os.path.basename(r["run_dir"]) for r in records)
    tpn = args.tasks_per_node or np_
    if args.launcher == "srun":
        launch = "srun --mpi=%s" % args.srun_mpi
    else:
        mpi_args = SLURM_MPI_ARGS if args.mpi_args is None else args.mpi_args
        launch = " ".join([args.mpiexec or "mpirun"] + ["-n", str(np_)] + ([mpi_args] if mpi_args else []))
    sb = ["--job-name=%s" % ("fc_%s_np%d" % (slug(member_name), np_))[:100],
          "--ntasks=%d" % np_, "--ntasks-per-node=%d" % min(tpn, np_), "--cpus-per-task=1",
          "--time=%s" % args.time, "--mem-per-cpu=%s" % args.mem_per_rank,
          "--output=%s" % os.path.join(job_dir, "slurm-%j.out"), "--error=%s" % os.path.join(job_dir, "slurm-%j.err")]
    for opt in ("partition", "account", "qos", "constraint"):
        if getattr(args, opt):
            sb.append("--%s=%s" % (opt, getattr(args, opt)))
    sb += args.sbatch_args
    q = shlex.quote
    return "\n".join([
        "#!/bin/bash",
        "# feticontact campaign %s: %s on %d rank(s), %s." % (os.path.basename(out), member_name, np_, reps),
        "# Written by tools/campaign.py --scheduler slurm. Submit it by hand with `sbatch job.sh` from any",
        "# folder (paths are absolute); `sbatch job.sh rep2` runs only rep2; options on the sbatch",
        "# command line override the #SBATCH lines. Each repetition runs in its folder rep<k>/ next to",
        "# this script (merged input case.nml, program output log.txt, results out/) and leaves there",
        "# started.txt and exit.txt (exit status, end time), which `tools/campaign.py --collect DIR`",
        "# reads: no Slurm accounting is needed.",
    ] + ["#SBATCH " + s for s in sb] + [
        "",
        "set -u",
        "# one thread per rank: the MPI ranks are the parallelism, BLAS must not start threads of its own",
        "export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1",
        "# Open MPI refuses to start as root without these (containers, test machines)",
        "if [ \"$(id -u)\" -eq 0 ]; then export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1; fi",
        "",
        "program=%s" % q(program),
        "job_dir=%s" % q(job_dir),
        "reps=(\"$@\")  # the repetitions named on the sbatch line, else all of this job's",
        "[ ${#reps[@]} -gt 0 ] || reps=(%s)" % reps,
        "",
        "now() { date +%Y-%m-%dT%H:%M:%S; }",
        "finish() { # exit.txt of the current repetition: <exit status> [<signal>]",
        "  local t1",
        "  t1=$(date +%s.%N)",
        "  printf 'exit_status=%s\\nsignal=%s\\nended=%s\\nwall_seconds=%s\\njob_id=%s\\n' \"$1\" \"${2:-}\" \"$(now)\" \\",
        "    \"$(awk -v a=\"$t0\" -v b=\"$t1\" 'BEGIN {printf \"%.3f\", b - a}')\" \"${SLURM_JOB_ID:-}\" >\"$dir/exit.txt.part\"",
        "  mv \"$dir/exit.txt.part\" \"$dir/exit.txt\"",
        "}",
        "# at the time limit and on scancel Slurm sends SIGTERM (SIGKILL later): record it, then stop",
        "dir=\"\"",
        "t0=$(date +%s.%N)",
        "trap '[ -n \"$dir\" ] && finish 143 TERM; exit 143' TERM",
        "",
        "status=0",
        "for rep in \"${reps[@]}\"; do",
        "  dir=$job_dir/$rep",
        "  [ -f \"$dir/case.nml\" ] || { echo \"no $dir/case.nml\" >&2; status=2; dir=\"\"; continue; }",
        "  rm -rf \"$dir/out\" \"$dir/exit.txt\"",
        "  printf 'job_id=%s\\nstarted=%s\\nload_before=%s\\nnodes=%s\\n' \"${SLURM_JOB_ID:-}\" \"$(now)\" \\",
        "    \"$(cut -d' ' -f1 /proc/loadavg)\" \"${SLURM_JOB_NODELIST:-$(hostname)}\" >\"$dir/started.txt\"",
        "  echo \"$(now) $rep started\"",
        "  t0=$(date +%s.%N)",
        "  echo \"# %s $program $dir/case.nml\" >\"$dir/log.txt\"" % launch,
        "  %s \"$program\" \"$dir/case.nml\" >>\"$dir/log.txt\" 2>&1 &" % launch,
        "  wait $!",
        "  rc=$?",
        "  finish $rc",
        "  echo \"$(now) $rep exit $rc\"",
        "  [ $rc -eq 0 ] || status=$rc",
        "done",
        "dir=\"\"",
        "exit $status",
        ""])


def sbatch(script, extra=(), reps=()):
    """Submit a job script; returns the job id."""
    cmd = ["sbatch", "--parsable"] + list(extra) + [script] + list(reps)
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=os.path.dirname(script))
    if p.returncode != 0:
        raise RuntimeError("%s: %s" % (" ".join(shlex.quote(c) for c in cmd), (p.stderr or p.stdout).strip()))
    return p.stdout.strip().split(";")[0]


def submit_slurm(args, plan, out, program):
    """One job script per member and rank count (its repetitions run one after the other inside
    it); submitted unless --dry-run; never a second job for runs pending, running or done."""
    data = load_jobs(out)
    states = squeue_states() if any(j.get("job_id") for j in data["jobs"]) else {}
    current = {id(job): state for job, _, state in survey(out, data, states)}
    groups = {}
    for member, np_, rep in plan:
        groups.setdefault((member["name"], np_), (member, []))[1].append(rep)
    submitted = kept = 0
    for (name, np_), (member, reps) in groups.items():
        reps = sorted(reps)
        old = [j for j in data["jobs"] if j["member"] == name and j["ranks"] == np_ and set(j["reps"]) & set(reps)]
        if old and current[id(old[0])] != "not submitted":
            hint = ""
            if current[id(old[0])] not in ("pending", "running", "completed", "unknown"):
                hint = " (%s --resubmit failed --out %s sends it again)" % (TOOL, shlex.quote(out))
            print("campaign: %s np%d: job %s is %s, not submitted again%s" % (
                name, np_, old[0].get("job_id"), current[id(old[0])], hint))
            kept += 1
            continue
        records = [prepare_run(out, member, np_, rep, args.overrides) for rep in reps]
        job_dir = os.path.dirname(records[0]["run_dir"])
        script = os.path.join(job_dir, "job.sh" if reps[0] == 1 else "job_rep%d-%d.sh" % (reps[0], reps[-1]))
        with open(script, "w") as f:
            f.write(job_script(args, out, name, np_, records, program))
        os.chmod(script, 0o755)
        job = old[0] if old else {}
        job.update(member=name, ranks=np_, reps=reps, script=os.path.relpath(script, out),
                   run_dirs=[os.path.relpath(r["run_dir"], out) for r in records], job_id=None, submitted=None)
        if not old:
            data["jobs"].append(job)
        if args.dry_run:
            print("campaign: wrote %s (not submitted)" % script)
        else:
            try:
                job["job_id"] = sbatch(script)
            except (RuntimeError, OSError, subprocess.SubprocessError) as e:
                save_jobs(out, data)
                sys.exit("campaign: sbatch failed: %s" % e)
            job["submitted"] = datetime.datetime.now().isoformat(timespec="seconds")
            print("campaign: submitted job %s: %s np%d %s" % (job["job_id"], name, np_, "rep%d" % reps[0] if
                                                              len(reps) == 1 else "rep%d-%d" % (reps[0], reps[-1])))
            submitted += 1
        save_jobs(out, data)
    if not args.dry_run:
        print("campaign: %d jobs submitted, %d already there; jobs in %s" % (submitted, kept,
                                                                           os.path.join(out, JOBS_FILE)))
        print("campaign: %s --status %s  /  --collect %s [--wait]" % (TOOL, shlex.quote(out), shlex.quote(out)))
    return 0


def resubmit_slurm(args, out, which):
    """Send the runs of the jobs in the given end states again (only those runs; an earlier
    attempt's folder is kept as rep<k>.attemptN, so its row stays in the CSV)."""
    data = load_jobs(out)
    if not data["jobs"]:
        sys.exit("campaign: no %s in %s" % (JOBS_FILE, out))
    states = squeue_states()
    extra = ["--time=%s" % args.time] if args.time_given else []
    extra += ["--%s=%s" % (o, getattr(args, o)) for o in ("partition", "account", "qos", "constraint")
              if getattr(args, o)]
    extra += args.sbatch_args
    n = 0
    for job, outcomes, state in survey(out, data, states):
        redo = [(d, o) for d, o in zip(job["run_dirs"], outcomes) if o["state"] in which]
        if not redo:
            continue
        attempt = {"job_id": job.get("job_id"), "run_dirs": []}
        for d, o in redo:
            src = os.path.join(out, d)
            if os.path.exists(os.path.join(src, "started.txt")):  # keep what it measured
                k = 1
                while os.path.exists("%s.attempt%d" % (src, k)):
                    k += 1
                shutil.copytree(src, "%s.attempt%d" % (src, k), symlinks=True)
                attempt["run_dirs"].append("%s.attempt%d" % (d, k))
            for name in os.listdir(src):
                if name not in ("case.nml", "run.json"):
                    p = os.path.join(src, name)
                    shutil.rmtree(p) if os.path.isdir(p) and not os.path.islink(p) else os.remove(p)
        if attempt["run_dirs"]:
            job.setdefault("previous", []).append(attempt)
        reps = [os.path.basename(d) for d, _ in redo]
        try:
            job["job_id"] = sbatch(os.path.join(out, job["script"]), extra, reps if len(redo) < len(outcomes) else [])
        except (RuntimeError, OSError, subprocess.SubprocessError) as e:
            save_jobs(out, data)
            sys.exit("campaign: sbatch failed: %s" % e)
        job["submitted"] = datetime.datetime.now().isoformat(timespec="seconds")
        print("campaign: %s np%d was %s: submitted again as job %s (%s)" % (
            job["member"], job["ranks"], state, job["job_id"], " ".join(reps)))
        save_jobs(out, data)
        n += 1
    print("campaign: %d jobs submitted again" % n)
    return 0


def status_table(out, surveyed):
    lines = ["| member | ranks | job | state | runs |", "|---|---:|---:|---|---|"]
    for job, outcomes, state in surveyed:
        runs = []
        for d, o in zip(job["run_dirs"], outcomes):
            s = o["state"]
            if s == "failed" and o.get("exit_status") is not None:
                s += " (exit %s)" % o["exit_status"]
            elif s == "pending" and o.get("reason"):
                s += " (%s)" % o["reason"]
            runs.append("%s %s" % (os.path.basename(d), s))
        lines.append("| %s | %d | %s | %s | %s |" % (job["member"], job["ranks"], job.get("job_id") or "-", state,
                                                      ", ".join(runs)))
    counts = {}
    for _, _, state in surveyed:
        key = state.split(" (")[0]
        counts[key] = counts.get(key, 0) + 1
    lines.append("")
    lines.append("%d jobs: %s" % (len(surveyed), ", ".join("%d %s" % (v, k) for k, v in counts.items())))
    return "\n".join(lines)


def collect_slurm(out, wait, poll):
    """Rows of every finished run (earlier attempts too) into campaign.csv; with wait, first wait
    until no job is pending or running."""
    data = load_jobs(out)
    if not data["jobs"]:
        sys.exit("campaign: no %s in %s (submitted with --scheduler slurm?)" % (JOBS_FILE, out))
    while True:
        states = squeue_states()
        surveyed = survey(out, data, states)
        active = [s for _, _, s in surveyed if s in ("pending", "running")]
        if not wait or not active:
            break
        print("campaign: %s waiting: %d jobs pending or running" % (
            datetime.datetime.now().strftime("%H:%M:%S"), len(active)), file=sys.stderr)
        time.sleep(poll)
    save_jobs(out, data)
    rows, unfinished, failures = [], 0, 0
    for job, _, _ in surveyed:
        for run_dir, job_id in job_runs(out, job):
            o = run_outcome(run_dir, job_id, states)
            if o["state"] not in FINISHED:
                unfinished += 1
                continue
            row = run_row(read_record(run_dir), o)
            failures += row["exit_status"] != "0"
            rows.append(row)
    csv_path = os.path.join(out, "campaign.csv")
    write_csv(csv_path, rows)
    print(status_table(out, surveyed))
    print("\ncampaign: %d runs finished, %d failed, %d not finished; CSV %s\n" % (len(rows), failures, unfinished,
                                                                                 csv_path))
    print(summary_table(rows))
    table = variant_table(rows)
    if table:
        print("\n" + table)
    return 1 if failures else (3 if unfinished else 0)


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
    ap.add_argument("--variant", action="append", default=[], metavar="NAME[:VAR=VALUE;...]",
                    help="a solver variant: a name and &solver settings (GROUP:VAR=VALUE for another group); "
                         "every member runs once per variant (repeatable; see tools/variants.py)")
    ap.add_argument("--variants", metavar="V1,V2,...",
                    help="one variant per value of --variant-variable: &solver preconditioner = 'V1', ...")
    ap.add_argument("--variant-variable", default="preconditioner",
                    help="the &solver variable that --variants sets (default %(default)s)")
    ap.add_argument("--program", default=os.path.join(ROOT, "build", "bin", "feticontact"),
                    help="feticontact executable (default %(default)s)")
    ap.add_argument("--mpiexec", help="MPI launcher (default: mpirun; local: its full path)")
    ap.add_argument("--mpi-args", help="launcher flags (default: local %r, slurm %r)" % (LOCAL_MPI_ARGS,
                                                                                          SLURM_MPI_ARGS))
    ap.add_argument("--timeout", type=float, default=0, help="local: kill a run after this many seconds (0: never)")
    ap.add_argument("--max-load", type=float, default=0,
                    help="local: before each run, wait until the 1-minute load average is below this (0: do not "
                         "wait); the runs' own ranks count too, so use about cores + 0.5")
    ap.add_argument("--max-wait", type=float, default=600, help="local: longest wait for --max-load per run [s]")
    ap.add_argument("--interleave", action="store_true",
                    help="local: run repetition 1 of every member, then repetition 2, ... (spreads machine drift)")
    ap.add_argument("--append", action="store_true", help="add runs (repetitions) to the campaign in --out")
    ap.add_argument("--dry-run", action="store_true",
                    help="local: write the merged inputs under DIR/dry-run/ and print the commands; slurm: write "
                         "the run folders and job scripts under DIR/runs/ without submitting")
    ap.add_argument("--summary", metavar="DIR_OR_CSV", help="only print the medians of an existing campaign")
    sl = ap.add_argument_group("Slurm (--scheduler slurm; clients find the cluster as usual, or via SLURM_CONF)")
    sl.add_argument("--scheduler", choices=("local", "slurm"), default="local",
                    help="local: run here one after the other (default); slurm: one sbatch job per member "
                         "and rank count, its repetitions one after the other inside it")
    sl.add_argument("--launcher", choices=("mpirun", "srun"), default="mpirun",
                    help="inside the job: mpirun (default) or srun --mpi=SRUN_MPI")
    sl.add_argument("--srun-mpi", default="pmix", help="MPI plugin of srun (default %(default)s; srun --mpi=list)")
    sl.add_argument("--time", default=None, help="time limit of a job, sbatch format (default 1:00:00)")
    sl.add_argument("--mem-per-rank", default="2G",
                    help="memory per rank: --mem-per-cpu with one cpu per task (default %(default)s; see "
                         "docs/CLUSTER.md)")
    sl.add_argument("--tasks-per-node", type=int, default=0,
                    help="ranks per node (default: all ranks of a job on one node); the cores of your nodes")
    sl.add_argument("--partition")
    sl.add_argument("--account")
    sl.add_argument("--qos")
    sl.add_argument("--constraint")
    sl.add_argument("--sbatch-arg", dest="sbatch_args", action="append", default=[], metavar="OPTION",
                    help="any other sbatch option, e.g. --sbatch-arg=--exclusive (repeatable)")
    sl.add_argument("--status", metavar="DIR", help="state of every job and run of a Slurm campaign")
    sl.add_argument("--collect", metavar="DIR", help="campaign.csv from the finished runs, and the medians")
    sl.add_argument("--wait", action="store_true", help="after submitting, or with --collect: wait until no job "
                                                        "is pending or running, then collect")
    sl.add_argument("--poll", type=float, default=30, help="seconds between squeue calls of --wait (default 30)")
    sl.add_argument("--resubmit", metavar="STATES",
                    help="submit the runs of --out again that ended in these states (comma list of failed, "
                         "timeout, cancelled, lost; 'failed' includes timeout and lost)")
    args = ap.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `| head` ends quietly
    args.time_given = args.time is not None
    args.time = args.time or "1:00:00"

    if args.summary:
        path = os.path.join(args.summary, "campaign.csv") if os.path.isdir(args.summary) else args.summary
        rows = read_csv(path)
        print(summary_table(rows))
        table = variant_table(rows)
        if table:
            print("\n" + table)
        return 0
    if args.status:
        out = os.path.abspath(args.status)
        data = load_jobs(out)
        if not data["jobs"]:
            sys.exit("campaign: no %s in %s" % (JOBS_FILE, out))
        surveyed = survey(out, data, squeue_states())
        save_jobs(out, data)
        print(status_table(out, surveyed))
        return 0
    if args.collect:
        return collect_slurm(os.path.abspath(args.collect), args.wait, args.poll)
    if args.resubmit:
        which = set()
        for w in args.resubmit.split(","):
            w = w.strip()
            if w not in ("failed", "timeout", "cancelled", "lost"):
                ap.error("--resubmit: expected failed, timeout, cancelled or lost, got %r" % w)
            which |= {"failed", "timeout", "lost"} if w == "failed" else {w}
        out = os.path.abspath(args.out)
        resubmit_slurm(args, out, which)
        return collect_slurm(out, True, args.poll) if args.wait else 0
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
    slurm = args.scheduler == "slurm"
    if slurm and not args.dry_run and not shutil.which("sbatch"):
        ap.error("--scheduler slurm: no sbatch on PATH (tools/local_slurm.sh starts a Slurm on this machine)")

    inputs = expand_inputs(args.inputs)
    try:
        variants = solver_variants.collect(args.variant, args.variants, args.variant_variable)
        if variants and os.access(program, os.X_OK):
            with open(inputs[0]) as f:
                groups = merge_overrides(parse_namelist(f.read()), args.overrides)
            solver_variants.check_variants(variants, groups, program, write_namelist,
                                           None if slurm else (args.mpiexec or shutil.which("mpirun")),
                                           shlex.split(LOCAL_MPI_ARGS if args.mpi_args is None else args.mpi_args)
                                           if not slurm else ())
    except ValueError as e:
        sys.exit("campaign: %s" % e)
    members = build_members(inputs, args.sweep, variants)
    out = os.path.abspath(args.out)
    csv_path = os.path.join(out, "campaign.csv")
    os.makedirs(out, exist_ok=True)
    first_rep, rows = {}, []
    if slurm:  # the repetitions already there: jobs.json
        if args.append:
            for job in load_jobs(out)["jobs"]:
                key = (job["member"], job["ranks"])
                first_rep[key] = max(first_rep.get(key, 0), max(job["reps"]))
    else:
        rows = read_csv(csv_path) if args.append and os.path.exists(csv_path) else []
        if not args.append and os.path.exists(csv_path) and not args.dry_run:
            os.replace(csv_path, csv_path + ".previous")
            print("campaign: moved the existing %s to campaign.csv.previous" % csv_path, file=sys.stderr)
        for r in rows:
            key = (r["member"], int(r["ranks"]))
            first_rep[key] = max(first_rep.get(key, 0), int(r.get("rep") or 0))
    plan = plan_runs(members, ranks, args.reps, args.interleave, first_rep)

    meta = {"command": [sys.argv[0]] + sys.argv[1:], "cwd": os.getcwd(), "program": program,
            "program_mtime": datetime.datetime.fromtimestamp(os.path.getmtime(program)).isoformat(timespec="seconds")
            if os.path.exists(program) else None,
            "git_commit": git_commit(), "host": socket.gethostname(), "cpus": os.cpu_count(),
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "inputs": inputs, "ranks": ranks, "reps": args.reps, "scheduler": args.scheduler,
            "variants": [{"name": v["name"], "settings": solver_variants.describe(v)} for v in variants]}
    if not args.dry_run:
        write_meta(out, meta, args.append)
    if not slurm:
        return run_local(args, plan, out, program, rows)
    submit_slurm(args, plan, out, program)
    if args.wait and not args.dry_run:
        return collect_slurm(out, True, args.poll)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (KeyboardInterrupt, Terminated) as e:
        sys.exit("campaign: stopped (%s); the CSV has the runs that finished" % (e or "interrupt"))
