#!/usr/bin/python3
"""End-to-end checks of a load history (&history, docs/INPUT.md).

    check_history.py --program BIN --mpiexec MPIEXEC --workdir DIR CHECK [--ranks N]

CHECK is one of
  steps     a loading and unloading history on a small cube: every step's
            displacements (HDF5) and contact force equal those of a separate
            one-step run at the same load (top displacement scaled by the
            step's factor, obstacle at the step's gap) to a bound derived
            from the solver tolerance; the history is warm started, the
            separate runs are cold.
  restart   a history stopped after a step (time_limit) and continued with
            restart = .true. gives the same report records (all but times)
            and bit-identical HDF5 fields as an uninterrupted one.
  bad       bad history input and bad checkpoints: exit status 2 and a
            message naming the group and variable (or the checkpoint).
  signal    SIGUSR1 to mpirun (forwarded to the ranks; SIGTERM under a batch
            system) stops a long history after the step under way, with its
            checkpoint; restart = .true. continues with the next step to the end.
  savings   warm starts on a history whose active set cannot change (a
            cube pressed by its top face onto a plane: its whole bottom in
            contact at every load, lambda linear in the load): each step after the first starts from the exact
            extrapolation, so it needs at most WARM_STEP_BOUND products
            where a cold step needs the whole solve; with
            &reconstruction method = 'multiplier' (the masked coarse
            instance left to the faces) and with 'both' (the standard
            reconstruction's matrix apart from the faces') every warm step
            reuses the face matrices of the step before; the two give the
            same steps, and the cold steps' solution to the tolerance; also
            with G G^T's Schur rows (216 subdomains).
  paraview  ParaView (pvpython, Debian's python3-paraview, under xvfb-run)
            opens the temporal XDMF and steps through every time; exit 77
            (skipped) when pvpython is absent.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np

SKIP = 77
TOL = 1e-9
# displacements: the solver stops when the constraint violation is below
# tol times the data's displacements; the primal error follows through the
# condition of the stiffness (a few hundred here): 1e3 tol relative to max |u|.
U_BOUND = 1e3 * TOL
# the contact force is the sum of the multipliers: the same bound, relative.
F_BOUND = 1e3 * TOL

BASE = """&mesh {mesh} /
&material young = 2.1e5, poisson = 0.3 /
&boundary top_dirichlet = .true., top_displacement = 0.0, 0.0, {uz!r} /
&obstacle shape = 'sphere', radius = 1.0, gap = {gap!r} /
&solver tol = {tol!r} /
&output directory = '{out}', run_name = 'run' /
"""

TOP_UZ = -0.02


MESH = 'nsub = 2, 2, 2, nel = 4, 4, 4'


def write_input(path, uz, gap, out, history=''):
    with open(path, 'w') as f:
        f.write(BASE.format(mesh=MESH, uz=uz, gap=gap, tol=TOL, out=out))
        f.write(history)


def run(args, nml, ranks=None, expect=0):
    ranks = ranks or args.ranks
    cmd = [args.mpiexec, '-n', str(ranks), args.program, nml]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    if expect is not None and p.returncode != expect:
        sys.stdout.write(p.stdout[-4000:])
        sys.stderr.write(p.stderr[-4000:])
        raise SystemExit('%s: exit %d, expected %d' % (nml, p.returncode, expect))
    return p


def read_h5(path):
    import h5py
    with h5py.File(path, 'r') as f:
        return {k: np.array(f[k]) for k in f.keys()}


def fresh(d):
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


def check_steps(args):
    work = fresh(os.path.join(args.workdir, 'steps'))
    hist_out = os.path.join(work, 'history')
    # 6 steps: factors 1/3, 2/3, 1, 2/3, 1/3, 0 (unloaded through the loading factors to 0);
    # the obstacle moves on the way down
    gaps = [0.0, 0.0, 0.0, 0.001, 0.002, 0.002]
    history = "&history nsteps = 6, path = 'load_unload', recycle = .true., gaps = %s /\n" % ', '.join(
        repr(g) for g in gaps)
    nml = os.path.join(work, 'history.nml')
    write_input(nml, TOP_UZ, 0.0, hist_out, history)
    run(args, nml)
    rep = json.load(open(os.path.join(hist_out, 'report.json')))
    steps = rep['history']
    assert len(steps) == 6, 'history records: %d' % len(steps)
    factors = [1 / 3, 2 / 3, 1.0, 2 / 3, 1 / 3, 0.0]
    # the top level describes the peak (step 3), named in `step`
    assert rep['step'] == 3, 'report.json step %r, expected the peak 3' % rep.get('step')
    assert rep['contact']['total_force'] == steps[2]['total_force'], (rep['contact'], steps[2])
    worst_u = worst_f = 0.0
    for k, rec in enumerate(steps, start=1):
        assert abs(rec['load_factor'] - factors[k - 1]) < 1e-15, rec['load_factor']
        assert rec['kkt_passed'] and rec['converged'], rec
        if factors[k - 1] == 0:
            # the unloaded state: no separate run (its solution is exactly zero), the zero field itself
            uh = read_h5(os.path.join(hist_out, 'run_step%04d.h5' % k))['displacement']
            assert rec['total_force'] == 0 and np.max(np.abs(uh)) == 0, rec
            print('step %d factor 0 gap %.4f: force 0, u = 0 (the unloaded state)' % (k, rec['gap']))
            continue
        assert (rec['warm_start'] != 'cold') == (k > 1), rec
        single_out = os.path.join(work, 'single%d' % k)
        snml = os.path.join(work, 'single%d.nml' % k)
        write_input(snml, TOP_UZ * factors[k - 1], gaps[k - 1], single_out)
        run(args, snml)
        srep = json.load(open(os.path.join(single_out, 'report.json')))
        uh = read_h5(os.path.join(hist_out, 'run_step%04d.h5' % k))['displacement']
        us = read_h5(os.path.join(single_out, 'run.h5'))['displacement']
        du = np.max(np.abs(uh - us)) / np.max(np.abs(us))
        fs = srep['contact']['total_force']
        df = abs(rec['total_force'] - fs) / max(abs(fs), 1e-300)
        worst_u, worst_f = max(worst_u, du), max(worst_f, df)
        print('step %d factor %.4f gap %.4f: |du|/|u| %.2e, |dF|/|F| %.2e, Hessian %d (history) %d (single)'
              % (k, rec['load_factor'], rec['gap'], du, df, rec['hessian_multiplications'],
                 srep['solver']['hessian_multiplications']))
        assert du <= U_BOUND, 'step %d: displacements differ by %.3e > %.1e' % (k, du, U_BOUND)
        assert df <= F_BOUND, 'step %d: contact force differs by %.3e > %.1e' % (k, df, F_BOUND)
    # the loads differ: a history that solved one load only would fail above; make sure the
    # forces really change along the path (loading up, unloading down)
    forces = [r['total_force'] for r in steps]
    assert forces[0] < forces[1] < forces[2] and forces[2] > forces[3] > forces[4] > forces[5], forces
    # the warm steps' face solves start from the kept face CG directions of the earlier steps
    assert any(r['recycled_directions'] > 0 for r in steps[1:]), steps
    print('steps: worst |du|/|u| %.2e (bound %.1e), |dF|/|F| %.2e (bound %.1e)' % (worst_u, U_BOUND, worst_f, F_BOUND))


PRESSURE = """&mesh nsub = 2, 2, 2, nel = 3, 3, 3 /
&material young = 2.1e5, poisson = 0.3 /
&load top_pressure = {p!r} /
&boundary top_dirichlet = .false., symmetry_x0 = .true., symmetry_y0 = .true. /
&obstacle shape = 'sphere', radius = 20.0, gap = {gap!r}, mirror_images = .true. /
&solver tol = {tol!r} /
&output directory = '{out}', run_name = 'run' /
"""
PEAK_PRESSURE = 200.0


def check_pressure_steps(args):
    """A pressure-loaded history (free top face held by the symmetry planes and the obstacle)
    whose obstacle moves: every step equals a separate one-step run at that step's pressure and
    gap (U_BOUND, F_BOUND), its recorded contact force balances the step's load p Lx Ly (the
    symmetry planes hold x and y only) to 100 tol, and equals (as does the log's step line) the
    bottom reactions recomputed from
    the step's HDF5 displacements by the test's own element assembly (contact_reference)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import contact_reference
    work = fresh(os.path.join(args.workdir, 'pressure'))
    hist_out = os.path.join(work, 'history')
    factors = [0.25, 1.0, 0.5, 0.75]
    gaps = [0.0, 0.0, -0.002, 0.001]
    history = "&history nsteps = 4, path = 'list', load_factors = %s, gaps = %s /\n" % (
        ', '.join(repr(f) for f in factors), ', '.join(repr(g) for g in gaps))
    nml = os.path.join(work, 'history.nml')
    with open(nml, 'w') as f:
        f.write(PRESSURE.format(p=PEAK_PRESSURE, gap=0.0, tol=TOL, out=hist_out) + history)
    log = run(args, nml).stdout
    steps = json.load(open(os.path.join(hist_out, 'report.json')))['history']
    assert len(steps) == 4, 'history records: %d' % len(steps)
    # the log's step lines state the same forces (es11.4: 5 digits)
    logged = [float(f) for f in re.findall(r'step \d+/4: factor .*?, force\s+([-+0-9.eE]+)', log)]
    assert len(logged) == 4, 'step lines in the log: %d' % len(logged)
    for k, rec in enumerate(steps, start=1):
        assert abs(rec['load_factor'] - factors[k - 1]) < 1e-15 and rec['gap'] == gaps[k - 1], rec
        assert rec['kkt_passed'] and rec['converged'], rec
        single_out = os.path.join(work, 'single%d' % k)
        snml = os.path.join(work, 'single%d.nml' % k)
        with open(snml, 'w') as f:
            f.write(PRESSURE.format(p=PEAK_PRESSURE * factors[k - 1], gap=gaps[k - 1], tol=TOL, out=single_out))
        run(args, snml)
        srep = json.load(open(os.path.join(single_out, 'report.json')))
        h = read_h5(os.path.join(hist_out, 'run_step%04d.h5' % k))
        us = read_h5(os.path.join(single_out, 'run.h5'))['displacement']
        du = np.max(np.abs(h['displacement'] - us)) / np.max(np.abs(us))
        fs = srep['contact']['total_force']
        df = abs(rec['total_force'] - fs) / abs(fs)
        load = PEAK_PRESSURE * factors[k - 1]                 # p Lx Ly, Lx = Ly = 1
        case = contact_reference.Case.read(snml)
        r = contact_reference.copy_reactions(case, h['coordinates'], h['displacement'], h['connectivity'],
                                             h['subdomain'])
        bottom = np.abs(h['coordinates'][:, 2]) < 1e-12
        fu = r[bottom, 2].sum()
        print('step %d factor %.2f gap %.4f: |du|/|u| %.2e, |dF|/|F| %.2e, force %.10e, from u %.10e, load %.4e'
              % (k, factors[k - 1], gaps[k - 1], du, df, rec['total_force'], fu, load))
        assert du <= U_BOUND, 'step %d: displacements differ by %.3e > %.1e' % (k, du, U_BOUND)
        assert df <= F_BOUND, 'step %d: contact force differs by %.3e > %.1e' % (k, df, F_BOUND)
        assert abs(rec['total_force'] - load) <= 100 * TOL * load, 'step %d: recorded force %.10e, load %.10e' % (
            k, rec['total_force'], load)
        assert abs(fu - rec['total_force']) <= 100 * TOL * load, 'step %d: recorded force %.10e, from u %.10e' % (
            k, rec['total_force'], fu)
        assert abs(logged[k - 1] - fu) <= 1e-4 * load, 'step %d: logged force %.4e, from u %.10e' % (
            k, logged[k - 1], fu)
    print('pressure: 4 steps equal their separate runs, every recorded force balances the load')


BLOCK = """&mesh nsub = {nsub}, {nsub}, {nsub}, nel = {nel}, {nel}, {nel} /
&material young = 2.1e5, poisson = 0.3 /
&boundary top_dirichlet = .true., top_displacement = 0.0, 0.0, -0.01 /
&obstacle shape = 'plane', gap = 0.0 /
&solver tol = 1e-8 /
&reconstruction method = '{method}' /
&output directory = '{out}', run_name = 'run', write_hdf5 = .false. /
&history nsteps = 5, path = 'ramp', warm_start = {warm}, recycle = {recycle} /
"""
# a warm step on the face of the step before with the exact extrapolation: its start meets
# the tolerance up to the two previous solves' errors (amplified at most 3x by the
# extrapolation with equal increments), so the face check (1 product), the start gradient
# of the face solve (1) and the few CG steps that take 3x tol below the face target
# (tol / 2: a factor 6, two steps at CG's worst rate of 3 per step on this face) suffice
WARM_STEP_BOUND = 4


def block_history(args, work, name, method, warm, nsub=2, nel=3, recycle=None):
    out = os.path.join(work, name)
    nml = os.path.join(work, name + '.nml')
    flag = lambda b: '.true.' if b else '.false.'
    with open(nml, 'w') as f:
        f.write(BLOCK.format(method=method, out=out, warm=flag(warm), recycle=flag(warm if recycle is None else recycle),
                             nsub=nsub, nel=nel))
    run(args, nml)
    return json.load(open(os.path.join(out, 'report.json')))['history']


def check_savings(args):
    work = fresh(os.path.join(args.workdir, 'savings'))
    cold = block_history(args, work, 'cold', 'both', False)
    warm = block_history(args, work, 'warm', 'both', True)
    kept = block_history(args, work, 'kept', 'multiplier', True)
    for rec in cold + warm + kept:
        assert rec['converged'] and rec['kkt_passed'], rec
    hc = [r['hessian_multiplications'] for r in cold]
    hw = [r['hessian_multiplications'] for r in warm]
    print('Hessian products per step: cold %s, warm %s' % (hc, hw))
    # the first step is a cold solve in both
    assert hw[0] == hc[0], (hw, hc)
    # the active set is that of the first step at every load (uniform contact pressure)
    assert len(set(r['active_nodes'] for r in warm)) == 1, warm
    assert all(h <= WARM_STEP_BOUND for h in hw[1:]), 'warm steps need more than %d products: %s' % (
        WARM_STEP_BOUND, hw)
    # hence the history's saving: at least 2x as soon as a cold solve needs 2 * WARM_STEP_BOUND
    assert min(hc[1:]) >= 2 * WARM_STEP_BOUND, hc
    assert 2 * sum(hw[1:]) <= sum(hc[1:]), (hw, hc)
    # face reuse: the steps after the first reuse the face of the step before, with either
    # reconstruction (the standard one's G_A G_A^T here is G G^T itself: every contact row active)
    reused = [r['faces_reused'] for r in kept]
    print('faces reused per step (method multiplier): %s; with both: %s' % (
        reused, [r['faces_reused'] for r in warm]))
    assert all(n >= 1 for n in reused[1:]), reused
    assert all(r['faces_reused'] >= 1 for r in warm[1:]), warm
    # ... the reconstruction method does not touch the solve: the same steps
    for a, b in zip(warm, kept):
        assert a['hessian_multiplications'] == b['hessian_multiplications'], (a, b)
        df = abs(a['total_force'] - b['total_force']) / abs(a['total_force'])
        assert df <= 1e-12, 'step %d: force %.17g (both) vs %.17g (multiplier)' % (
            a['step'], a['total_force'], b['total_force'])
    # ... and the reused faces give the solution the cold steps' own faces give, to the solver
    # tolerance (1e-8 here; the bound of F_BOUND scaled to it)
    for a, c in zip(warm, cold):
        df = abs(a['total_force'] - c['total_force']) / abs(c['total_force'])
        assert df <= 1e3 * 1e-8, 'step %d: force %.17g (warm, faces reused) vs %.17g (cold)' % (
            a['step'], a['total_force'], c['total_force'])
    # the scaled start of step 2 (lambda and muhat of step 1 times the ratio of the load factors):
    # with a zero gap on the plane and every contact row active, lambda is linear in the load
    # factor, so the start is step 2's solution to step 1's tolerance and the first check of the
    # solve meets it (1 product). Without recycling, which would repair any start on this face.
    plain = block_history(args, work, 'scaled', 'both', True, recycle=False)
    hs = [r['hessian_multiplications'] for r in plain]
    print('Hessian products per step, warm without recycling: %s' % hs)
    assert hs[1] <= 1, 'the scaled start of step 2 is not its solution: %s' % hs
    print('savings: warm %d products after the first step against cold %d; faces reused %d' % (
        sum(hw[1:]), sum(hc[1:]), sum(reused)))
    # with G G^T factorized by MUMPS with the contact-face subdomains as Schur rows (216 subdomains,
    # 36 under contact), the standard reconstruction's G_A G_A^T is a view of its own, so the
    # default method = 'both' keeps the last face for the next step too
    both = block_history(args, work, 'schur', 'both', True, nsub=6, nel=2)
    for rec in both:
        assert rec['converged'] and rec['kkt_passed'], rec
    reused_both = [r['faces_reused'] for r in both]
    print('faces reused per step (method both, Schur rows): %s' % reused_both)
    assert all(n >= 1 for n in reused_both[1:]), reused_both


def strip_times(records):
    out = []
    for r in records:
        r = dict(r)
        r.pop('seconds', None)
        out.append(r)
    return out


def check_restart(args):
    work = fresh(os.path.join(args.workdir, 'restart_np%d' % args.ranks))
    full_out = os.path.join(work, 'full')
    part_out = os.path.join(work, 'part')
    hist = "&history nsteps = 5, path = 'load_unload', recycle = .true.%s /\n"
    nml = os.path.join(work, 'full.nml')
    write_input(nml, TOP_UZ, 0.0, full_out, hist % '')
    run(args, nml)
    # stopped after step 1 by the time limit (any step takes longer than 1e-9 s), restarted
    # twice (after step 2, then to the end)
    nml1 = os.path.join(work, 'part1.nml')
    write_input(nml1, TOP_UZ, 0.0, part_out, hist % ', time_limit = 1e-9')
    p = run(args, nml1)
    assert 'stopped after step 1 of 5' in p.stdout, p.stdout[-2000:]
    p = run(args, _restart_input(work, part_out, hist, '1e-9'))
    assert 'restart after step 1 of 5' in p.stdout and 'stopped after step 2 of 5' in p.stdout, p.stdout[-2000:]
    p = run(args, _restart_input(work, part_out, hist, '0'))
    assert 'restart after step 2 of 5' in p.stdout, p.stdout[-2000:]
    full = json.load(open(os.path.join(full_out, 'report.json')))
    part = json.load(open(os.path.join(part_out, 'report.json')))
    a, b = strip_times(full['history']), strip_times(part['history'])
    assert len(a) == len(b) == 5, (len(a), len(b))
    for ra, rb in zip(a, b):
        # warm_start and everything else: the restarted steps start from the checkpoint
        assert ra == rb, 'record differs:\n%s\n%s' % (ra, rb)
    for k in range(1, 6):
        fa = read_h5(os.path.join(full_out, 'run_step%04d.h5' % k))
        fb = read_h5(os.path.join(part_out, 'run_step%04d.h5' % k))
        assert fa.keys() == fb.keys()
        for key in fa:
            assert np.array_equal(fa[key], fb[key]), 'step %d dataset %s differs' % (k, key)
    print('restart on %d ranks: 5 records and every dataset of 5 steps bit-identical' % args.ranks)


def _restart_input(work, out, hist, limit):
    path = os.path.join(work, 'restart_%s.nml' % limit.replace('-', 'm'))
    extra = ', restart = .true.'
    if limit != '0':
        extra += ', time_limit = %s' % limit
    write_input(path, TOP_UZ, 0.0, out, hist % extra)
    return path


def expect_error(args, nml, pattern):
    p = run(args, nml, expect=2)
    text = p.stdout + p.stderr
    assert re.search(pattern, text), 'no message matching %r in:\n%s' % (pattern, text[-2000:])


def check_bad(args):
    work = fresh(os.path.join(args.workdir, 'bad'))
    out = os.path.join(work, 'out')
    cases = [
        ('&history nsteps = 0 /', r'group &history, variable nsteps: must be in \[1, 1000\]'),
        ("&history nsteps = 3, path = 'zigzag' /",
         r"group &history, variable path: must be 'ramp', 'load_unload' or 'list'"),
        ("&history nsteps = 3, path = 'list', load_factors = 0.5, 1.0 /",
         r"group &history, variable load_factors: needs nsteps values"),
        ("&history nsteps = 2, load_factors = 0.5, 1.0 /",
         r"group &history, variable load_factors: is for path = 'list' only"),
        ("&history nsteps = 2, path = 'list', load_factors = 0.5, -1.0 /",
         r"group &history, variable load_factors: each factor must be >= 0"),
        ("&history nsteps = 3, gaps = 0.0, 0.1 /", r"group &history, variable gaps: needs exactly nsteps values"),
        ("&history nsteps = 2, gaps = 0.0, -0.5 /", r"group &history, variable gaps: the obstacle must not be deeper"),
        ('&history nsteps = 2, factor_peak = 0 /', r'group &history, variable factor_peak: must be > 0'),
        ('&history nsteps = 2, time_limit = -1 /', r'group &history, variable time_limit: must be >= 0'),
        ('&history nsteps = 2, warm_start = .false., recycle = .true. /',
         r'group &history, variable recycle: needs warm_start = .true.'),
        ('&history nsteps = 2, speed = 1 /', r'group &history: variable speed: not a variable of this group'),
    ]
    for k, (group, pattern) in enumerate(cases):
        nml = os.path.join(work, 'bad%d.nml' % k)
        write_input(nml, TOP_UZ, 0.0, out, group + '\n')
        expect_error(args, nml, pattern)
    # restart without a checkpoint
    nml = os.path.join(work, 'nockpt.nml')
    write_input(nml, TOP_UZ, 0.0, os.path.join(work, 'empty'), "&history nsteps = 2, restart = .true. /\n")
    expect_error(args, nml, r'&history restart: checkpoint .*does not exist')
    # a checkpoint of another input (another top displacement) is foreign
    nml = os.path.join(work, 'first.nml')
    write_input(nml, TOP_UZ, 0.0, out, "&history nsteps = 3, time_limit = 1e-9 /\n")
    run(args, nml)
    nml = os.path.join(work, 'foreign.nml')
    write_input(nml, TOP_UZ / 2, 0.0, out, "&history nsteps = 3, restart = .true. /\n")
    expect_error(args, nml, r'&history restart: checkpoint .*belongs to another input or mesh')
    # a damaged checkpoint (not a checkpoint at all)
    with open(os.path.join(out, 'run.checkpoint.0'), 'wb') as f:
        f.write(b'garbage')
    nml = os.path.join(work, 'damaged.nml')
    write_input(nml, TOP_UZ, 0.0, out, "&history nsteps = 3, restart = .true. /\n")
    expect_error(args, nml, r'&history restart: checkpoint .*is not a feticontact history checkpoint')
    print('bad: %d input errors and 3 checkpoint errors refused with exit 2' % len(cases))


def check_signal(args):
    import signal
    import time
    work = fresh(os.path.join(args.workdir, 'signal'))
    out = os.path.join(work, 'out')
    nml = os.path.join(work, 'h.nml')
    hist = "&history nsteps = 200, path = 'ramp'%s /\n"
    write_input(nml, TOP_UZ, 0.0, out, hist % '')
    log = os.path.join(work, 'log.txt')
    with open(log, 'w') as f:
        p = subprocess.Popen([args.mpiexec, '-n', str(args.ranks), args.program, nml], stdout=f,
                             stderr=subprocess.STDOUT)
        t0 = time.time()
        while time.time() - t0 < 600:
            time.sleep(0.5)
            if re.search(r'^step 2/200', open(log).read(), re.M) or p.poll() is not None:
                break
        p.send_signal(signal.SIGUSR1)
        rc = p.wait(timeout=600)
    text = open(log).read()
    m = re.search(r'stopped after step (\d+) of 200 \(stop signal\)', text)
    assert rc == 0 and m, 'exit %d, log:\n%s' % (rc, text[-3000:])
    k = int(m.group(1))
    assert k < 200, k
    nml2 = os.path.join(work, 'restart.nml')
    write_input(nml2, TOP_UZ, 0.0, out, hist % ', restart = .true.')
    r = run(args, nml2)
    assert 'restart after step %d of 200' % k in r.stdout, r.stdout[-2000:]
    rep = json.load(open(os.path.join(out, 'report.json')))
    assert [s['step'] for s in rep['history']] == list(range(1, 201))
    print('signal: stopped after step %d of 200, restarted and finished' % k)


PV_SCRIPT = r"""
import sys
from paraview.simple import XDMFReader, UpdatePipeline, servermanager
xdmf, nsteps, peak = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
r = XDMFReader(FileNames=[xdmf])     # every grid enabled (the reader's default)
times = list(r.TimestepValues)
assert len(times) == nsteps, times
maxima, pressure = [], []
for t in times:
    UpdatePipeline(time=t, proxy=r)
    data = servermanager.Fetch(r)
    blocks = {data.GetMetaData(i).Get(data.NAME()): data.GetBlock(i) for i in range(data.GetNumberOfBlocks())}
    # the same named blocks at every step (README: the block "contact" holds the pressure)
    assert sorted(blocks) == ['contact', 'mesh'], 'time %g: blocks %s' % (t, sorted(blocks))
    assert blocks['contact'] is not None and blocks['contact'].GetNumberOfPoints() > 0, 'time %g: contact empty' % t
    u = blocks['mesh'].GetPointData().GetArray('displacement')
    maxima.append(max(abs(u.GetRange(2)[0]), abs(u.GetRange(2)[1])))
    pressure.append(blocks['contact'].GetPointData().GetArray('contact_pressure').GetRange()[1])
print('times', times)
print('max |u_z|', maxima)
print('max contact pressure', pressure)
assert pressure[peak - 1] > 0, 'the peak step shows no contact pressure'
assert pressure[peak - 1] == max(pressure), 'the peak step has the largest pressure'
assert pressure[-1] == 0 and maxima[-1] == 0, 'the unloaded last step shows a zero field'
"""


def check_paraview(args):
    pv = shutil.which('pvpython')
    xvfb = shutil.which('xvfb-run')
    if pv is None:
        print('pvpython not found (Debian: python3-paraview): skipped')
        return SKIP
    work = fresh(os.path.join(args.workdir, 'paraview'))
    out = os.path.join(work, 'out')
    nml = os.path.join(work, 'h.nml')
    # loading and unloading to 0: the peak (report.json `step`) in the middle, zero force at the end
    write_input(nml, TOP_UZ, 0.0, out, "&history nsteps = 4, path = 'load_unload' /\n")
    run(args, nml)
    peak = json.load(open(os.path.join(out, 'report.json')))['step']
    assert peak == 2, 'report.json step %r, expected the peak 2' % peak
    script = os.path.join(work, 'steps.py')
    with open(script, 'w') as f:
        f.write(PV_SCRIPT)
    cmd = ([xvfb, '-a'] if xvfb else []) + [pv, script, os.path.join(out, 'run.xdmf'), '4', str(peak)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    sys.stdout.write(p.stdout)
    if p.returncode != 0:
        sys.stderr.write(p.stderr[-4000:])
        raise SystemExit('pvpython failed on the temporal XDMF')
    return 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--program', required=True)
    ap.add_argument('--mpiexec', default='mpirun')
    ap.add_argument('--ranks', type=int, default=2)
    ap.add_argument('--workdir', required=True)
    ap.add_argument('--mesh', default=None, help="the &mesh variables (default: %s)" % MESH)
    ap.add_argument('check', choices=['steps', 'pressure', 'restart', 'bad', 'signal', 'paraview', 'savings'])
    args = ap.parse_args()
    if args.mesh:
        globals()['MESH'] = args.mesh
    os.makedirs(args.workdir, exist_ok=True)
    status = {'steps': check_steps, 'pressure': check_pressure_steps, 'restart': check_restart, 'bad': check_bad,
              'signal': check_signal, 'paraview': check_paraview, 'savings': check_savings}[args.check](args)
    return status or 0


if __name__ == '__main__':
    sys.exit(main())
