#!/usr/bin/python3
"""End-to-end checks of the scenes a contact engineer sets up (docs/INPUT.md
&obstacle axis and mirror_images, the rigid-motion check, the warnings).

    check_scenes.py --program BIN --mpiexec MPIEXEC --workdir DIR CHECK [--ranks N]

CHECK is one of
  quarter    a quarter model (symmetry x0 and y0, the sphere's axis on the
             corner) and the full model of the same top-Dirichlet body (twice
             as wide, the sphere under its centre) at tol 1e-9: the quarter's
             nodal displacements equal the full model's at the same
             coordinates (the full model is the reference) to 1e-6 of the
             largest displacement.
  diagonal   a pressure-loaded quarter plate (no top Dirichlet condition,
             held by the symmetry planes and the contact): the field is
             symmetric about the diagonal x = y (u_x(x, y, z) = u_y(y, x, z),
             u_z(x, y, z) = u_z(y, x, z)) to 1e-6 of the largest displacement.
  refused    a symmetry plane off the sphere's axis exits 2 naming
             &boundary symmetry_x0 and &obstacle mirror_images (mirror_images
             = .true. runs); a body the contact cannot hold (a sphere of
             radius 0.05 with no bottom node over it) exits 2 naming
             &obstacle and the number of bottom nodes over it, also with
             --check (no internal error from the coarse factorization).
  warnings   a 1 mm cube in metres and pascals pressed by 25 times its
             height: report.json `warnings` and the log name the largest
             strain and the largest displacement; an upward top displacement
             is named a sign error; the demo-sized cube has no such warning.
  check_only `--check` creates no output folder and writes nothing.
Exit status 0 when every check passes.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np

FAILURES = []


def check(condition, what):
    print(("ok   " if condition else "FAIL ") + what)
    if not condition:
        FAILURES.append(what)


def fresh(d):
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


def write_input(path, groups):
    """groups: {group: 'a = 1, b = 2'}; &output points into the input's folder unless given."""
    groups = dict(groups)
    groups.setdefault("output", "directory = '%s', run_name = 'case'" % os.path.join(os.path.dirname(path), "out"))
    with open(path, "w") as f:
        for g, body in groups.items():
            f.write("&%s %s /\n" % (g, body))
    return path


def run(args, nml, ranks=None, extra=(), expect=0):
    cmd = [args.mpiexec, "-n", str(ranks or args.ranks), args.program] + list(extra) + [nml]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if expect is not None and p.returncode != expect:
        sys.stdout.write(p.stdout[-4000:])
        sys.stderr.write(p.stderr[-4000:])
        raise SystemExit("%s: exit %d, expected %d" % (nml, p.returncode, expect))
    return p


def fields(outdir):
    files = [f for f in os.listdir(outdir) if f.endswith(".h5")]
    assert len(files) == 1, "one .h5 file in %s, found %s" % (outdir, files)
    with h5py.File(os.path.join(outdir, files[0]), "r") as h5:
        return h5["coordinates"][...], h5["displacement"][...]


def by_position(x, u, shift=(0.0, 0.0, 0.0)):
    keys = np.round((x - np.array(shift)) * 1e9).astype(np.int64)
    return {tuple(k): v for k, v in zip(keys, u)}


