#!/usr/bin/python3
"""Run feticontact end to end on a case and check its outputs.

    run_case.py --program feticontact --mpiexec mpiexec --ranks 2 --input inputs/block.nml \
        --workdir DIR [--set group:variable=value ...] [--expect-exit N] [--expect-message REGEX] \
        [--check block_exact:TOL] [--check report] [--check xdmf] [--check same_as:DIR:TOL]
        [--check f_action:explicit_shared|explicit|implicit]
        [--check alpha_agree:TOL] [--check switch:yes|no[:seen]] [--check same_switch_as:DIR]
        [--switch-threshold DIR:inside|above]

The input file is copied with the --set overrides merged into its groups and
with &output directory pointing into DIR. Every check derives its expected
values independently (the exact solution of docs/CASES.md, the file formats), never
from numbers the program printed. Exit status 0 when every check passes.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

FAILURES = []
PASSED = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    (PASSED if condition else FAILURES).append(what)


def parse_namelist(text):
    """Groups of a simple namelist file: {group: [(variable, raw value text)]}."""
    text = re.sub(r"!.*", "", text)
    groups = {}
    # a group ends at the first '/' outside quotes
    for m in re.finditer(r"&(\w+)((?:'[^']*'|\"[^\"]*\"|[^'\"/])*)/", text, re.S):
        body = m.group(2)
        starts = [a.start() for a in re.finditer(r"\w+(\([^)]*\))?\s*=", body)]
        items = []
        for i, s in enumerate(starts):
            piece = body[s:starts[i + 1] if i + 1 < len(starts) else len(body)].strip().rstrip(",")
            name, value = piece.split("=", 1)
            items.append((name.strip().lower(), value.strip()))
        groups[m.group(1).lower()] = items
    return groups


def write_namelist(groups, path):
    with open(path, "w") as f:
        for g, items in groups.items():
            f.write("&%s %s /\n" % (g, ", ".join("%s = %s" % kv for kv in items)))


def merged_input(args):
    with open(args.input) as f:
        groups = parse_namelist(f.read())
    overrides = ["output:directory='%s'" % os.path.join(args.workdir, "out")] + list(args.set)
    for s in overrides:
        gv, value = s.split("=", 1)
        g, v = gv.split(":")
        items = [kv for kv in groups.get(g, []) if kv[0] != v] + [(v, value)]
        groups[g] = items
    os.makedirs(args.workdir, exist_ok=True)
    path = os.path.join(args.workdir, "case.nml")
    write_namelist(groups, path)
    return path, groups


def value_of(groups, g, v, default):
    for name, value in groups.get(g, []):
        if name == v:
            return value
    return default


def fields(outdir):
    files = [f for f in os.listdir(outdir) if f.endswith(".h5")]
    assert len(files) == 1, "expected one .h5 file in %s, found %s" % (outdir, files)
    return h5py.File(os.path.join(outdir, files[0]), "r")


def check_block_exact(outdir, groups, tol):
    """docs/CASES.md `block`: u = (nu p x/E, nu p y/E, -p z/E), contact pressure p."""
    p = float(value_of(groups, "load", "top_pressure", "0").replace("d", "e"))
    young = float(value_of(groups, "material", "young", "2.1e5"))
    nu = float(value_of(groups, "material", "poisson", "0.3"))
    with fields(outdir) as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
        exact = np.column_stack([nu * p * x[:, 0] / young, nu * p * x[:, 1] / young, -p * x[:, 2] / young])
        err = np.abs(u - exact).max() / np.abs(exact).max()
        check(err <= tol, "block: max |u - u_exact| / max |u_exact| = %.3e <= %.1e" % (err, tol))
        pressure = h5["contact_pressure"][...]
        perr = np.abs(pressure - p).max() / p
        check(perr <= max(tol, 1e-8) * 100, "block: contact pressure = p, max rel. error %.3e" % perr)
        vm = h5["von_mises"][...]
        check(np.abs(vm - p).max() / p <= max(tol, 1e-8) * 100, "block: von Mises = p in every element")


# The KKT residuals of a converged run, relative (docs/CASES.md), are bounded by this constant
# times the run's own tol (docs/INPUT.md: what tol buys is a displacement error of about 20 tol;
# every residual is a displacement or force error of that order relative to its scale).
KKT_FACTOR = 100


def check_report(outdir, ranks, groups):
    with open(os.path.join(outdir, "report.json")) as f:
        r = json.load(f)
    need = {
        "case": ["mesh", "material", "solver", "output"],
        "sizes": ["subdomains", "ranks", "primal_dofs", "dual_dofs", "coarse_dim", "contact_rows",
                  "active_contact"],
        "solver": ["converged", "outer_iterations", "hessian_multiplications", "cg_steps", "expansion_steps",
                   "proportioning_steps", "projected_gradient", "equality_residual"],
        "kkt": ["equilibrium", "equality", "feasibility", "dual_feasibility", "complementarity"],
        "reconstruction": ["alpha_difference", "new", "standard"],
        "timings": ["solve", "total"],
        "contact": ["total_force", "max_pressure", "active_nodes", "contact_radius"],
        "memory": ["peak_rss_bytes"],
    }
    for key, subkeys in need.items():
        check(key in r, "report has '%s'" % key)
        for s in subkeys:
            check(s in r.get(key, {}), "report has '%s.%s'" % (key, s))
    s, sol = r["sizes"], r["solver"]
    check(s["ranks"] == ranks, "sizes.ranks == %d" % ranks)
    per_unit = int(np.prod(r["case"]["mesh"].get("cluster", [1, 1, 1])))   # hybrid TFETI: 6 rows per cluster
    check(s["coarse_dim"] * per_unit == 6 * s["subdomains"], "coarse_dim = 6 * subdomains / cluster size")
    check(s["active_contact"] <= s["contact_rows"], "active_contact <= contact_rows")
    check(s["dual_dofs"] >= s["contact_rows"], "dual_dofs >= contact_rows")
    check(sol["converged"] is True, "solver converged")
    check(sol["hessian_multiplications"] >= sol["outer_iterations"] >= 1, "hessian mults >= outer its >= 1")
    check(sol["cg_steps"] + sol["expansion_steps"] + sol["proportioning_steps"] <= sol["hessian_multiplications"],
          "steps <= hessian multiplications")
    tol = solver_tol(groups)
    residuals = {k: v for k, v in r["kkt"].items() if k != "passed"}
    check(len(residuals) >= 6, "report.json has the KKT residuals (%d)" % len(residuals))
    for k, v in sorted(residuals.items()):
        check(v is not None and v <= KKT_FACTOR * tol, "KKT residual %s = %.3e <= %d tol = %.1e (%.2f tol)"
              % (k, v if v is not None else float("nan"), KKT_FACTOR, KKT_FACTOR * tol,
                 (v if v is not None else float("nan")) / tol))
    check(r["kkt"].get("passed") is True, "report.json kkt.passed")
    t = r["timings"]
    check(all(t[k]["min"] <= t[k]["mean"] * (1 + 1e-12) <= t[k]["max"] * (1 + 1e-12) for k in t),
          "timings: min <= mean <= max")
    check(t["solve"]["max"] <= t["total"]["max"], "solve time <= total time")
    check(r["memory"]["peak_rss_bytes"]["max"] > 0, "peak RSS reported")
    phases = r["memory"].get("phases", [])
    names = [ph["name"] for ph in phases]
    check(names[:2] == ["MPI_Init", "mesh"] and "coarse setup" in names and names[-1] == "output",
          "memory.phases from MPI_Init to output: %s" % names)
    check(all(0 < ph["rss_mean"] <= ph["peak_mean"] <= ph["peak_max"] and ph["rss_mean"] <= ph["rss_max"]
              for ph in phases), "memory.phases: 0 < rss_mean <= peak_mean <= peak_max")
    # VmHWM never decreases: the marks in order, and the final peak is the largest. The kernel
    # reads the RSS it compares with the high-water mark approximately: per-CPU counters with a
    # batch of max(32, 2 ncpu) pages per CPU (Linux >= 6.2), or per-thread caches of up to 64
    # page events (older kernels; at most about 8 threads per rank with Open MPI), so a mark may
    # read up to that many pages below the one before (seen: 2 pages).
    ncpu = os.cpu_count() or 1
    slack = os.sysconf("SC_PAGE_SIZE") * max(64 * 8, max(32, 2 * ncpu) * ncpu)
    check(all(a["peak_max"] <= b["peak_max"] + slack for a, b in zip(phases, phases[1:])),
          "memory.phases: peaks grow (within the kernel's RSS counter slack, %d bytes)" % slack)
    check(phases[-1]["peak_max"] <= r["memory"]["peak_rss_bytes"]["max"], "last mark <= peak RSS")
    force = r["contact"]["total_force"]
    check(force >= 0, "total contact force >= 0")


def check_xdmf(outdir):
    files = [f for f in os.listdir(outdir) if f.endswith(".xdmf")]
    check(len(files) == 1, "one .xdmf file")
    tree = ET.parse(os.path.join(outdir, files[0]))
    items = [e for e in tree.iter() if e.tag == "DataItem"]
    check(len(items) >= 4, "xdmf has DataItems")
    for item in items:
        ref = item.text.strip()
        name, path = ref.split(":")
        dims = tuple(int(d) for d in item.get("Dimensions").split())
        with h5py.File(os.path.join(outdir, name), "r") as h5:
            check(path in h5, "xdmf reference %s exists" % ref)
            if path in h5:
                check(h5[path].shape == dims, "%s has the dimensions %s" % (ref, dims))
    check(not any(f.endswith(".tmp") for f in os.listdir(outdir)), "no temporary files left")


def displacement_by_position(outdir):
    with fields(outdir) as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
    keys = np.round(x * 1e9).astype(np.int64)
    return {tuple(k): v for k, v in zip(keys, u)}


def check_same_as(outdir, other, tol):
    a, b = displacement_by_position(outdir), displacement_by_position(other)
    check(set(a) == set(b), "same node positions as %s" % other)
    scale = max(np.abs(v).max() for v in b.values())
    diff = max(np.abs(a[k] - b[k]).max() for k in a if k in b)
    check(diff <= tol * scale, "same displacements as %s: max diff / max |u| = %.3e <= %.1e" % (other, diff / scale, tol))


def solver_tol(groups):
    """The run's own tolerance (&solver tol, docs/INPUT.md default 1e-6): every bound on the
    solution's error or on its KKT residuals is a constant times it."""
    return float(value_of(groups, "solver", "tol", "1e-6").lower().replace("d", "e"))


