#!/usr/bin/python3
"""Run hard-case inputs and print the stability table (markdown).

    stability_table.py --program build/bin/feticontact [--ranks 2] --workdir DIR \
        [--set group:variable=value ...] [--label NAME] \
        [--variant NAME[:VAR=VALUE;...] ...] [--variants V1,V2 [--variant-variable VAR]] inputs/hard/*.nml

Each input runs once under mpiexec with &output directory pointing into
DIR/<name>; the row comes from report.json (status, iterations, Hessian
multiplications, KKT residuals, timings) and, for the `block` family, from
the HDF5 displacement compared with the exact solution (hard_checks.py).
The full log of every run is kept in DIR/<name>/log.txt and all rows in
DIR/table.json.

Solver variants (tools/variants.py): with --variant (a name and &solver settings,
repeatable) or --variants none,lumped,dirichlet (&solver preconditioner = 'none', ...),
every input runs once per variant as <name>@<variant>, and the table gains the
columns variant, Hessian/outer (products per outer iteration), contraction (geometric
mean of ||C x_k|| / ||C x_(k-1)|| over the second half of the outer iterations,
report.json solver.contraction_late), KKT (pass/fail) and switch at (report.json
solver.preconditioner_switch_at: the Hessian count at which `preconditioner = 'auto'`
switched to 'dirichlet', - if it did not). Each variant is first
checked with `feticontact --check`: a variable or value the program rejects stops the
tool with the program's message.
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "app"))
sys.path.insert(0, os.path.join(HERE, "..", "..", "tools"))
import run_case  # noqa: E402  (parse_namelist, write_namelist)
import hard_checks  # noqa: E402
import variants as solver_variants  # noqa: E402  (tools/variants.py)


USED = set()


def run_one(args, path, variant=None):
    name = os.path.splitext(os.path.basename(path))[0]
    if (name, variant and variant["name"]) in USED:   # e.g. inputs/block.nml and inputs/hard/block.nml
        name = os.path.basename(os.path.dirname(os.path.abspath(path))) + "_" + name
    USED.add((name, variant and variant["name"]))
    if args.label:
        name = name + "-" + args.label
    if variant is not None:
        name = name + "@" + variant["name"]
    work = os.path.join(args.workdir, name)
    os.makedirs(work, exist_ok=True)
    with open(path) as f:
        groups = run_case.parse_namelist(f.read())
    for s in ["output:directory='%s'" % os.path.join(work, "out")] + args.set:
        gv, value = s.split("=", 1)
        g, v = gv.split(":")
        groups[g] = [kv for kv in groups.get(g, []) if kv[0] != v] + [(v, value)]
    if variant is not None:
        groups = solver_variants.merge(groups, variant)
    case = os.path.join(work, "case.nml")
    run_case.write_namelist(groups, case)
    report = os.path.join(work, "out", "report.json")
    if os.path.exists(report):
        os.remove(report)
    cmd = [args.mpiexec, "--oversubscribe", "--bind-to", "none", "-n", str(args.ranks), args.program, case]
    t0 = time.time()
    log = os.path.join(work, "log.txt")
    with open(log, "w") as f:
        f.write(" ".join(cmd) + "\n")
        f.flush()
        try:
            code = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, timeout=args.timeout).returncode
        except subprocess.TimeoutExpired:
            code = "timeout"
    wall = time.time() - t0
    with open(log) as f:
        out = f.read()
    row = {"name": name, "exit": code, "wall": wall, "variant": variant["name"] if variant else ""}
    if os.path.exists(report):
        with open(report) as f:
            r = json.load(f)
        s, k, t = r["solver"], r["kkt"], r["timings"]
        row.update(converged=s["converged"], outer=s["outer_iterations"], inner=s["inner_iterations"],
                   hessian=s["hessian_multiplications"], cg=s["cg_steps"], expansion=s["expansion_steps"],
                   proportioning=s["proportioning_steps"], m_updates=s.get("m_updates"),
                   message=s["message"], subdomains=r["sizes"]["subdomains"], dual=r["sizes"]["dual_dofs"],
                   primal=r["sizes"]["primal_dofs"], active=r["sizes"]["active_contact"],
                   contact_rows=r["sizes"]["contact_rows"],
                   kkt=[k["equilibrium"], k["equality"], k["feasibility"], k["dual_feasibility"],
                        k["complementarity"]],
                   total=t["total"]["max"], solve=t["solve"]["max"], alpha_difference=r["reconstruction"].get(
                       "alpha_difference"), kkt_passed=k.get("passed"), solver_variant=s.get("variant"),
                   hessian_per_outer=s.get("hessian_per_outer_mean"), contraction=s.get("contraction_late"),
                   contraction_median=s.get("contraction_median"),
                   switch_at=s.get("preconditioner_switch_at"))
    else:
        lines = [l for l in out.splitlines() if l.strip()]
        row["message"] = lines[-1] if lines else "no output"
    if os.path.basename(path).startswith("block") and os.path.isdir(os.path.join(work, "out")):
        try:
            row["error"] = hard_checks.block_error(os.path.join(work, "out"), groups)
        except (ValueError, RuntimeError) as e:
            row["error_note"] = str(e)
    return row


def fmt(row, with_variants=False):
    if "kkt" not in row:
        return "| %s | exit %s | | | | | | | | | | %s |%s" % (row["name"], row["exit"], row["message"],
                                                               " | | | | |" if with_variants else "")
    err = "%.1e" % row["error"] if "error" in row else "-"
    text = "| %s | %d | %s | %d | %d | %d | %s | %.2f | %.2f | %s | %d/%d |" % (
        row["name"], row["subdomains"], "yes" if row["exit"] == 0 else "exit %s" % row["exit"], row["outer"],
        row["inner"], row["hessian"], " ".join("%.0e" % v for v in row["kkt"]), row["total"], row["solve"], err,
        row["active"], row["contact_rows"])
    if with_variants:
        q = row.get("contraction")
        hpo = row.get("hessian_per_outer")
        sw = row.get("switch_at")
        text += " %s | %s | %s | %s | %s |" % (row["variant"], "%.1f" % hpo if hpo is not None else "-",
                                               "%.3f" % q if q is not None else "-",
                                               {True: "pass", False: "fail"}.get(row.get("kkt_passed"), "-"),
                                               sw if sw is not None else "-")
    return text


HEADER = ("| case | subdomains | converged | outer | inner | Hessian | KKT: equil. equal. feas. dual-feas. compl. "
          "| total [s] | solve [s] | error vs exact | active/contact rows |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|")
VARIANT_HEADER = ("| case | subdomains | converged | outer | inner | Hessian | KKT: equil. equal. feas. dual-feas. "
                  "compl. | total [s] | solve [s] | error vs exact | active/contact rows | variant | Hessian/outer "
                  "| contraction | KKT | switch at |\n"
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--label", default="")
    ap.add_argument("--timeout", type=int, default=900)
    ap.add_argument("--variant", action="append", default=[], metavar="NAME[:VAR=VALUE;...]",
                    help="a solver variant: a name and &solver settings; every input runs once per variant")
    ap.add_argument("--variants", metavar="V1,V2,...",
                    help="one variant per value of --variant-variable: &solver preconditioner = 'V1', ...")
    ap.add_argument("--variant-variable", default="preconditioner")
    ap.add_argument("inputs", nargs="+")
    args = ap.parse_args()
    try:
        variants = solver_variants.collect(args.variant, args.variants, args.variant_variable)
        if variants:
            with open(args.inputs[0]) as f:
                groups = run_case.parse_namelist(f.read())
            for s in args.set:
                gv, value = s.split("=", 1)
                g, v = gv.split(":")
                groups[g] = [kv for kv in groups.get(g, []) if kv[0] != v] + [(v, value)]
            solver_variants.check_variants(variants, groups, args.program, run_case.write_namelist,
                                           args.mpiexec, ["--oversubscribe", "--bind-to", "none"])
    except ValueError as e:
        sys.exit("stability_table: %s" % e)
    os.makedirs(args.workdir, exist_ok=True)
    rows = []
    print(VARIANT_HEADER if variants else HEADER, flush=True)
    for path in args.inputs:
        for variant in variants or [None]:
            row = run_one(args, path, variant)
            rows.append(row)
            print(fmt(row, bool(variants)), flush=True)
    table = os.path.join(args.workdir, "table.json")
    old = []
    if os.path.exists(table):
        with open(table) as f:
            old = [r for r in json.load(f) if r["name"] not in {x["name"] for x in rows}]
    with open(table, "w") as f:
        json.dump(old + rows, f, indent=1)


if __name__ == "__main__":
    main()
