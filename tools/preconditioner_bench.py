#!/usr/bin/python3
"""Run inputs x `&solver preconditioner` variants on 2 ranks, side by side.

    tools/preconditioner_bench.py PROGRAM OUTDIR INPUT.nml...
    VARIANTS=none,dirichlet tools/preconditioner_bench.py ...   (default none,lumped,dirichlet)

For every input, the variants run one after the other (so that the times of
one input are measured under the same machine load), each in
OUTDIR/<input>_<variant>/ (case.nml with `preconditioner` and the output
directory set and HDF5 off, log.txt, report.json), `nice mpirun -np 2`,
killed after 400 s (exit 124). One line per run is appended to
OUTDIR/results.tsv: exit status, outer iterations, Hessian multiplications,
CG steps, preconditioner applications, the face condition estimate and the
extreme Ritz values (report.json `solver`), the solve time
(`performance.solve_seconds`, max over ranks), the total time (timer
'total', max over ranks) and the wall time of mpirun.
Used for docs/RESULTS.md "Preconditioned MPRGP (issue 14, item 3)".
"""
import json, os, re, subprocess, sys, time
prog = sys.argv[1]; out = sys.argv[2]; inputs = sys.argv[3:]
variants = os.environ.get("VARIANTS", "none,lumped,dirichlet").split(",")
env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")
os.makedirs(out, exist_ok=True)
tsv = os.path.join(out, "results.tsv")
if not os.path.exists(tsv):
    open(tsv, "w").write("input\tvariant\texit\touter\thessian\tcg\tprec_apps\tface_cond\tritz_min\tritz_max\tsolve_s\ttotal_s\twall_s\n")
for inp in inputs:
    text = open(inp).read()
    name = os.path.splitext(os.path.basename(inp))[0]
    for v in variants:
        d = os.path.join(out, name + "_" + v)
        os.makedirs(d, exist_ok=True)
        t = re.sub(r"directory\s*=\s*'[^']*'", "directory = '%s'" % d, text)
        t = re.sub(r"write_hdf5\s*=\s*\.true\.", "write_hdf5 = .false.", t)
        if re.search(r"^&solver", t, re.M):
            t = re.sub(r"^&solver", "&solver preconditioner = '%s'," % v, t, count=1, flags=re.M)
        else:
            t += "\n&solver preconditioner = '%s' /\n" % v
        nml = os.path.join(d, "case.nml")
        open(nml, "w").write(t)
        t0 = time.time()
        with open(os.path.join(d, "log.txt"), "w") as log:
            rc = subprocess.call(["timeout", "400", "nice", "mpirun", "-np", "2", prog, nml], stdout=log,
                                 stderr=subprocess.STDOUT, env=env)
        wall = time.time() - t0
        row = [name, v, str(rc)] + [""] * 9 + ["%.1f" % wall]
        try:
            r = json.load(open(os.path.join(d, "report.json")))
            s = r["solver"]; tm = r["timings"]
            def tmax(k):
                for e in (tm if isinstance(tm, list) else [dict(name=a, **b) for a, b in tm.items()]):
                    if e.get("name") == k: return "%.3f" % e.get("max", 0)
                return ""
            row = [name, v, str(rc), str(s["outer_iterations"]), str(s["hessian_multiplications"]), str(s["cg_steps"]),
                   str(s.get("preconditioner_applications")), "%s" % s.get("face_condition_estimate"),
                   "%s" % s.get("face_ritz_min"), "%s" % s.get("face_ritz_max"),
                   "%.3f" % r["performance"]["solve_seconds"], tmax("total"), "%.1f" % wall]
        except Exception as e:
            row[3] = "noreport:" + str(e)[:40]
        open(tsv, "a").write("\t".join(row) + "\n")
        print("\t".join(row), flush=True)