def node_ijk(x, groups):
    """Global mesh indices (i, j, k) of points x (n, 3) of the box mesh: a node is moved by at most
    distortion * h < h/2 per component, so rounding x / h gives its indices."""
    nsub = np.array([int(v) for v in value_of(groups, "mesh", "nsub", "2,2,2").split(",")])
    nel = np.array([int(v) for v in value_of(groups, "mesh", "nel", "4,4,4").split(",")])
    lengths = np.array([float(v) for v in value_of(groups, "mesh", "lengths", "1,1,1").split(",")])
    h = lengths / (nsub * nel)
    return np.rint(x / h).astype(np.int64), h


def check_reference(outdir, case_file, groups, factor):
    """The program's displacements and contact pressures against the undecomposed reference
    solution of tests/app/contact_reference.py (a primal-dual active set solve of the global Q1
    problem, built from docs/CASES.md without any module of the program). docs/INPUT.md states
    what tol buys: max |u - u*| / max |u*| of about 20 tol; the bound is factor * tol."""
    import contact_reference
    tol = solver_tol(groups)
    ref = contact_reference.Problem(contact_reference.Case.read(case_file))
    u_ref, lam = ref.solve()
    res = ref.kkt_residuals()
    check(max(res.values()) <= 1e-10, "reference solution: KKT residuals %s <= 1e-10"
          % ", ".join("%s %.1e" % kv for kv in res.items()))
    nact = int((lam > 0).sum())
    print("reference: %d dofs, %d contact rows, %d active, %d active-set iterations, total force %.6e"
          % (ref.ndof, len(lam), nact, ref.iterations, lam.sum()))
    with fields(outdir) as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
        xc = h5["contact_coordinates"][...]
        pc = h5["contact_pressure"][...]
        gc = h5["contact_gap"][...]
    ijk, h = node_ijk(x, groups)
    idx = ref.mesh.node_index(ijk)
    check(len(x) >= ref.mesh.nn and set(idx.tolist()) == set(range(ref.mesh.nn)),
          "every node of the reference mesh (%d) has a copy in the output (%d copies)" % (ref.mesh.nn, len(x)))
    dx = np.abs(x - ref.mesh.x[idx]).max() / h.min()
    check(dx <= 1e-12, "same node coordinates as the reference mesh: max |x - x_ref| / h = %.1e <= 1e-12" % dx)
    scale = np.abs(u_ref).max()
    err = np.abs(u - u_ref[idx]).max() / scale
    check(err <= factor * tol, "max |u - u_ref| / max |u_ref| = %.3e <= %g tol = %.1e (%.2f tol)"
          % (err, factor, factor * tol, err / tol))
    # contact pressures, node by node (the output holds one row per physical contact node)
    ijk_c, _ = node_ijk(xc, groups)
    where = {int(n): i for i, n in enumerate(ref.contact_nodes)}
    rows = [where.get(int(n), -1) for n in ref.mesh.node_index(ijk_c)]
    check(len(rows) == len(ref.contact_nodes) and sorted(rows) == list(range(len(ref.contact_nodes))),
          "the output's contact rows are the reference's %d contact nodes (got %d)" % (len(ref.contact_nodes), len(rows)))
    if len(rows) == len(ref.contact_nodes) and min(rows, default=0) >= 0:
        p_ref = ref.pressure()[rows]
        pscale = max(np.abs(p_ref).max(), 1e-300)
        perr = np.abs(pc - p_ref).max() / pscale
        check(perr <= factor * tol, "max |p - p_ref| / max p_ref = %.3e <= %g tol (%.2f tol)"
              % (perr, factor, perr / tol))
        # the deformed gap g + u_z of each contact node (docs/CASES.md), to the displacement bound
        g_ref = ref.g[rows] + u_ref[ref.contact_nodes[rows], 2]
        gerr = np.abs(gc - g_ref).max() / scale
        check(gerr <= factor * tol, "max |gap - gap_ref| / max |u_ref| = %.3e <= %g tol (%.2f tol)"
              % (gerr, factor, gerr / tol))
    return ref, nact


