#!/usr/bin/python3
"""CTest check (label `cluster`) of `tools/campaign.py --scheduler slurm` on a real Slurm.

    check_cluster.py --program feticontact --workdir DIR

Starts a one-node Slurm with tools/local_slurm.sh (its files under DIR/slurm), then:
  A. submits a weak campaign (cube_h4_n8 and cube_h4_n64, 1 and 2 ranks) plus a member with a
     bad input, waits and collects: every good job completed, one CSV row per run with the
     solver's figures, exit status 0 and the KKT check passed; the bad member failed with the
     program's exit status 2 and its error message; the job scripts have the #SBATCH lines;
  B. submits the same campaign again: no job is duplicated; `--resubmit failed` sends only the
     failed members again and keeps the first attempt's rows;
  C. cancels a running job with scancel: reported cancelled, its row kept;
  D. writes a job script with --dry-run (launcher srun), submits it by hand with sbatch:
     --collect picks the result up;
  E. a job that outlives its time limit of 1 minute (a stand-in program that sleeps; it runs
     alongside C and D) is reported timed out, exit status 124 in its row.
Always stops the daemons at the end. Exit 77 (CTest SKIP_RETURN_CODE) when Slurm cannot be
started on this machine (not root, packages not installable); 0 when every check passes.
"""
import argparse
import csv
import json
import os
import signal
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CAMPAIGN = [sys.executable, os.path.join(ROOT, "tools", "campaign.py")]
LOCAL_SLURM = os.path.join(ROOT, "tools", "local_slurm.sh")
SKIP = 77
DEADLINE = time.monotonic() + 500  # reset after the start: 200 s for the checks; CTest's limit is above
FAILURES = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what, flush=True)
    if not condition:
        FAILURES.append(what)
    return condition


def run(cmd, timeout=60, **kw):
    timeout = max(5, min(timeout, DEADLINE - time.monotonic()))
    print("$ " + " ".join(cmd), flush=True)
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)
    out = p.stdout + p.stderr
    print(out[-4000:], flush=True)
    return p.returncode, p.stdout, out


def rows_of(out):
    with open(os.path.join(out, "campaign.csv"), newline="") as f:
        return list(csv.DictReader(f))


def jobs_of(out):
    with open(os.path.join(out, "jobs.json")) as f:
        return json.load(f)["jobs"]


def squeue_ids():
    p = subprocess.run(["squeue", "-h", "-t", "all", "-o", "%i"], capture_output=True, text=True, timeout=30)
    return sorted(p.stdout.split())


