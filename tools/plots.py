#!/usr/bin/python3
"""Figures from tools/campaign.py results and from one run's HDF5 file (PNG, matplotlib Agg).

    tools/plots.py weak CAMPAIGN [CAMPAIGN ...]            iterations and phase times against subdomains
    tools/plots.py reconstruction CAMPAIGN [CAMPAIGN ...]  reconstruction cost, new (Eq. 24) vs standard (Eq. 10)
    tools/plots.py tolerance CAMPAIGN [--reference H5]     speed against accuracy of a --sweep solver:tol=... campaign
    tools/plots.py hertz RUN_OUT_DIR_OR_H5                 contact pressure against the Hertz solution
    tools/plots.py history RUN_OUT_DIR_OR_REPORT           force against indentation of a load history (&history)

CAMPAIGN is a campaign directory (tools/campaign.py --out) or its campaign.csv.
Every subcommand writes its PNG(s) next to its data (the folder of the first
CAMPAIGN, of the run's .h5) or under --figures DIR, prints a Markdown table of
what it plotted, and takes --help. Times are the
max over ranks; over repetitions the median is plotted, with the min-max range
as error bars (--stat min plots the fastest repetition instead, the robust
choice on a shared machine); iteration counts do not depend on the repetition.
Only runs that exited 0 are plotted, except in `tolerance`, where runs that
stopped on the KKT check (exit 4) are plotted too (a loose tolerance may fail
it; its KKT residual is what the figure shows).

Examples (repository root; --figures docs/figures replaces the repository's figures):
    tools/plots.py weak output/campaigns/weak_h4 output/campaigns/weak_h8
    tools/plots.py reconstruction output/campaigns/weak_h4 output/campaigns/weak_h8
    tools/plots.py tolerance output/campaigns/tol_block --name tolerance_block
    tools/plots.py tolerance output/campaigns/tol_cube --name tolerance_cube
    tools/plots.py hertz output/campaigns/hertz/runs/hertz/np2/rep1/out

Python: /usr/bin/python3 (numpy, matplotlib, h5py).
"""
import argparse
import csv
import json
import math
import os
import re
import signal
import statistics
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARKERS = "osD^v<>p*h"

# Set-up phases of a campaign.csv written before its setup_max column (tools/campaign.py SETUP_PHASES).
SETUP_PHASES = ["mesh", "assembly", "factorization", "B and G", "explicit F", "coarse setup", "orthonormal coarse",
                "preconditioner setup"]

# Phases shown in the weak-scaling time figure: label -> timer names summed (max over ranks);
# SETUP: tools/campaign.py's set-up (every phase before the solve except the dual set-up) without the
# factorization of K^s, its own row: the rows before the total are disjoint.
SETUP = "setup"
PHASE_GROUPS = [
    ("set-up without the factorization (mesh, K, B, G, explicit F, GG^T)", SETUP),
    ("factorization of K^s (K^+)", ["factorization"]),
    ("dual set-up (d, lambda~, the norm of PFP)", ["dual setup"]),
    ("SMALBE/MPRGP solve", ["solve"]),
    ("reconstruction + primal", ["dual gradient", "rec new", "rec standard", "primal"]),
    ("KKT check + output", ["kkt", "output"]),
    ("total", ["total"]),
    ("(inside the above) F actions", ["F action"]),
    ("(inside the above) coarse solves", ["coarse solve"]),
]


# ---------------------------------------------------------------- campaign data
def phase_column(phase, stat):
    return "t_%s_%s" % (re.sub(r"[^a-z0-9]+", "_", phase.lower()).strip("_"), stat)


def campaign_csv(path):
    return os.path.join(path, "campaign.csv") if os.path.isdir(path) else path


def figures_dir(args, data):
    """--figures, else the folder of `data` (a campaign directory or CSV, a run's .h5)."""
    if args.figures:
        return args.figures
    return os.path.dirname(os.path.abspath(campaign_csv(data)))


def load_campaign(path):
    csv_path = campaign_csv(path)
    if not os.path.exists(csv_path):
        sys.exit("plots: no campaign CSV at %s" % csv_path)
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    name = os.path.basename(os.path.dirname(os.path.abspath(csv_path)))
    return name, rows