def check_equilibrium(outdir, case_file, groups, log):
    """The contact force a user reads (report.json, the log's summary line) against the bottom
    reactions recomputed from the displacements by an assembly written for the test
    (contact_reference.copy_reactions: the Q1 element stiffness of the reference, applied to
    every subdomain copy of the HDF5 output): the sum over the copies of the nodes on z = 0 of
    (K_s u_s)_z. Gluing forces cancel in that sum; what is left is the obstacle's force, exact
    up to the subdomains' equilibrium, which the solver holds to its tol (G lambda = e): the
    bound is KKT_FACTOR tol relative. Where the top face is free and carries a pressure, the
    same force balances the load: p Lx Ly (the symmetry planes hold x and y only)."""
    import contact_reference
    tol = solver_tol(groups)
    case = contact_reference.Case.read(case_file)
    with fields(outdir) as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
        conn = h5["connectivity"][...]
        sub = h5["subdomain"][...]
    with open(os.path.join(outdir, "report.json")) as f:
        reported = json.load(f)["contact"]["total_force"]
    r = contact_reference.copy_reactions(case, x, u, conn, sub)
    ijk, _ = node_ijk(x, groups)
    bottom = ijk[:, 2] == 0
    recomputed = r[bottom, 2].sum()
    scale = max(abs(recomputed), 1e-300)
    err = abs(reported - recomputed) / scale
    print("equilibrium: reported force %.10e, recomputed from u %.10e" % (reported, recomputed))
    check(recomputed > 0, "the recomputed contact force %.6e is a push (> 0)" % recomputed)
    check(err <= KKT_FACTOR * tol, "report.json contact force = sum of the bottom reactions from u: "
          "rel. difference %.3e <= %g tol" % (err, KKT_FACTOR))
    # every bottom node off the contact rows carries no force (summed over its copies)
    contact_keys = set()
    with fields(outdir) as h5:
        cijk, _ = node_ijk(h5["contact_coordinates"][...], groups)
        contact_keys = {tuple(k) for k in cijk}
    per_node = {}
    for k, f in zip(map(tuple, ijk[bottom]), r[bottom, 2]):
        per_node[k] = per_node.get(k, 0.0) + f
    free = [abs(f) for k, f in per_node.items() if k not in contact_keys]
    if free:
        check(max(free) <= KKT_FACTOR * tol * scale, "bottom nodes off the obstacle carry no force: max %.3e" % max(free))
    m = re.findall(r"contact force\s+([-+0-9.eE]+)", log)
    check(len(m) >= 1, "the log states the contact force")
    if m:
        logged = float(m[-1])
        check(abs(logged - recomputed) <= 1e-5 * scale + KKT_FACTOR * tol * scale,
              "the log's contact force %.5e = the recomputed %.5e (5 digits)" % (logged, recomputed))
    if not case.top_dirichlet and case.top_pressure != 0:
        load = case.top_pressure * case.lengths[0] * case.lengths[1]
        check(abs(recomputed - load) <= KKT_FACTOR * tol * load,
              "the recomputed force balances the pressure: %.10e vs p Lx Ly = %.10e" % (recomputed, load))
        check(abs(reported - load) <= KKT_FACTOR * tol * load,
              "report.json's force balances the pressure: %.10e vs p Lx Ly = %.10e" % (reported, load))


