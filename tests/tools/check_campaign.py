#!/usr/bin/python3
"""CTest check of tools/campaign.py and tools/plots.py on a tiny `block` case.

    check_campaign.py --program feticontact --mpiexec mpiexec --workdir DIR

Runs one campaign of two members on 1 rank, 1 repetition: the tiny block input
as it is (must converge) and with solver:max_hessian=1 (must fail with exit 3
and still be a row of the CSV). Checks the CSV columns, the converged row
(iteration counts, KKT residuals, times, the exact solution's contact force
p Lx Ly), the recorded failure, the namelist merge (quoted '/' and '!'), and
that tools/plots.py makes its figures from that CSV. Exit 0 when all pass.
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
TOOLS = os.path.join(ROOT, "tools")
FAILURES = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    if not condition:
        FAILURES.append(what)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--workdir", required=True)
    args = ap.parse_args()
    shutil.rmtree(args.workdir, ignore_errors=True)   # no stale outputs of an earlier run
    os.makedirs(args.workdir)
    out = os.path.join(args.workdir, "campaign")
    cmd = [sys.executable, os.path.join(TOOLS, "campaign.py"), "--program", args.program, "--mpiexec", args.mpiexec,
           "--ranks", "1", "--reps", "1", "--timeout", "60", "--out", out,
           "--sweep", "solver:max_hessian=20000,1", os.path.join(HERE, "tiny_block.nml")]
    print("running:", " ".join(cmd))
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    print(run.stdout[-3000:], run.stderr[-3000:])
    check(run.returncode == 1, "campaign exit status 1 (one run failed on purpose), got %d" % run.returncode)
    csv_path = os.path.join(out, "campaign.csv")
    check(os.path.exists(csv_path), "campaign.csv written")
    if FAILURES:
        return 1
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames
        rows = list(reader)
    need = ["member", "input", "overrides", "ranks", "rep", "exit_status", "status", "wall_seconds", "case",
            "subdomains", "primal_dofs", "dual_dofs", "coarse_dim", "contact_rows", "active_contact", "converged",
            "outer_iterations", "hessian_multiplications", "cg_steps", "expansion_steps", "proportioning_steps",
            "kkt_equilibrium", "kkt_equality", "kkt_feasibility", "kkt_dual_feasibility", "kkt_complementarity",
            "kkt_max", "alpha_difference", "rec_new_seconds", "rec_standard_seconds", "contact_total_force",
            "contact_max_pressure", "contact_active_nodes", "contact_radius", "peak_rss_max_bytes",
            "peak_rss_sum_bytes", "t_total_mean", "t_total_max", "t_solve_mean", "t_solve_max",
            "t_factorization_mean", "t_rec_new_max", "t_rec_standard_max", "h5", "run_dir"]
    missing = [c for c in need if c not in cols]
    check(not missing, "CSV has the expected columns (missing: %s)" % missing)
    check(len(rows) == 2, "two rows, one per run (got %d)" % len(rows))
    good = [r for r in rows if r["member"] == "tiny_block[max_hessian=20000]"]
    bad = [r for r in rows if r["member"] == "tiny_block[max_hessian=1]"]
    check(len(good) == 1 and len(bad) == 1, "one row per member")
    if len(good) == 1:
        r = good[0]
        check(r["exit_status"] == "0" and r["status"] == "ok", "converged run: exit 0")
        check(r["converged"] == "true", "converged run: converged = true")
        check(r["case"] == "tiny_block" and r["ranks"] == "1" and r["rep"] == "1", "case name, ranks, rep")
        check(r["subdomains"] == "2" and r["coarse_dim"] == "12", "2 subdomains, coarse dimension 12")
        check(r["nsub"] == "2x1x1" and r["nel"] == "2x2x2", "nsub and nel columns")
        check(int(r["hessian_multiplications"]) >= int(r["outer_iterations"]) >= 1, "Hessian mults >= outer >= 1")
        check(int(r["contact_rows"]) == int(r["active_contact"]) == 5 * 3, "every one of 15 contact rows active")
        check(float(r["kkt_max"]) <= 1e-6, "KKT residuals small (%s)" % r["kkt_max"])
        force = float(r["contact_total_force"])
        check(abs(force - 100.0) <= 1e-6 * 100, "contact force = p Lx Ly = 100 (got %s)" % force)
        check(float(r["t_total_max"]) >= float(r["t_solve_max"]) > 0, "times: total >= solve > 0")
        check(float(r["t_total_max"]) >= float(r["t_total_mean"]) > 0, "times: max >= mean")
        check(float(r["peak_rss_sum_bytes"]) >= float(r["peak_rss_max_bytes"]) > 0, "peak RSS recorded")
        check(os.path.exists(r["h5"]), "the run's .h5 is kept")
        with open(os.path.join(r["run_dir"], "case.nml")) as f:
            nml = f.read()
        check("run_name = 'tiny_block'" in nml and "monitor = .false." in nml,
              "merged input keeps the other variables")
        check("max_hessian = 20000" in nml and os.path.join(r["run_dir"], "out") in nml,
              "merged input has the override and the run's output directory")
    if len(bad) == 1:
        r = bad[0]
        check(r["exit_status"] == "3" and r["status"] == "not converged",
              "failed run recorded with exit status 3 (got %s, %s)" % (r["exit_status"], r["status"]))
        check(r["converged"] == "false", "failed run: converged = false (its report.json is read)")
    check("FAILED: tiny_block[max_hessian=1]" in run.stdout, "the summary names the failed run")
    if len(good) == 1:
        r = good[0]
        check(r["solver_variant"].startswith("tol=") and "monitor" not in r["solver_variant"],
              "solver_variant: the changed &solver settings (tol; monitor left out), got %r" % r["solver_variant"])
        check(float(r["hessian_per_outer"]) > 0 and (r["contraction_median"] != "" or r["outer_iterations"] == "1"),
              "products per outer iteration and the contraction of ||C x|| recorded")
    check_variants(args)

    figures = os.path.join(args.workdir, "figures")
    for sub in (["weak", out, "--name", "t_weak"], ["reconstruction", out, "--name", "t_rec"]):
        p = subprocess.run([sys.executable, os.path.join(TOOLS, "plots.py"), "--figures", figures] + sub,
                           capture_output=True, text=True, timeout=60)
        print(p.stdout[-2000:], p.stderr[-2000:])
        check(p.returncode == 0, "plots.py %s exits 0" % sub[0])
    for name in ("t_weak_iterations", "t_weak_times", "t_rec"):
        check(os.path.getsize(os.path.join(figures, name + ".png")) > 1000 if os.path.exists(
            os.path.join(figures, name + ".png")) else False, "%s.png written" % name)
    print("%d failed" % len(FAILURES))
    return 1 if FAILURES else 0


def check_variants(args):
    """Two solver variants (--variant): one run each, the `variant` column, report.json's
    solver.variant naming the changed &solver settings, the variant table; a variant whose
    variable the program does not know stops the campaign before any run, with the
    program's message."""
    out = os.path.join(args.workdir, "campaign_variants")
    base = [sys.executable, os.path.join(TOOLS, "campaign.py"), "--program", args.program, "--mpiexec",
            args.mpiexec, "--ranks", "1", "--timeout", "60"]
    cmd = base + ["--out", out, "--variant", "plain", "--variant", "keep:m_no_step=keep;beta=0.25",
                  os.path.join(HERE, "tiny_block.nml")]
    print("running:", " ".join(cmd))
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    print(run.stdout[-3000:], run.stderr[-3000:])
    check(run.returncode == 0, "variant campaign exits 0 (got %d)" % run.returncode)
    csv_path = os.path.join(out, "campaign.csv")
    rows = []
    if os.path.exists(csv_path):
        with open(csv_path, newline="") as f:
            rows = list(csv.DictReader(f))
    by = {r.get("variant"): r for r in rows}
    check(sorted(by) == ["keep", "plain"], "one row per variant with the variant column (got %s)" % sorted(by))
    if "keep" in by and "plain" in by:
        check(by["keep"]["member"] == "tiny_block@keep", "member named input@variant")
        check("m_no_step=keep" in by["keep"]["solver_variant"] and "beta=0.25" in by["keep"]["solver_variant"],
              "report.json solver.variant names the variant's settings (got %r)" % by["keep"]["solver_variant"])
        check("m_no_step" not in by["plain"]["solver_variant"], "the plain variant changes nothing")
        with open(os.path.join(by["keep"]["run_dir"], "case.nml")) as f:
            nml = f.read()
        check("m_no_step = 'keep'" in nml, "the variant's setting (quoted) is in the merged input")
    check("| tiny_block | 1 | keep |" in run.stdout and "Hessian/outer" in run.stdout,
          "the variant table is printed")
    cmd = base + ["--out", out + "_bad", "--variants", "a,b", "--variant-variable", "no_such_variable",
                  os.path.join(HERE, "tiny_block.nml")]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    print(run.stdout[-2000:], run.stderr[-2000:])
    check(run.returncode != 0 and "variant 'a'" in run.stderr and "rejected" in run.stderr
          and "no_such_variable" in run.stderr, "a variant the program rejects stops the campaign with its message")
    check(not os.path.exists(os.path.join(out + "_bad", "campaign.csv")), "nothing ran for a rejected variant")


if __name__ == "__main__":
    sys.exit(main())