def campaign_a(args, common):
    out = os.path.join(args.workdir, "weak")
    inputs = [os.path.join(ROOT, "inputs", "weak", "cube_h4_n8.nml"), os.path.join(ROOT, "inputs", "weak",
                                                                                   "cube_h4_n64.nml"),
              os.path.join(HERE, "bad_input.nml")]
    submit = CAMPAIGN + common + ["--ranks", "1,2", "--out", out] + inputs
    t0 = time.monotonic()
    rc, stdout, _ = run(submit + ["--wait", "--poll", "1"], timeout=150)
    print("campaign A: %.1f s" % (time.monotonic() - t0))
    check(rc == 1, "submit --wait exits 1 (the bad member fails on purpose), got %d" % rc)
    jobs = jobs_of(out)
    check(len(jobs) == 6 and all(j.get("job_id") for j in jobs), "jobs.json: 6 jobs, each with its job id")
    rows = rows_of(out)
    check(len(rows) == 6, "CSV: one row per run, 6 (got %d)" % len(rows))
    good = [r for r in rows if r["member"].startswith("cube_h4")]
    bad = [r for r in rows if r["member"] == "bad_input"]
    check(len(good) == 4 and len(bad) == 2, "4 good and 2 bad rows")
    for r in good:
        what = "%s np%s" % (r["member"], r["ranks"])
        check(r["exit_status"] == "0" and r["status"] == "ok", what + ": exit status 0")
        check(r["converged"] == "true" and r["kkt_passed"] == "true", what + ": converged, KKT check passed")
        check(r["subdomains"] == r["member"].split("_n")[1] and r["ranks_reported"] == r["ranks"],
              what + ": subdomains and ranks from report.json")
        check(int(r["hessian_multiplications"]) >= int(r["outer_iterations"]) >= 1 and
              float(r["kkt_max"]) < 1e-3 and float(r["t_total_max"]) > 0 and float(r["wall_seconds"]) > 0,
              what + ": iterations, KKT residuals, times")
        check(r["job_id"] in [j["job_id"] for j in jobs] and r["started"] and r["load_before"],
              what + ": job id, start time and load from the run folder")
    for r in bad:
        check(r["exit_status"] == "2" and r["status"].startswith("bad input"),
              "bad input np%s: failed with the program's exit status 2 (got %s, %s)" % (
                  r["ranks"], r["exit_status"], r["status"]))
        check("ERROR" in r["message"] and "bogus" in r["message"],
              "bad input np%s: the program's message in the CSV (%s)" % (r["ranks"], r["message"][:80]))
    rc, stdout, _ = run(CAMPAIGN + ["--status", out])
    check(stdout.count("| completed |") == 4 and stdout.count("| failed (exit 2) |") == 2,
          "--status: 4 jobs completed, 2 failed (exit 2)")
    with open(os.path.join(out, "runs", "cube_h4_n64", "np2", "job.sh")) as f:
        script = f.read()
    for line in ("#SBATCH --job-name=", "#SBATCH --ntasks=2", "#SBATCH --ntasks-per-node=2",
                 "#SBATCH --cpus-per-task=1", "#SBATCH --time=5:00", "#SBATCH --mem-per-cpu=1G",
                 "#SBATCH --output=", "#SBATCH --error=", "export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1",
                 "mpirun -n 2 --bind-to none"):
        check(line in script, "job script has %r" % line)

    # B: the same submission again duplicates nothing; --resubmit failed sends the two bad ones
    before = squeue_ids()
    rc, stdout, _ = run(CAMPAIGN + common + ["--ranks", "1,2", "--out", out] + inputs)
    check(rc == 0 and stdout.count("not submitted again") == 6 and squeue_ids() == before,
          "submitting again: no new job (6 'not submitted again')")
    check([j["job_id"] for j in jobs_of(out)] == [j["job_id"] for j in jobs], "jobs.json unchanged")
    rc, stdout, _ = run(CAMPAIGN + ["--resubmit", "failed", "--out", out, "--time", "4:00", "--wait", "--poll", "1"],
                        timeout=90)
    check(stdout.count("submitted again as job") == 2, "--resubmit failed: only the 2 failed jobs submitted again")
    new = jobs_of(out)
    check([j["job_id"] for j in new if j["member"].startswith("cube")] ==
          [j["job_id"] for j in jobs if j["member"].startswith("cube")], "completed jobs not submitted again")
    rows = rows_of(out)
    check(len(rows) == 8 and sum(r["member"] == "bad_input" for r in rows) == 4,
          "CSV keeps the first attempt's rows of the failed members (8 rows, got %d)" % len(rows))


def submit_timeout(args, common):
    fake = os.path.join(args.workdir, "sleeper.sh")
    with open(fake, "w") as f:
        f.write("#!/bin/sh\n# stands in for feticontact: outlives the time limit\nsleep 600\n")
    os.chmod(fake, 0o755)
    out = os.path.join(args.workdir, "timeout")
    common = [c if c != args.program else fake for c in common]
    common[common.index("--time") + 1] = "1"
    rc, stdout, _ = run(CAMPAIGN + common + ["--ranks", "1", "--out", out,
                                             os.path.join(ROOT, "inputs", "weak", "cube_h4_n8.nml")])
    check(rc == 0 and "submitted job" in stdout, "submitted a job with a time limit of 1 minute")
    return out


def collect_timeout(out):
    rc, stdout, _ = run(CAMPAIGN + ["--collect", out, "--wait", "--poll", "2"], timeout=150)
    check("| timeout | rep1 timeout |" in stdout, "--collect: the job past its time limit is reported timeout")
    rows = rows_of(out)
    check(len(rows) == 1 and rows[0]["exit_status"] == "124" and rows[0]["status"] == "timeout",
          "the timed-out run keeps its row (exit status 124, status timeout)")