def check_quarter(args):
    work = fresh(os.path.join(args.workdir, "quarter"))
    common = {"material": "young = 2.1e5, poisson = 0.3", "solver": "tol = 1e-9, monitor = .false."}
    os.makedirs(os.path.join(work, "full"))
    os.makedirs(os.path.join(work, "quarter"))
    full = write_input(os.path.join(work, "full", "case.nml"),
                       dict(common, mesh="nsub = 2, 2, 1, nel = 4, 4, 4, lengths = 2.0, 2.0, 1.0",
                            obstacle="shape = 'sphere', radius = 1.0"))
    quarter = write_input(os.path.join(work, "quarter", "case.nml"),
                          dict(common, mesh="nsub = 2, 1, 1, nel = 2, 4, 4, lengths = 1.0, 1.0, 1.0",
                               boundary="symmetry_x0 = .true., symmetry_y0 = .true.",
                               obstacle="shape = 'sphere', radius = 1.0, axis = 0.0, 0.0"))
    run(args, full)
    run(args, quarter)
    xf, uf = fields(os.path.join(work, "full", "out"))
    xq, uq = fields(os.path.join(work, "quarter", "out"))
    ref = by_position(xf, uf, shift=(1.0, 1.0, 0.0))
    got = by_position(xq, uq)
    check(all(k in ref for k in got), "every node of the quarter is a node of the full model")
    scale = np.abs(uf).max()
    diff = max(np.abs(got[k] - ref[k]).max() for k in got)
    check(scale > 1e-4, "the full model deforms (max |u| = %.3e)" % scale)
    check(diff <= 1e-6 * scale, "quarter = full model on the quarter: max diff / max |u| = %.3e <= 1e-6"
          % (diff / scale))
    with open(os.path.join(work, "quarter", "out", "report.json")) as f:
        rq = json.load(f)
    with open(os.path.join(work, "full", "out", "report.json")) as f:
        rf = json.load(f)
    fq, ff = rq["contact"]["total_force"], rf["contact"]["total_force"]
    check(abs(4 * fq - ff) <= 1e-5 * abs(ff), "4 x the quarter's contact force = the full model's (%.6e, %.6e)"
          % (4 * fq, ff))
    check(rq["case"]["obstacle"]["axis"] == [0.0, 0.0], "report.json names the axis (0, 0)")


def check_diagonal(args):
    work = fresh(os.path.join(args.workdir, "diagonal"))
    nml = write_input(os.path.join(work, "case.nml"), {
        "mesh": "nsub = 2, 2, 1, nel = 4, 4, 4, lengths = 1.0, 1.0, 0.2",
        "load": "top_pressure = 10.0",
        "boundary": "top_dirichlet = .false., symmetry_x0 = .true., symmetry_y0 = .true.",
        "obstacle": "shape = 'sphere', radius = 2.0, axis = 0.0, 0.0",
        "solver": "tol = 1e-9, monitor = .false."})
    run(args, nml)
    x, u = fields(os.path.join(work, "out"))
    at = by_position(x, u)
    swapped = by_position(x[:, [1, 0, 2]], u[:, [1, 0, 2]])
    check(set(at) == set(swapped), "the mesh is symmetric about x = y")
    scale = np.abs(u).max()
    diff = max(np.abs(at[k] - swapped[k]).max() for k in at)
    check(scale > 1e-5, "the plate deforms (max |u| = %.3e)" % scale)
    check(diff <= 1e-6 * scale, "symmetric about the diagonal: max diff / max |u| = %.3e <= 1e-6" % (diff / scale))
    corner, far = at[(0, 0, 0)][2], at[tuple(np.round(np.array([1.0, 1.0, 0.0]) * 1e9).astype(np.int64))][2]
    check(abs(corner) < abs(far), "the corner over the sphere moves less than the far corner (%.3e, %.3e)"
          % (corner, far))


def check_refused(args):
    work = fresh(os.path.join(args.workdir, "refused"))
    off = {"mesh": "nsub = 2, 1, 1, nel = 2, 4, 4", "boundary": "symmetry_x0 = .true.",
           "solver": "monitor = .false."}
    nml = write_input(os.path.join(work, "off_axis.nml"), off)
    p = run(args, nml, expect=2)
    text = p.stdout + p.stderr
    check(re.search(r"group &boundary, variable symmetry_x0: .*&obstacle axis\(1\).*mirror_images = \.true\.", text)
          is not None, "a symmetry plane off the axis: exit 2 naming symmetry_x0, axis and mirror_images")
    nml = write_input(os.path.join(work, "mirror.nml"), dict(off, obstacle="mirror_images = .true."))
    run(args, nml, extra=["--check"], expect=0)
    check(True, "mirror_images = .true. accepts it (--check exits 0)")
    tiny = {"mesh": "nsub = 1, 1, 2, nel = 5, 5, 2", "load": "top_pressure = 10.0",
            "boundary": "top_dirichlet = .false., symmetry_x0 = .true., symmetry_y0 = .true.",
            "obstacle": "shape = 'sphere', radius = 0.05, mirror_images = .true.", "solver": "monitor = .false."}
    nml = write_input(os.path.join(work, "tiny.nml"), tiny)
    for extra in ([], ["--check"]):
        p = run(args, nml, extra=extra, expect=2)
        text = p.stdout + p.stderr
        check(re.search(r"group &obstacle, variable shape: .* 0 bottom node\(s\) lie over the obstacle", text)
              is not None, "tiny sphere %s: exit 2 naming &obstacle and 0 bottom nodes over it" % " ".join(extra))
        check("pivot" not in text and "MPI_ABORT" not in text, "no internal error %s" % " ".join(extra))
    # the same sphere on the corner of a quarter model touches one node: held
    nml = write_input(os.path.join(work, "corner.nml"), dict(tiny, obstacle="shape = 'sphere', radius = 0.05, "
                                                                             "axis = 0.0, 0.0"))
    run(args, nml, extra=["--check"], expect=0)
    check(True, "the tiny sphere on the quarter's corner holds the body (--check exits 0)")