def check_kkt_failed(outdir, groups, log):
    """Exit status 4: the run converged (to a loose tol) but a KKT residual exceeds kkt_tol. The
    message's largest residual is the largest of report.json's residuals, above kkt_tol, and
    kkt.passed is false. The message names that residual as the log's KKT line does."""
    kkt_tol = float(value_of(groups, "reconstruction", "kkt_tol", "1e-3").lower().replace("d", "e"))
    m = re.search(r"KKT check failed: largest residual \(([^)]*)\)\s+(\S+) > kkt_tol\s+(\S+)", log)
    check(m is not None, "the message 'KKT check failed: largest residual (NAME) X > kkt_tol Y'")
    with open(os.path.join(outdir, "report.json")) as f:
        r = json.load(f)
    check(r["solver"]["converged"] is True, "the solver converged (exit 4 is about the KKT check, not 3)")
    check(r["kkt"]["passed"] is False, "report.json kkt.passed is false")
    residuals = {k: v for k, v in r["kkt"].items() if k not in ("passed", "equality", "feasibility")}
    name, worst = max(residuals.items(), key=lambda kv: kv[1])
    check(worst > kkt_tol, "the largest residual, %s = %.3e, exceeds kkt_tol %.1e" % (name, worst, kkt_tol))
    log_names = {"equilibrium": "equilibrium", "gluing": "gluing jump", "dirichlet": "Dirichlet",
                 "penetration": "penetration", "dual_feasibility": "dual feasibility",
                 "complementarity": "complementarity"}
    if m:
        said = float(m.group(2))
        check(abs(said - worst) <= 1e-3 * worst, "the message's residual %.3e is report.json's largest, %s (%.3e)"
              % (said, name, worst))
        check(m.group(1) == log_names.get(name), "the message names the largest residual: '%s' (report.json: %s)"
              % (m.group(1), name))
        check(abs(float(m.group(3)) - kkt_tol) <= 1e-3 * kkt_tol, "the message's kkt_tol is the input's")
    line = re.search(r"equilibrium \(worst subdomain\)\s+(\S+), gluing jump\s+(\S+), Dirichlet\s+(\S+), "
                     r"penetration\s+(\S+), dual feasibility\s+(\S+), complementarity\s+(\S+)", log)
    check(line is not None, "the log's KKT line names every residual")
    if line:
        logged = dict(zip(["equilibrium", "gluing", "dirichlet", "penetration", "dual_feasibility",
                           "complementarity"], [float(v) for v in line.groups()]))
        check(abs(logged[name] - worst) <= 1e-3 * worst, "the log names %s = %.3e, the largest" % (name, logged[name]))