def num(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def ok_rows(rows, allow=(0,)):
    return [r for r in rows if num(r.get("exit_status")) in allow]


def by_member(rows):
    """{(member, ranks): [rows]} in first-appearance order."""
    out = {}
    for r in rows:
        out.setdefault((r["member"], r["ranks"]), []).append(r)
    return out


def values(runs, col):
    v = [num(r.get(col)) for r in runs]
    return [x for x in v if x is not None]


def summed(run, phases, stat="max"):
    if phases == SETUP:
        factorization = num(run.get(phase_column("factorization", stat))) or 0.0
        if num(run.get("setup_" + stat)) is not None:
            return num(run.get("setup_" + stat)) - factorization
        v = [x for x in (num(run.get(phase_column(p, stat))) for p in SETUP_PHASES if p != "factorization")
             if x is not None]
        return sum(v) if v else None
    v = [num(run.get(phase_column(p, stat))) for p in phases]
    return sum(v) if v and all(x is not None for x in v) else None


CENTRE = {"stat": "median"}  # --stat: the plotted value of repeated measurements


def med_range(xs):
    """(central value, min, max) of repeated measurements; the central value is the
    median, or the minimum with --stat min (more robust when other jobs share the cores)."""
    if not xs:
        return None, None, None
    return (min(xs) if CENTRE["stat"] == "min" else statistics.median(xs)), min(xs), max(xs)


def family_points(rows):
    """One point per member: subdomains, iteration counts, medians of times."""
    pts = []
    for (member, ranks), runs in by_member(ok_rows(rows)).items():
        if not values(runs, "subdomains"):  # no report.json (write_report = .false.)
            print("plots: %s has no report data, skipped" % member, file=sys.stderr)
            continue
        p = {"member": member, "ranks": ranks, "n": len(runs), "subdomains": values(runs, "subdomains")[0]}
        for col in ("outer_iterations", "hessian_multiplications", "primal_dofs", "dual_dofs", "peak_rss_max_bytes",
                    "peak_rss_sum_bytes", "rec_new_seconds", "rec_standard_seconds", "rec_standard_assembly",
                    "rec_standard_factorization", "rec_standard_solve", "kkt_max", "alpha_difference",
                    "active_contact"):
            p[col] = med_range(values(runs, col))
        # the phases of one repetition, the one whose total is the median (--stat min: the
        # fastest): its columns add up to its total (up to the untimed rest); the error bars
        # span each phase's min..max over the repetitions
        timed = [r for r in runs if summed(r, ["total"]) is not None]
        rep = None
        if timed:
            ordered = sorted(timed, key=lambda r: summed(r, ["total"]))
            rep = ordered[0] if CENTRE["stat"] == "min" else ordered[(len(ordered) - 1) // 2]
        for label, phases in PHASE_GROUPS:
            _, lo, hi = med_range([x for x in (summed(r, phases) for r in runs) if x is not None])
            p[label] = (summed(rep, phases) if rep is not None else None, lo, hi)
        pts.append(p)
    pts.sort(key=lambda p: p["subdomains"])
    return pts


def errorbars(triples):
    med = np.array([t[0] if t[0] is not None else np.nan for t in triples], dtype=float)
    lo = np.array([t[1] if t[1] is not None else np.nan for t in triples], dtype=float)
    hi = np.array([t[2] if t[2] is not None else np.nan for t in triples], dtype=float)
    return med, np.vstack([med - lo, hi - med])


def family_label(name, pts):
    ranks = sorted({p["ranks"] for p in pts})
    return "%s (%s rank%s)" % (name, ",".join(ranks), "" if ranks == ["1"] else "s")


def save(fig, figures, name):
    os.makedirs(figures, exist_ok=True)
    path = os.path.join(figures, name + ".png")
    fig.savefig(path, dpi=130, bbox_inches="tight")
    plt.close(fig)
    print("wrote %s" % os.path.relpath(path, os.getcwd()))
    return path


def subdomain_axis(ax, xs):
    ax.set_xscale("log", base=2)
    ax.set_xticks(sorted(set(xs)))
    ax.set_xticklabels([str(int(x)) for x in sorted(set(xs))])
    ax.set_xlabel("subdomains")
    ax.grid(True, which="both", alpha=0.3)


def g(x, f="%.3g"):
    return "-" if x is None else f % x


# ---------------------------------------------------------------- (a) weak scaling
def scaling_kind(families):
    """'Weak scaling' when the ranks grow with the subdomains; on a fixed rank count the figure shows
    the cost against the number of subdomains (more, smaller subdomains per rank), not weak scaling."""
    ranks = {r["ranks"] for _, rows in families for r in ok_rows(rows)}
    if len(ranks) == 1:
        return "Cost against subdomains on %s rank%s (fixed ranks, not weak scaling)" % (
            next(iter(ranks)), "" if ranks == {"1"} else "s")
    return "Weak scaling"


def cmd_weak(args):
    families = [load_campaign(c) for c in args.campaigns]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    allx = []
    print("| family | subdomains | ranks | runs | primal dofs | outer | Hessian | " +
          " | ".join(lbl for lbl, _ in PHASE_GROUPS) + " | RSS max [MiB] |")
    print("|---|" + "---:|" * (7 + len(PHASE_GROUPS)))
    for k, (name, rows) in enumerate(families):
        pts = family_points(rows)
        if not pts:
            print("plots: %s has no successful run, skipped" % name, file=sys.stderr)
            continue
        x = [p["subdomains"] for p in pts]
        allx += x
        lbl = family_label(name, pts)
        ax.plot(x, [p["outer_iterations"][0] for p in pts], "--", marker=MARKERS[k], color="C%d" % k,
                label="%s: outer" % lbl)
        ax.plot(x, [p["hessian_multiplications"][0] for p in pts], "-", marker=MARKERS[k], color="C%d" % k,
                label="%s: Hessian mult." % lbl)
        for p in pts:
            print("| %s | %d | %s | %d | %s | %s | %s | %s | %s |" % (
                name, p["subdomains"], p["ranks"], p["n"], g(p["primal_dofs"][0], "%d"),
                g(p["outer_iterations"][0], "%d"), g(p["hessian_multiplications"][0], "%d"),
                " | ".join(g(p[lbl_][0]) for lbl_, _ in PHASE_GROUPS),
                g(None if p["peak_rss_max_bytes"][0] is None else p["peak_rss_max_bytes"][0] / 2**20, "%.0f")))
    print("times [s]: of the repetition with the %s total (one repetition per row, not per-column "
          "medians); each phase is its max over ranks, so the phases add up to the total only up to the "
          "untimed rest and the ranks' imbalance (a rank's wait counts in the phase it waits in); the "
          "'(inside the above)' columns are parts of the others" % ("smallest" if CENTRE["stat"] == "min" else "median"))
    subdomain_axis(ax, allx)
    ax.set_ylabel("count")
    ax.set_ylim(bottom=0)
    ax.set_title("%s: SMALBE outer iterations and Hessian multiplications" % scaling_kind(families))
    ax.legend(fontsize=7)
    save(fig, figures_dir(args, args.campaigns[0]), args.name + "_iterations")

    n = len(families)
    fig, axes = plt.subplots(1, n, figsize=(5.6 * n, 4.4), squeeze=False, sharey=True)
    for k, (name, rows) in enumerate(families):
        ax = axes[0][k]
        pts = family_points(rows)
        if not pts:
            continue
        x = [p["subdomains"] for p in pts]
        for j, (lbl, _) in enumerate(PHASE_GROUPS):
            med, err = errorbars([p[lbl] for p in pts])
            if np.all(np.isnan(med)):
                continue
            ax.errorbar(x, med, yerr=err, marker=MARKERS[j % len(MARKERS)], capsize=3, label=lbl,
                        color="k" if lbl == "total" else "C%d" % j, lw=2 if lbl == "total" else 1,
                        ls=":" if lbl.startswith("(inside") else "-")
        subdomain_axis(ax, x)
        ax.set_yscale("log")
        ax.set_title(family_label(name, pts), fontsize=10)
        if k == 0:
            ax.set_ylabel("time [s] (max over ranks; the repetition with the %s total, bars: min-max)"
                          % ("smallest" if CENTRE["stat"] == "min" else "median"), fontsize=8)
        ax.legend(fontsize=7)
    fig.suptitle("%s: time per phase" % scaling_kind(families))
    save(fig, figures_dir(args, args.campaigns[0]), args.name + "_times")


# ---------------------------------------------------------------- (b) reconstruction
def cmd_reconstruction(args):
    families = [load_campaign(c) for c in args.campaigns]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    allx = []
    print("| family | subdomains | ranks | active contact rows | new [s] | standard [s] | assembly | "
          "factorization | solve | standard/new | alpha difference |")
    print("|---|" + "---:|" * 10)
    for k, (name, rows) in enumerate(families):
        pts = family_points(rows)
        if not pts:
            continue
        x = [p["subdomains"] for p in pts]
        allx += x
        lbl = family_label(name, pts)
        med, err = errorbars([p["rec_standard_seconds"] for p in pts])
        ax.errorbar(x, med, yerr=err, marker=MARKERS[k], color="C%d" % k, capsize=3,
                    label="%s: standard (Eq. 10: G_A G_A^T assembled, factorized, solved)" % lbl)
        med, err = errorbars([p["rec_new_seconds"] for p in pts])
        ax.errorbar(x, med, yerr=err, marker=MARKERS[k], color="C%d" % k, ls="--", mfc="none", capsize=3,
                    label="%s: new (Eq. 14 + 24: one coarse solve, alpha - mu^)" % lbl)
        if args.breakdown:
            for part, ls in (("rec_standard_factorization", ":"), ("rec_standard_assembly", "-.")):
                ax.plot(x, [p[part][0] for p in pts], ls=ls, color="C%d" % k, lw=0.8,
                        label="%s: standard, %s only" % (lbl, part.split("_")[-1]))
        for p in pts:
            new, std = p["rec_new_seconds"][0], p["rec_standard_seconds"][0]
            print("| %s | %d | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
                name, p["subdomains"], p["ranks"], g(p["active_contact"][0], "%d"), g(new), g(std),
                g(p["rec_standard_assembly"][0]), g(p["rec_standard_factorization"][0]),
                g(p["rec_standard_solve"][0]), g(std / new if new and std else None, "%.0f"),
                g(p["alpha_difference"][0], "%.1e")))
    print("times [s]: of the repetition with the %s total (one repetition per row, not per-column "
          "medians); each phase is its max over ranks, so the phases add up to the total only up to the "
          "untimed rest and the ranks' imbalance (a rank's wait counts in the phase it waits in); the "
          "'(inside the above)' columns are parts of the others" % ("smallest" if CENTRE["stat"] == "min" else "median"))
    subdomain_axis(ax, allx)
    ax.set_yscale("log")
    ax.set_ylabel("seconds (max over ranks; %s, min-max of repetitions)" % CENTRE["stat"])
    ax.set_title("Rigid body amplitudes: cost of the two reconstructions")
    ax.legend(fontsize=7)
    save(fig, figures_dir(args, args.campaigns[0]), args.name)


# ---------------------------------------------------------------- (c) tolerance sweep
def read_h5(path):
    import h5py
    with h5py.File(path, "r") as h5:
        return h5["coordinates"][...], h5["displacement"][...]


def report_of(run):
    path = os.path.join(run["run_dir"], "out", "report.json")
    with open(path) as f:
        return json.load(f)


def block_exact_error(run):
    """docs/CASES.md `block`: max |u - u_exact| / max |u_exact|, u_exact = (nu p x/E, nu p y/E, -p z/E)."""
    case = report_of(run)["case"]
    p, young, nu = case["load"]["top_pressure"], case["material"]["young"], case["material"]["poisson"]
    x, u = read_h5(run["h5"])
    exact = np.column_stack([nu * p * x[:, 0] / young, nu * p * x[:, 1] / young, -p * x[:, 2] / young])
    return float(np.abs(u - exact).max() / np.abs(exact).max())


def reference_error(run, ref):
    """max |u - u_ref| / max |u_ref|; nodes matched by position when the layouts differ."""
    xr, ur = ref
    x, u = read_h5(run["h5"])
    if x.shape != xr.shape or not np.array_equal(x, xr):
        keys = {tuple(k): i for i, k in enumerate(np.round(xr * 1e9).astype(np.int64))}
        idx = np.array([keys.get(tuple(k), -1) for k in np.round(x * 1e9).astype(np.int64)])
        if (idx < 0).any():
            raise ValueError("%s: nodes not in the reference mesh" % run["h5"])
        ur = ur[idx]
    return float(np.abs(u - ur).max() / np.abs(ur).max())


def cmd_tolerance(args):
    name, rows = load_campaign(args.campaign)
    rows = ok_rows(rows, allow=(0, 4))  # exit 4: stopped on the KKT check, results written
    groups = by_member(rows)
    if not groups:
        sys.exit("plots: %s has no run with results" % name)
    members = []
    for (member, ranks), runs in groups.items():
        if not values(runs, "tol"):
            print("plots: %s has no report data, skipped" % member, file=sys.stderr)
            continue
        tol = values(runs, "tol")[0]
        with_h5 = [r for r in runs if r.get("h5") and os.path.exists(r["h5"])]
        members.append({"member": member, "ranks": ranks, "tol": tol, "runs": runs, "h5run": with_h5[0] if with_h5
                        else None, "shape": runs[0].get("shape")})
    members.sort(key=lambda m: -m["tol"])
    mode = args.error
    if mode == "auto":
        mode = "exact" if all(m["shape"] == "plane" for m in members) else "reference"
    ref_label = ""
    if mode == "reference":
        if args.reference:
            ref = read_h5(args.reference)
            ref_label = "reference %s" % args.reference
        else:
            tight = members[-1]
            if tight["h5run"] is None:
                sys.exit("plots: the tightest member %s has no .h5; give --reference" % tight["member"])
            ref = read_h5(tight["h5run"]["h5"])
            ref_label = "reference: the tol = %g run" % tight["tol"]
            members = members[:-1]
    for m in members:
        m["error"] = None
        if m["h5run"] is None:
            continue
        m["error"] = block_exact_error(m["h5run"]) if mode == "exact" else reference_error(m["h5run"], ref)
    time_col = phase_column(args.time, "max")

    def pick(col):
        return [med_range(values(m["runs"], col)) for m in members]

    t = pick(time_col)
    hess = [m[0] for m in pick("hessian_multiplications")]
    kkt = [m[0] for m in pick("kkt_max")]
    err = [m["error"] for m in members]
    tols = [m["tol"] for m in members]
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5))
    xsets = [("largest relative KKT residual", kkt),
             ("max |u - u_exact| / max |u_exact|" if mode == "exact" else "max |u - u_ref| / max |u_ref|", err)]
    for i, (xlabel, xs) in enumerate(xsets):
        xs_ = np.array([np.nan if v is None else v for v in xs], dtype=float)
        med, e = errorbars(t)
        ax = axes[0][i]
        ax.errorbar(xs_, med, yerr=e, marker="o", capsize=3)
        ax.set_ylabel("%s time [s] (max over ranks; %s)" % (args.time, CENTRE["stat"]))
        ax.set_yscale("log")
        ax2 = axes[1][i]
        ax2.plot(xs_, hess, marker="s", color="C1")
        ax2.set_ylabel("Hessian multiplications")
        for a in (ax, ax2):
            a.set_xscale("log")
            a.invert_xaxis()
            a.grid(True, which="both", alpha=0.3)
            a.set_xlabel(xlabel)
        for a, ys in ((ax, med), (ax2, hess)):
            for xv, yv, tol in zip(xs_, ys, tols):
                if np.isfinite(xv) and yv is not None and np.isfinite(yv):
                    a.annotate("%.0e" % tol, (xv, yv), textcoords="offset points", xytext=(4, 4), fontsize=7)
    fig.suptitle("%s: speed against accuracy (points: solver tol; %s)" % (
        name, "error against the exact solution" if mode == "exact" else ref_label), fontsize=10)
    save(fig, figures_dir(args, args.campaign), args.name or "tolerance_" + name)
    print("| tol | outer | Hessian | %s time [s] | spread | largest KKT residual | error (%s) | exit |" % (
        args.time, "exact" if mode == "exact" else "reference"))
    print("|---:|---:|---:|---:|---:|---:|---:|---|")
    for m, tt in zip(members, t):
        spread = (tt[2] - tt[1]) / tt[0] if tt[0] else None
        print("| %.0e | %s | %s | %s | %s | %s | %s | %s |" % (
            m["tol"], g(statistics.median(values(m["runs"], "outer_iterations")), "%d"),
            g(statistics.median(values(m["runs"], "hessian_multiplications")), "%d"), g(tt[0]),
            "-" if spread is None or len(m["runs"]) < 2 else "%.0f%%" % (100 * spread),
            g(statistics.median(values(m["runs"], "kkt_max")), "%.1e"), g(m["error"], "%.1e"),
            ",".join(sorted({r["exit_status"] for r in m["runs"]}))))
    print("time: max over ranks, %s over repetitions; spread = (max - min)/median" % CENTRE["stat"])
    if ref_label:
        print(ref_label)