def check_warnings(args):
    work = fresh(os.path.join(args.workdir, "warnings"))
    os.makedirs(os.path.join(work, "metres"))
    nml = write_input(os.path.join(work, "metres", "case.nml"), {
        "mesh": "nsub = 2, 1, 1, nel = 2, 4, 4, lengths = 0.001, 0.001, 0.001",
        "material": "young = 2.1e11, poisson = 0.3",
        "boundary": "top_displacement = 0.0, 0.0, -0.025",
        "obstacle": "shape = 'sphere', radius = 0.001", "solver": "monitor = .false."})
    p = run(args, nml)
    with open(os.path.join(work, "metres", "out", "report.json")) as f:
        w = json.load(f).get("warnings", [])
    strain = [s for s in w if "strain" in s and "1e-2" in s]
    disp = [s for s in w if "largest displacement" in s]
    check(len(strain) == 1, "report.json warns of the largest strain above 1e-2 (%s)" % strain)
    check(len(disp) == 1, "report.json warns of the largest displacement above a tenth of the smallest length")
    check(all(s.split(":")[0] in p.stdout for s in strain + disp), "the log says the same")
    log = os.path.join(work, "metres", "out", "case.log")
    check(os.path.exists(log) and "largest strain" in open(log).read(), "the log file beside report.json has it")
    os.makedirs(os.path.join(work, "up"))
    nml = write_input(os.path.join(work, "up", "case.nml"), {
        "mesh": "nsub = 2, 1, 1, nel = 2, 2, 2", "boundary": "top_displacement = 0.0, 0.0, 0.01",
        "solver": "monitor = .false."})
    p = run(args, nml, extra=["--check"])
    check(re.search(r"top_displacement\(3\) = \+?1\.000E-02 .*upward.*sign", p.stdout, re.I) is not None,
          "an upward top displacement is named a sign error")
    check("is larger than what" not in p.stdout, "not the gap warning")
    os.makedirs(os.path.join(work, "demo"))
    nml = write_input(os.path.join(work, "demo", "case.nml"), {
        "mesh": "nsub = 2, 1, 1, nel = 2, 4, 4", "solver": "monitor = .false."})
    run(args, nml)
    with open(os.path.join(work, "demo", "out", "report.json")) as f:
        w = json.load(f).get("warnings", [])
    check(not any("strain" in s or "largest displacement" in s for s in w), "a small-strain case is not warned")


def check_check_only(args):
    work = fresh(os.path.join(args.workdir, "check_only"))
    out = os.path.join(work, "never", "made")
    nml = write_input(os.path.join(work, "case.nml"), {
        "mesh": "nsub = 2, 1, 1, nel = 2, 2, 2", "output": "directory = '%s', run_name = 'x'" % out})
    p = run(args, nml, extra=["--check"])
    check("input checked: OK" in p.stdout, "--check says OK")
    check(not os.path.exists(os.path.join(work, "never")), "--check creates no output folder")
    check(sorted(os.listdir(work)) == ["case.nml"], "--check writes nothing (got %s)" % sorted(os.listdir(work)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--program", required=True)
    ap.add_argument("--mpiexec", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("check", choices=["quarter", "diagonal", "refused", "warnings", "check_only"])
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    globals()["check_" + args.check](args)
    print("%d failed" % len(FAILURES))
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