def campaign_c(args, common):
    out = os.path.join(args.workdir, "cancel")
    rc, stdout, _ = run(CAMPAIGN + common + ["--ranks", "1", "--out", out,
                                             os.path.join(ROOT, "inputs", "weak", "cube_h4_n512.nml")])
    job_id = jobs_of(out)[0]["job_id"]
    running = False
    while time.monotonic() < DEADLINE - 40:
        rc, stdout, _ = run(CAMPAIGN + ["--status", out])
        if "rep1 running" in stdout:
            running = True
            break
        time.sleep(1)
    check(running, "--status reports the job running")
    run(["scancel", job_id])
    rc, stdout, _ = run(CAMPAIGN + ["--collect", out, "--wait", "--poll", "1"], timeout=60)
    check("| cancelled | rep1 cancelled |" in stdout, "--collect: the job scancel ended is reported cancelled")
    rows = rows_of(out)
    check(len(rows) == 1 and rows[0]["status"] == "cancelled" and rows[0]["job_id"] == job_id,
          "the cancelled run keeps its row (status cancelled)")


def by_hand(args, common):
    out = os.path.join(args.workdir, "by_hand")
    rc, stdout, _ = run(CAMPAIGN + common + ["--ranks", "1", "--launcher", "srun", "--dry-run", "--out", out,
                                             os.path.join(ROOT, "inputs", "weak", "cube_h4_n8.nml")])
    script = os.path.join(out, "runs", "cube_h4_n8", "np1", "job.sh")
    check(rc == 0 and os.path.exists(script), "--dry-run writes the script")
    with open(script) as f:
        check("srun --mpi=pmix \"$program\"" in f.read(), "launcher srun with the MPI plugin named")
    rc, stdout, _ = run(CAMPAIGN + ["--status", out])
    check("not submitted" in stdout, "--status: written, not submitted")
    rc, stdout, _ = run(["sbatch", script], cwd=args.workdir)  # by hand, from another folder
    check(rc == 0 and "Submitted batch job" in stdout, "sbatch by hand")
    hand_id = stdout.split("Submitted batch job")[-1].strip()
    rc, stdout, _ = run(CAMPAIGN + ["--collect", out, "--wait", "--poll", "1"], timeout=60)
    rows = rows_of(out)
    check(rc == 0 and len(rows) == 1 and rows[0]["exit_status"] == "0" and rows[0]["kkt_passed"] == "true"
          and rows[0]["job_id"] == hand_id == jobs_of(out)[0].get("job_id"),
          "--collect picks up the job submitted by hand (srun, exit 0, KKT passed, its job id)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--workdir", required=True)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    env_dir = os.path.join(args.workdir, "slurm")
    os.environ["FETICONTACT_SLURM_DIR"] = env_dir
    os.environ["SLURM_CONF"] = os.path.join(env_dir, "slurm.conf")
    for sub in ("weak", "cancel", "by_hand", "timeout"):
        subprocess.run(["rm", "-rf", os.path.join(args.workdir, sub)])

    def stop(signum=None, frame=None):
        subprocess.run([LOCAL_SLURM, "stop"], timeout=120)
        if signum:
            sys.exit(1)

    signal.signal(signal.SIGTERM, stop)
    t0 = time.monotonic()
    global DEADLINE
    try:
        p = subprocess.run([LOCAL_SLURM, "start"], timeout=300)  # may install packages first
    except subprocess.TimeoutExpired:
        p = subprocess.CompletedProcess([], 1)
    if p.returncode == SKIP:
        print("SKIPPED: Slurm cannot be started on this machine (see above)")
        return SKIP
    try:
        if not check(p.returncode == 0, "tools/local_slurm.sh start (%.1f s)" % (time.monotonic() - t0)):
            return 1
        DEADLINE = time.monotonic() + 200
        leftover = subprocess.run(["squeue", "-h", "-o", "%i"], capture_output=True, text=True,
                                  timeout=30).stdout.split()  # jobs of an earlier check that was killed
        if leftover:
            run(["scancel"] + leftover)
        common = ["--scheduler", "slurm", "--program", args.program, "--mpi-args=--bind-to none",
                  "--time", "5:00", "--mem-per-rank", "1G"]
        try:
            campaign_a(args, common)
            timeout_out = submit_timeout(args, common)  # runs alongside C and D (one core each)
            campaign_c(args, common)
            by_hand(args, common)
            collect_timeout(timeout_out)
        except (OSError, ValueError, KeyError, IndexError, subprocess.SubprocessError) as e:
            check(False, "%s: %s" % (type(e).__name__, e))
    finally:
        stop()
        rc = subprocess.run([LOCAL_SLURM, "status"], capture_output=True, text=True).returncode
        check(rc == 3, "tools/local_slurm.sh stop: no daemon left running")
    print("%d failed (%.0f s)" % (len(FAILURES), time.monotonic() - t0))
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