# ---------------------------------------------------------------- (d) Hertz
def cmd_hertz(args):
    import h5py
    path = args.run
    if os.path.isdir(path):
        h5s = sorted(f for f in os.listdir(path) if f.endswith(".h5"))
        if len(h5s) != 1:
            sys.exit("plots: expected one .h5 file in %s, found %s" % (path, h5s))
        path = os.path.join(path, h5s[0])
    report_path = args.report or os.path.join(os.path.dirname(path), "report.json")
    with open(report_path) as f:
        report = json.load(f)
    case = report["case"]
    if case["obstacle"]["shape"] != "sphere":
        sys.exit("plots: hertz needs a sphere obstacle (got %s)" % case["obstacle"]["shape"])
    young, nu, radius = case["material"]["young"], case["material"]["poisson"], case["obstacle"]["radius"]
    lx, ly = case["mesh"]["lengths"][:2]
    with h5py.File(path, "r") as h5:
        xc = h5["contact_coordinates"][...]
        pc = h5["contact_pressure"][...]
    r = np.hypot(xc[:, 0] - lx / 2, xc[:, 1] - ly / 2)
    force = report["contact"]["total_force"]
    estar = young / (1 - nu**2)
    a = (3 * force * radius / (4 * estar)) ** (1 / 3)
    p0 = 3 * force / (2 * math.pi * a**2)
    hertz = p0 * np.sqrt(np.clip(1 - r**2 / a**2, 0, None))
    active = pc > 0
    r_active = r[active].max() if active.any() else 0.0
    outside = r[(~active) & (r > r_active)]
    r_next = outside.min() if outside.size else float("nan")
    pmax = pc.max()
    inner = r < 0.9 * a
    rms = float(np.sqrt(np.mean((pc[inner] - hertz[inner]) ** 2)) / p0) if inner.any() else float("nan")
    h = lx / (case["mesh"]["nsub"][0] * case["mesh"]["nel"][0])

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    rr = np.linspace(0, max(1.6 * a, r_next if np.isfinite(r_next) else 0), 400)
    ax.plot(rr, p0 * np.sqrt(np.clip(1 - rr**2 / a**2, 0, None)), "k-",
            label="Hertz: F = %.4g N, a = %.4g mm, p0 = %.4g MPa" % (force, a, p0))
    sel = r <= rr[-1]
    ax.plot(r[sel], pc[sel], "o", ms=3, color="C0", alpha=0.7,
            label="computed: %d nodes in contact (p > 0) of %d shown (h = %.3g mm)" % (active.sum(), sel.sum(), h))
    ax.axvline(a, color="k", ls=":", lw=0.8)
    ax.axvline(r_active, color="C0", ls=":", lw=0.8)
    ax.set_xlabel("r: distance from the sphere axis [mm]")
    ax.set_ylabel("contact pressure [MPa]")
    ax.set_title("%s: contact pressure against Hertz (E* = %.4g MPa, R = %g mm)" % (
        case["output"]["run_name"], estar, radius), fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, figures_dir(args, path), args.name)
    print("| quantity | Hertz | computed | computed / Hertz |")
    print("|---|---:|---:|---:|")
    print("| total force F [N] | (the computed F) | %.5g | |" % force)
    print("| contact radius a [mm] | %.4g | %.4g (last active node); next node %.4g | %.3f |" % (
        a, r_active, r_next, r_active / a))
    print("| max pressure p0 [MPa] | %.5g | %.5g | %.4f |" % (p0, pmax, pmax / p0))
    print("| nodes in contact (p > 0) | | %d | |" % active.sum())
    print("| rms(p - p_Hertz)/p0 over r < 0.9a | | %.3g | |" % rms)
    print("h = %.4g mm, a/h = %.2f; a/R = %.3f, a/Lx = %.3f (Hertz assumes both small)" % (
        h, a / h, a / radius, a / lx))