MONITOR_LINE = re.compile(r"^\s*(\d+)  (outer|mprgp|face|round)\s+(\S+)\s+(\S+)\s+(\S+)(?:  (.*))?$")
REASON_LINE = re.compile(r"^SMALBE reason: (\w+) after (\d+) outer iterations? and (\d+) Hessian multiplications?; (.*)$")


def monitor_lines(log):
    """The monitor's lines (docs/INPUT.md "The monitor"): (products, loop, step, measure, target, details)."""
    lines = []
    for text in log.splitlines():
        m = MONITOR_LINE.match(text)
        if m:
            lines.append((int(m.group(1)), m.group(2), m.group(3), float(m.group(4)), float(m.group(5)),
                          m.group(6) or ""))
    return lines


def check_reason(outdir, log, expected):
    """The reason line is there (whatever the monitor setting), names `expected` (CONVERGED_TOL,
    DIVERGED_MAX_HESSIAN, ...) and counts the outer iterations and Hessian multiplications
    that report.json records."""
    found = [REASON_LINE.match(t) for t in log.splitlines() if t.startswith("SMALBE reason:")]
    check(len(found) == 1 and found[0] is not None, "one parseable 'SMALBE reason:' line (found %d)" % len(found))
    if not found or found[0] is None:
        return
    m = found[0]
    s = solver_report(outdir)
    check(m.group(1) == expected, "the reason is %s (got %s)" % (expected, m.group(1)))
    check(int(m.group(2)) == s["outer_iterations"], "reason line: %s outer iterations, report.json %d"
          % (m.group(2), s["outer_iterations"]))
    check(int(m.group(3)) == s["hessian_multiplications"], "reason line: %s Hessian multiplications, report.json %d"
          % (m.group(3), s["hessian_multiplications"]))
    check(s["converged"] == expected.startswith("CONVERGED"), "report.json converged agrees with the reason")
    summary = [t for t in log.splitlines() if t.startswith("  inner MPRGP: ")]
    check(len(summary) == 1, "the summary's counts line is there")


def check_monitor(outdir, log):
    """The monitor's lines agree with report.json: one outer line per outer iteration, numbered
    1..n; the MPRGP lines' step counts add up to the CG, expansion and proportioning steps; one
    face line per polish CG step and one round line per face solve; the products column never
    decreases and the last line's is the total of Hessian multiplications; measures and targets
    are finite and >= 0; when the run converged, the last outer line meets both targets and no
    earlier one does."""
    lines = monitor_lines(log)
    s = solver_report(outdir)
    check(len(lines) > 0, "monitor lines present (%d)" % len(lines))
    if not lines:
        return
    outer = [l for l in lines if l[1] == "outer"]
    check([int(l[2]) for l in outer] == list(range(1, s["outer_iterations"] + 1)),
          "outer lines 1..%d (got %d lines)" % (s["outer_iterations"], len(outer)))
    kinds = {"cg": 0, "expansion": 0, "proportioning": 0}
    for l in lines:
        if l[1] == "mprgp":
            m = re.match(r"(cg|expansion|proportioning)\((\d+)\)$", l[2])
            check(m is not None, "mprgp step %r is kind(count)" % l[2])
            if m:
                kinds[m.group(1)] += int(m.group(2))
    check(kinds["cg"] == s["cg_steps"], "mprgp lines: %d CG steps, report.json %d" % (kinds["cg"], s["cg_steps"]))
    check(kinds["expansion"] == s["expansion_steps"], "mprgp lines: %d expansion steps, report.json %d"
          % (kinds["expansion"], s["expansion_steps"]))
    check(kinds["proportioning"] == s["proportioning_steps"], "mprgp lines: %d proportioning steps, report.json %d"
          % (kinds["proportioning"], s["proportioning_steps"]))
    faces = [l for l in lines if l[1] == "face"]
    rounds = [l for l in lines if l[1] == "round"]
    check(len(faces) == s.get("polish_cg_steps", 0), "face lines %d == polish_cg_steps %s"
          % (len(faces), s.get("polish_cg_steps")))
    check(len(rounds) == s.get("polish_face_solves", 0), "round lines %d == polish_face_solves %s"
          % (len(rounds), s.get("polish_face_solves")))
    products = [l[0] for l in lines]
    check(all(a <= b for a, b in zip(products, products[1:])), "the products column never decreases")
    check(products[-1] == s["hessian_multiplications"], "last line's products %d == hessian_multiplications %d"
          % (products[-1], s["hessian_multiplications"]))
    check(all(l[3] >= 0 and l[4] >= 0 and np.isfinite(l[3]) and np.isfinite(l[4]) for l in lines),
          "measures and targets finite and >= 0")
    if s["converged"] and outer:
        check(outer[-1][3] <= outer[-1][4], "the last outer line meets its target (%.3e <= %.3e)"
              % (outer[-1][3], outer[-1][4]))

        def feasible(details):
            m = re.match(r"feasibility\s+(\S+) \(target\s+(\S+)\)", details)
            return m is not None and float(m.group(1)) <= float(m.group(2))
        check(feasible(outer[-1][5]), "the last outer line's feasibility meets its target: %r" % outer[-1][5])
        check(not any(l[3] <= l[4] and feasible(l[5]) for l in outer[:-1]),
              "no earlier outer line meets both targets (the solve would have stopped there)")