# ---------------------------------------------------------------- (e) load history
def hertz_indentation(force, estar, radius):
    """d of Hertz's law P = (4/3) E* R^(1/2) d^(3/2) for the force P."""
    return (3 * np.asarray(force) / (4 * estar * math.sqrt(radius))) ** (2 / 3)


def history_costs(report, path, cold_path=None):
    """The costs of a history: the first step's total (set-up + step 1: the program's total less
    the later steps), each later step against it, Hessian products (against a cold history of
    the same loads, --cold), accumulated reconstruction seconds new against standard."""
    steps = report["history"]
    total = report["timings"]["total"]["max"]
    later = [s["seconds"]["step"] for s in steps[1:]]
    first = total - sum(later)
    if (report["case"].get("history") or {}).get("restart"):
        print("(a restarted run: its total covers only the steps it made; the first step's total is not known)")
        first = float("nan")
    print("first step's total (set-up + step 1): %.3f s; later steps: mean %.3f s = %.1f%%, max %.3f s = %.1f%%" % (
        first, statistics.mean(later) if later else 0, 100 * statistics.mean(later) / first if later else 0,
        max(later) if later else 0, 100 * max(later) / first if later else 0))
    cold = None
    if cold_path:
        cp = os.path.join(cold_path, "report.json") if os.path.isdir(cold_path) else cold_path
        with open(cp) as f:
            cold = json.load(f)["history"]
        if [s["load_factor"] for s in cold] != [s["load_factor"] for s in steps]:
            sys.exit("plots: --cold has other load factors than %s" % path)
    print("| step | factor | start | outer | Hessian | %sstep [s] | rec new [s] | rec standard [s] |" % (
        "Hessian cold | cold / warm | " if cold else ""))
    print("|---:|---:|---|---:|---:|%s---:|---:|---:|" % ("---:|---:|" if cold else ""))
    for k, s in enumerate(steps):
        extra = ""
        if cold:
            hc = cold[k]["hessian_multiplications"]
            extra = "%d | %.2f | " % (hc, hc / max(s["hessian_multiplications"], 1))
        print("| %d | %.3f | %s | %d | %d | %s%.3f | %.3g | %.3g |" % (
            s["step"], s["load_factor"], s["warm_start"], s["outer_iterations"], s["hessian_multiplications"], extra,
            s["seconds"]["step"], s["seconds"]["rec_new"], s["seconds"]["rec_standard"]))
    hw = [s["hessian_multiplications"] for s in steps[1:]]
    line = "Hessian products per step after the first: mean %.1f" % (statistics.mean(hw) if hw else 0)
    if cold:
        hc = [s["hessian_multiplications"] for s in cold[1:]]
        line += " (cold %.1f: %.2fx)" % (statistics.mean(hc), statistics.mean(hc) / max(statistics.mean(hw), 1e-300))
    print(line)
    rn = sum(s["seconds"]["rec_new"] for s in steps)
    rs = sum(s["seconds"]["rec_standard"] for s in steps)
    print("reconstruction over %d steps: new %.4f s, standard %.4f s (standard / new %.1f)" % (
        len(steps), rn, rs, rs / rn if rn > 0 else float("nan")))