def check_no_monitor(log):
    """monitor = .false.: no monitor line, while the summary and the reason line stay (check reason)."""
    check(len(monitor_lines(log)) == 0, "no monitor line with monitor = .false.")


def check_polish_accepted(outdir):
    """The polish (SMALBE's exact face solve; with the default polish_first it starts the solve)
    must produce the solution: at least one polish after which the outer stopping test held at
    once (report.json solver.polish_accepted > 0)."""
    s = solver_report(outdir)
    check(s.get("polish_count", 0) > 0, "a polish was made (polish_count %s)" % s.get("polish_count"))
    check(s.get("polish_accepted", 0) > 0, "a polish was accepted at once (polish_accepted %s)" % s.get("polish_accepted"))


def check_partly_active(ref, nact):
    """The case is one of partly active contact (else a reference check on it proves less)."""
    check(0 < nact < len(ref.contact_nodes), "partly active contact: %d of %d contact rows active in the reference"
          % (nact, len(ref.contact_nodes)))


def check_rigid(outdir, groups, factor):
    """No contact and no load but the top face's displacement d: the exact solution is the rigid
    translation u = d at every node, with every contact force 0 and every gap open."""
    tol = solver_tol(groups)
    d = np.array([float(v) for v in value_of(groups, "boundary", "top_displacement", "0,0,-0.005").split(",")])
    with fields(outdir) as h5:
        u = h5["displacement"][...]
        pc = h5["contact_pressure"][...]
        gap = h5["contact_gap"][...]
    err = np.abs(u - d).max() / np.abs(d).max()
    check(len(u) > 0 and err <= factor * tol, "rigid translation: max |u - d| / |d| = %.3e <= %g tol" % (err, factor))
    check(len(pc) > 0 and np.all(pc == 0), "every contact pressure is 0 (%d rows, max %.3e)" % (len(pc), np.abs(pc).max(initial=0)))
    check(len(gap) > 0 and gap.min() > 0, "every gap open (min %.3e)" % (gap.min() if len(gap) else float("nan")))


def check_no_contact(outdir):
    """Every contact multiplier is 0 (the obstacle is out of reach)."""
    with fields(outdir) as h5:
        pc = h5["contact_pressure"][...]
        gap = h5["contact_gap"][...]
    check(len(pc) > 0 and np.all(pc == 0), "every contact multiplier is 0 (%d rows, max pressure %.3e)"
          % (len(pc), np.abs(pc).max(initial=0)))
    check(len(gap) > 0 and gap.min() > 0, "every gap open (min %.3e)" % (gap.min() if len(gap) else float("nan")))


def check_hertz(outdir, groups):
    """docs/CASES.md "Hertz check": with the computed total force F (the sum of the output's
    pressures times their tributary areas), E* = E / (1 - nu^2), a = (3 F R / (4 E*))^(1/3),
    p0 = 3 F / (2 pi a^2). Bounds suited to a mesh of size h, on a zone of at least 2.5 elements
    in radius (asserted):
    - contact radius (the largest distance from the axis of a node under pressure) within h of a:
      the contact edge lies between the last node in contact and the next one;
    - peak nodal pressure within (0.05 + (h/a)^2 / 12) p0: a few percent for the finite body
      (docs/CASES.md), plus the mean of p0 sqrt(1 - r^2/a^2) ~ p0 (1 - r^2 / (2 a^2)) over the
      h x h tributary square of the centre node, which lies (h/a)^2/12 below p0."""
    young = float(value_of(groups, "material", "young", "2.1e5"))
    nu = float(value_of(groups, "material", "poisson", "0.3"))
    radius = float(value_of(groups, "obstacle", "radius", "1.0"))
    lengths = np.array([float(v) for v in value_of(groups, "mesh", "lengths", "1,1,1").split(",")])
    with fields(outdir) as h5:
        xc = h5["contact_coordinates"][...]
        pc = h5["contact_pressure"][...]
        gc = h5["contact_gap"][...]
    _, h = node_ijk(xc, groups)
    area = np.full(len(xc), h[0] * h[1])
    for c in range(2):
        area[(np.abs(xc[:, c]) < 1e-9) | (np.abs(xc[:, c] - lengths[c]) < 1e-9)] /= 2
    force = float((pc * area).sum())
    estar = young / (1 - nu ** 2)
    a = (3 * force * radius / (4 * estar)) ** (1 / 3)
    p0 = 3 * force / (2 * np.pi * a ** 2)
    r = np.hypot(xc[:, 0] - lengths[0] / 2, xc[:, 1] - lengths[1] / 2)
    rc = r[pc > 0].max()
    hh = max(h[0], h[1])
    print("Hertz: F = %.4e, a = %.4f (h = %.4f, a/h = %.2f), contact radius %.4f, p0 = %.4e, peak pressure %.4e"
          % (force, a, hh, a / hh, rc, p0, pc.max()))
    check(a >= 2.5 * hh, "the contact zone spans at least 2.5 elements in radius (a / h = %.2f)" % (a / hh))
    check(abs(rc - a) <= hh, "contact radius %.4f = Hertz a %.4f within h = %.4f" % (rc, a, hh))
    bound = 0.05 + (hh / a) ** 2 / 12
    check(abs(pc.max() - p0) <= bound * p0, "peak pressure %.4e = Hertz p0 %.4e within %.3f p0 (rel. diff %.3f)"
          % (pc.max(), p0, bound, abs(pc.max() - p0) / p0))