def cmd_history(args):
    path = args.run
    if os.path.isdir(path):
        path = os.path.join(path, "report.json")
    with open(path) as f:
        report = json.load(f)
    steps = report.get("history")
    if not steps:
        sys.exit("plots: %s has no load history (report.json without `history`)" % path)
    case = report["case"]
    top = abs(case["boundary"]["top_displacement"][2])
    gap0 = case["obstacle"]["gap"]
    factor = np.array([s["load_factor"] for s in steps])
    force = np.array([s["total_force"] for s in steps])
    gap = np.array([s["gap"] for s in steps])
    # the approach of the top face and the obstacle: the top moves down by factor |u_top|,
    # the obstacle down by its gap (from where the input puts it, gap0: touching at 0)
    delta = factor * top - (gap - gap0) - gap0
    sphere = case["obstacle"]["shape"] == "sphere"
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    order = np.arange(len(steps))
    # loading (the factor grows from the step before) and unloading steps marked apart, joined in order
    loading = np.array([k == 0 or factor[k] > factor[k - 1] for k in order])
    ax.plot(delta, force, "-", color="0.6", lw=1, zorder=1)
    ax.plot(delta[loading], force[loading], "^", ms=6, color="C0", zorder=2,
            label="computed, loading: force against the top's approach (delta)")
    if (~loading).any():
        ax.plot(delta[~loading], force[~loading], "o", ms=10, color="C3", mfc="none", zorder=3,
                label="computed, unloading (same factors back to 0)")
    peak = report.get("step")
    if peak is not None and 1 <= peak <= len(steps):
        ax.annotate("peak (step %d)" % peak, (delta[peak - 1], force[peak - 1]), textcoords="offset points",
                    xytext=(-80, 0), fontsize=8, arrowprops={"arrowstyle": "->", "color": "0.4"})
    rows = []
    if sphere:
        young, nu, radius = case["material"]["young"], case["material"]["poisson"], case["obstacle"]["radius"]
        estar = young / (1 - nu**2)
        # the body's own compliance C (the approach of the top face that is not the local Hertz
        # indentation): d = delta - C F; given (--compliance, default 0: d = delta) or fitted by
        # least squares over the steps with contact (--compliance fit; the Hertz law is not fitted)
        on = force > 0
        if args.compliance != "fit":
            c = float(args.compliance)
            how = "given"
        else:
            dh = hertz_indentation(force[on], estar, radius)
            c = float(np.sum(force[on] * (delta[on] - dh)) / np.sum(force[on] ** 2))
            how = "fitted"
        d = delta - c * force
        hertz = 4 / 3 * estar * math.sqrt(radius) * np.clip(d, 0, None) ** 1.5
        dd = np.linspace(0, max(d.max(), 1e-300) * 1.05, 200)
        if c != 0:
            ax.plot(d, force, "s", ms=3, color="C1", zorder=1, label="computed: against the indentation d = delta - C F "
                    "(C = %.3g mm/N, %s)" % (c, how))
        ax.plot(dd, 4 / 3 * estar * math.sqrt(radius) * dd**1.5, "k-",
                label="Hertz: P = 4/3 E* R^1/2 d^3/2 (E* = %.4g MPa, R = %g mm)" % (estar, radius))
        for k in order:
            rows.append((steps[k]["step"], "loading" if loading[k] else "unloading", factor[k], delta[k], d[k],
                         force[k], hertz[k], force[k] / hertz[k] if hertz[k] > 0 else float("nan")))
    ax.set_xlabel("approach / indentation [mm]")
    ax.set_ylabel("contact force [N]")
    ax.set_title("%s: force against indentation over %d steps" % (case["output"]["run_name"], len(steps)),
                 fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    save(fig, figures_dir(args, path), args.name)
    history_costs(report, path, args.cold)
    if sphere:
        lx, ly, lz = case["mesh"]["lengths"]
        print("C = %.4g mm/N (%s; for scale, the compliance of the body as a column in uniaxial "
              "compression, L_z / (E L_x L_y) = %.4g mm/N)" % (c, how, lz / (young * lx * ly)))
        print("| step | path | factor | delta [mm] | d [mm] | F [N] | Hertz P(d) [N] | F / P |")
        print("|---:|---|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            print("| %d | %s | %.3f | %.5g | %.5g | %.5g | %.5g | %.4f |" % r)
    else:
        print("| step | path | factor | delta [mm] | F [N] |")
        print("|---:|---|---:|---:|---:|")
        for k in order:
            print("| %d | %s | %.3f | %.5g | %.5g |" % (steps[k]["step"], "loading" if loading[k] else "unloading",
                                                     factor[k], delta[k], force[k]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], epilog=__doc__.split("\n", 2)[2],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    def common(parser, default):  # accepted before or after the subcommand
        parser.add_argument("--figures", default=default if default is not None else "",
                            help="output folder of the PNGs (default: the folder of the data, the first "
                                 "campaign's or the run's)")
        parser.add_argument("--stat", choices=["median", "min"], default=default if default is not None else "median",
                            help="value plotted for repeated times (default median; min is more robust on a "
                                 "shared machine); error bars always span min..max")

    common(ap, None)
    sub = ap.add_subparsers(dest="command", required=True)
    _add_parser = sub.add_parser

    def add_parser(*a, **k):
        p = _add_parser(*a, **k)
        common(p, argparse.SUPPRESS)
        return p

    sub.add_parser = add_parser

    p = sub.add_parser("weak", help="(a) iterations and phase times against subdomains (weak scaling when the "
                                    "ranks grow with them)")
    p.add_argument("campaigns", nargs="+", help="campaign directories or CSVs, one per family")
    p.add_argument("--name", default="weak", help="file name prefix: NAME_iterations.png, NAME_times.png")
    p.set_defaults(func=cmd_weak)

    p = sub.add_parser("reconstruction", help="(b) reconstruction cost, new vs standard, against subdomains")
    p.add_argument("campaigns", nargs="+", help="campaign directories or CSVs, one per family")
    p.add_argument("--name", default="weak_reconstruction", help="file name (default %(default)s.png)")
    p.add_argument("--breakdown", action="store_true", help="also the assembly and factorization of G_A G_A^T")
    p.set_defaults(func=cmd_reconstruction)

    p = sub.add_parser("tolerance", help="(c) time and Hessian multiplications against KKT residual and error")
    p.add_argument("campaign", help="campaign of a --sweep solver:tol=... (runs must keep their .h5)")
    p.add_argument("--error", choices=["auto", "exact", "reference"], default="auto",
                   help="exact: the `block` solution of docs/CASES.md; reference: against --reference or the "
                        "tightest run of the sweep (then left out of the plot); auto: exact when the obstacle "
                        "is a plane (default)")
    p.add_argument("--reference", help="HDF5 file of a tightly converged run of the same case")
    p.add_argument("--time", default="solve", help="timer plotted (default %(default)s; e.g. total)")
    p.add_argument("--name", help="file name (default tolerance_<campaign>.png)")
    p.set_defaults(func=cmd_tolerance)

    p = sub.add_parser("hertz", help="(d) contact pressure of one run against the Hertz solution")
    p.add_argument("run", help="a run's output directory (with report.json and one .h5) or its .h5")
    p.add_argument("--report", help="report.json of the run (default: beside the .h5)")
    p.add_argument("--name", default="hertz", help="file name (default %(default)s.png)")
    p.set_defaults(func=cmd_hertz)

    p = sub.add_parser("history", help="(e) force against indentation of a load history, Hertz for a sphere")
    p.add_argument("run", help="a history run's output directory (with report.json) or its report.json")
    p.add_argument("--compliance", default="0",
                   help="the body's compliance C [mm/N] in d = delta - C F, or 'fit' (least squares over the "
                        "steps); default 0: the indentation is the top face's approach delta")
    p.add_argument("--cold", help="a cold history of the same loads (warm_start = .false.): Hessian products compared")
    p.add_argument("--name", default="history_force", help="file name (default %(default)s.png)")
    p.set_defaults(func=cmd_history)

    args = ap.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `| head` ends quietly
    CENTRE["stat"] = args.stat
    args.func(args)


if __name__ == "__main__":
    main()