def check_cluster(outdir, groups, expect):
    """&mesh cluster: 'auto_hybrid' = chosen automatically and > 1 (dividing nsub), 'auto_plain' = chosen
    automatically and 1,1,1; report.json records the clusters used, whether they were automatic and why."""
    with open(os.path.join(outdir, "report.json")) as f:
        m = json.load(f)["case"]["mesh"]
    c, nsub = m["cluster"], m["nsub"]
    check(m.get("cluster_auto") is True, "report: mesh.cluster_auto = true")
    check(len(m.get("cluster_choice", "")) > 0, "report: mesh.cluster_choice says why: %r" % m.get("cluster_choice"))
    if expect == "auto_hybrid":
        check(int(np.prod(c)) > 1 and all(n % k == 0 for n, k in zip(nsub, c)),
              "automatic clusters %s > 1 and dividing nsub %s" % (c, nsub))
    else:
        check(c == [1, 1, 1], "automatic choice plain TFETI (cluster %s)" % c)


def check_f_action(outdir, expected):
    """report.json's F action is `expected` ('explicit_shared', 'explicit' or 'implicit')."""
    with open(os.path.join(outdir, "report.json")) as f:
        perf = json.load(f)["performance"]
    got = perf["f_action"] + ("_shared" if perf["f_action"] == "explicit" and perf["f_shared"] else "")
    check(got == expected, "F action %s (expected %s)" % (got, expected))


def check_alpha_agree(outdir, tol):
    """&reconstruction method = 'both': the new (Eq. 24) and the standard (Eq. 10) alpha agree."""
    with open(os.path.join(outdir, "report.json")) as f:
        d = json.load(f)["reconstruction"]["alpha_difference"]
    check(d is not None and d <= tol, "||alpha_new - alpha_standard|| / ||alpha_standard|| = %s <= %.1e" % (d, tol))


def solver_report(outdir):
    with open(os.path.join(outdir, "report.json")) as f:
        return json.load(f)["solver"]


def check_switch(outdir, expected, seen=False):
    """&solver preconditioner = 'auto': whether it switched to 'dirichlet' (report.json
    solver.preconditioner_switch_at not null, and the preconditioner in use at the end).
    seen: the run had CG runs long enough for a condition estimate (so that 'no' means the
    estimate stayed below the threshold, not that there was none)."""
    s = solver_report(outdir)
    at = s.get("preconditioner_switch_at")
    if expected == "yes":
        check(at is not None and at >= 0 and s.get("preconditioner") == "dirichlet",
              "preconditioner 'auto' switched to dirichlet (at Hessian product %s, estimate %s)"
              % (at, s.get("preconditioner_switch_estimate")))
        est = s.get("preconditioner_switch_estimate")
        check(at is not None and at <= s["hessian_multiplications"], "the switch point %s is within the run's %d products"
              % (at, s["hessian_multiplications"]))
        check(est is not None and est > 1, "the switch estimate %s is a condition number > 1" % est)
    else:
        check(at is None and s.get("preconditioner") == "lumped",
              "preconditioner 'auto' stayed lumped (switch at %s, in use %s, face condition estimate %s)"
              % (at, s.get("preconditioner"), s.get("face_condition_estimate")))
        if seen:
            check(s.get("face_condition_estimate") is not None, "a face condition estimate was made (%s CG runs)"
                  % s.get("cg_runs"))


def switch_threshold(spec):
    """&solver preconditioner_switch for an 'auto' run, from the largest face condition
    estimate E of a 'lumped' run of the same case in DIR (report.json
    solver.face_condition_estimate: the largest Ritz ratio of its CG runs; the extreme Ritz
    values of a run move outwards step by step, so E is also the largest running estimate an
    'auto' run sees before it switches, up to rounding). 'inside': sqrt(E), the geometric
    middle of [1, E], which the estimate must pass (E >= 4 asserted: a factor >= 2 on either
    side); 'above': 2 E, which it must not reach. Not a number tuned on one CPU: the bound
    follows the quantity the switch compares."""
    folder, mode = spec.rsplit(":", 1)
    est = solver_report(os.path.join(folder, "out")).get("face_condition_estimate")
    check(est is not None and est >= 1, "the lumped run in %s has a face condition estimate (%s)" % (folder, est))
    if est is None or est < 1:
        return None
    if mode == "inside":
        check(est >= 4, "its estimate %.3g >= 4: sqrt(E) is a factor >= 2 from both 1 and E" % est)
        return est ** 0.5
    check(mode == "above", "switch threshold mode %s is 'inside' or 'above'" % mode)
    return 2 * est


def check_same_switch_as(outdir, other):
    """The switch point is the same Hessian count as in another run (e.g. another rank count)."""
    a, b = solver_report(outdir), solver_report(other)
    check(a.get("preconditioner_switch_at") == b.get("preconditioner_switch_at"),
          "same switch point as %s: %s == %s" % (other, a.get("preconditioner_switch_at"),
                                                  b.get("preconditioner_switch_at")))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--input", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--expect-exit", type=int, default=0)
    ap.add_argument("--expect-message", default=None)
    ap.add_argument("--check", action="append", default=[])
    ap.add_argument("--timeout", type=int, default=600)
    ap.add_argument("--switch-threshold", default=None)
    args = ap.parse_args()
    if args.switch_threshold:
        kappa = switch_threshold(args.switch_threshold)
        if kappa is None:
            print("%d passed, %d failed" % (len(PASSED), len(FAILURES)))
            sys.exit(1)
        print("preconditioner_switch = %.6g (from %s)" % (kappa, args.switch_threshold))
        args.set.append("solver:preconditioner_switch=%.17g" % kappa)

    shutil.rmtree(os.path.join(args.workdir, "out"), ignore_errors=True)   # no stale outputs
    path, groups = merged_input(args)
    cmd = [args.mpiexec, "--oversubscribe", "--bind-to", "none", "-n", str(args.ranks), args.program, path]
    print("running:", " ".join(cmd))
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    out = run.stdout + run.stderr
    # the whole log in the work folder (what a wrapper checks), its tail here
    os.makedirs(args.workdir, exist_ok=True)
    with open(os.path.join(args.workdir, "log.txt"), "w") as f:
        f.write(out)
    print(out[-6000:])
    check(run.returncode == args.expect_exit, "exit status %d (expected %d)" % (run.returncode, args.expect_exit))
    if args.expect_message:
        check(re.search(args.expect_message, out) is not None, "output matches %r" % args.expect_message)
    outdir = os.path.join(args.workdir, "out")
    for g, items in groups.items():
        for name, value in items:
            if g == "output" and name == "directory":
                outdir = value.strip().strip("'")
    for c in args.check:
        kind, *rest = c.split(":")
        if kind == "block_exact":
            check_block_exact(outdir, groups, float(rest[0]))
        elif kind == "report":
            check_report(outdir, args.ranks, groups)
        elif kind == "xdmf":
            check_xdmf(outdir)
        elif kind == "reference":
            check_reference(outdir, path, groups, float(rest[0]))
        elif kind == "reference_partial":
            check_partly_active(*check_reference(outdir, path, groups, float(rest[0])))
        elif kind == "equilibrium":
            check_equilibrium(outdir, path, groups, out)
        elif kind == "monitor":
            check_monitor(outdir, out)
        elif kind == "no_monitor":
            check_no_monitor(out)
        elif kind == "reason":
            check_reason(outdir, out, rest[0])
        elif kind == "polish_accepted":
            check_polish_accepted(outdir)
        elif kind == "kkt_failed":
            check_kkt_failed(outdir, groups, out)
        elif kind == "rigid":
            check_rigid(outdir, groups, float(rest[0]))
        elif kind == "no_contact":
            check_no_contact(outdir)
        elif kind == "hertz":
            check_hertz(outdir, groups)
        elif kind == "cluster":
            check_cluster(outdir, groups, rest[0])
        elif kind == "f_action":
            check_f_action(outdir, rest[0])
        elif kind == "alpha_agree":
            check_alpha_agree(outdir, float(rest[0]))
        elif kind == "same_as":
            check_same_as(outdir, os.path.join(rest[0], "out"), float(rest[1]))
        elif kind == "switch":
            check_switch(outdir, rest[0], len(rest) > 1 and rest[1] == "seen")
        elif kind == "same_switch_as":
            check_same_switch_as(outdir, os.path.join(rest[0], "out"))
        else:
            check(False, "unknown check %s" % kind)
    print("%d passed, %d failed" % (len(PASSED), len(FAILURES)))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
