#!/usr/bin/python3
"""Weak-scaling figures of the coarse problem: runs cube_h4 at 512 and 4096
subdomains (and the 4096 mesh without an obstacle and with a sphere of radius
50), each --reps times, interleaved, and prints the medians of the report.json
timings, the ratios that docs/RESULTS.md "Coarse problem at scale" quotes,
and a table of the two reconstructions beside the solve's face work:

- total per subdomain at 4096 against 512;
- contact against the no-obstacle run on the same mesh (R = 1 and R = 50);
- the coarse work's share of the total at 4096: every timer whose name starts
  with 'coarse' or 'face:' wherever it ran (G G^T's set-up, the coarse solves
  of every phase, the polish's face matrices and face solves, the standard
  reconstruction's coarse assembly and factorization), not counting a timer
  inside another one already counted.

The cube_h4 runs take the default settings (the automatic choice of
clusters). Optional cases: --with-32768 (cube_h4_n32768, about 40 s and
4 GB per rank, run once), --with-110592 (the H/h = 3 pair: cube_h3_n4096
--reps times and cube_h3_n110592 once, about 9 GB per rank), --with-h2 (the
hybrid H/h = 2 pair at 4096 and 32768) and --clusters (cube_h4 at 512 and
4096 subdomains in plain TFETI and in clusters of 2^3 glued by their faces
and by their corners, and with --with-32768 the same at 32768, once each:
the Hessian products, phases and peak memory side by side).

  tools/coarse_targets.py --program build-release/bin/feticontact --reps 3 --dir D

Standard library only (run with /usr/bin/python3). Each run's log and
output stay in DIR/<case>_<rep>/.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WEAK = os.path.join(ROOT, 'inputs', 'weak')


def variant(src, dst, obstacle, mesh=None):
    """Copy of the input `src` with its &obstacle line replaced (None: as is)
    and `mesh` (variables) added to its &mesh group."""
    text = open(src).read()
    if mesh is not None:
        text, n = re.subn(r'^(&mesh[^\n]*?)\s*/\s*$', r'\1, ' + mesh + ' /', text, flags=re.M)
        if n != 1:
            sys.exit(f'coarse_targets: no single &mesh line in {src}')
    if obstacle is not None:
        text, n = re.subn(r'^&obstacle[^\n]*/\s*$', obstacle, text, flags=re.M)
        if n != 1:
            sys.exit(f'coarse_targets: no single &obstacle line in {src}')
    text = re.sub(r"directory\s*=\s*'[^']*'", "directory = 'output'", text)
    with open(dst, 'w') as f:
        f.write(text)


def cases(args):
    """(name, input, &obstacle line or None, subdomains, &mesh variables or None); the names in ONCE run
    in the first repetition only"""
    c = [('h4_n512', 'cube_h4_n512.nml', None, 512, None),
         ('h4_n4096', 'cube_h4_n4096.nml', None, 4096, None)]
    if not args.clusters_only:
        c += [('h4_n4096_free', 'cube_h4_n4096.nml', "&obstacle shape = 'none' /", 4096, None),
              ('h4_n4096_r50', 'cube_h4_n4096.nml',
               "&obstacle shape = 'sphere', radius = 50.0, gap = 0.0 /", 4096, None)]
    if args.with_32768:
        c.append(('h4_n32768', 'cube_h4_n32768.nml', None, 32768, None))
    if args.with_110592:
        c += [('h3_n4096', 'cube_h3_n4096.nml', None, 4096, None),
              ('h3_n110592', 'cube_h3_n110592.nml', None, 110592, None)]
    if args.with_h2:
        c += [('h2_n4096', 'cube_h2_n4096_hybrid.nml', None, 4096, None),
              ('h2_n32768', 'cube_h2_n32768_hybrid.nml', None, 32768, None)]
    if args.clusters or args.clusters_only:
        faces = "cluster = 2, 2, 2, cluster_gluing = 'faces'"
        corners = "cluster = 2, 2, 2, cluster_gluing = 'corners'"
        c += [('h4_n512_plain', 'cube_h4_n512.nml', None, 512, 'cluster = 1, 1, 1'),
              ('h4_n4096_plain', 'cube_h4_n4096.nml', None, 4096, 'cluster = 1, 1, 1'),
('h4_n512_faces', 'cube_h4_n512.nml', None, 512, faces),
              ('h4_n4096_faces', 'cube_h4_n4096.nml', None, 4096, faces),
              ('h4_n512_corners', 'cube_h4_n512.nml', None, 512, corners),
              ('h4_n4096_corners', 'cube_h4_n4096.nml', None, 4096, corners)]
        if args.with_32768:
            c += [('h4_n32768_faces', 'cube_h4_n32768.nml', None, 32768, faces),
                  ('h4_n32768_plain', 'cube_h4_n32768.nml', None, 32768, 'cluster = 1, 1, 1'),
                  ('h4_n32768_corners', 'cube_h4_n32768.nml', None, 32768, corners)]
    return c


ONCE = ('h4_n32768', 'h4_n32768_faces', 'h4_n32768_plain', 'h4_n32768_corners', 'h3_n110592', 'h2_n32768')


def coarse_work(node):
    """Sum of the maxima of the timers named coarse* or face:* (outermost only)."""
    total = 0.0
    for child in node.get('children', []):
        name = child['name']
        if name.startswith('coarse') or name.startswith('face:'):
            total += child['max']
        else:
            total += coarse_work(child)
    return total


def run_case(args, name, nml, rep):
    folder = os.path.join(args.dir, f'{name}_{rep}')
    os.makedirs(folder, exist_ok=True)
    cmd = ['mpirun', '--bind-to', 'none', '-n', str(args.ranks), args.program, nml]
    t0 = time.time()
    with open(os.path.join(folder, 'log.txt'), 'w') as log:
        status = subprocess.call(cmd, cwd=folder, stdout=log, stderr=subprocess.STDOUT)
    wall = time.time() - t0
    rec = {'case': name, 'rep': rep, 'status': status, 'wall': wall}
    path = os.path.join(folder, 'output', 'report.json')
    if status == 0 and os.path.exists(path):
        r = json.load(open(path))
        t = r['timings']
        rec['total'] = t['total']['max']
        rec['coarse'] = coarse_work(t['total'])
        for key in ('coarse setup', 'solve', 'polish', 'face: solves', 'face: matrices', 'rec new',
                    'rec standard', 'assembly', 'B and G', 'dual setup'):
            if key in t:
                rec[key] = t[key]['max']
        rec['products'] = r['solver']['hessian_multiplications']
        rec['peak_gb'] = r['memory']['peak_rss_bytes']['max'] / 1e9
    return rec


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--program', required=True)
    ap.add_argument('--ranks', type=int, default=2)
    ap.add_argument('--reps', type=int, default=3)
    ap.add_argument('--dir', default='coarse_targets')
    ap.add_argument('--with-32768', action='store_true')
    ap.add_argument('--with-110592', action='store_true')
    ap.add_argument('--with-h2', action='store_true')
    ap.add_argument('--clusters', action='store_true', help='also the clusters of 2^3 (faces and corners)')
    ap.add_argument('--clusters-only', action='store_true',
                    help='the plain and cluster runs at 512 and 4096 only (no obstacle variants)')
    args = ap.parse_args()
    args.program = os.path.abspath(args.program)
    os.makedirs(args.dir, exist_ok=True)
    args.dir = os.path.abspath(args.dir)
    env = os.environ
    if os.getuid() == 0:
        env.setdefault('OMPI_ALLOW_RUN_AS_ROOT', '1')
        env.setdefault('OMPI_ALLOW_RUN_AS_ROOT_CONFIRM', '1')
    env.setdefault('OMPI_MCA_rmaps_base_oversubscribe', '1')
    todo = []
    for name, src, obstacle, nsub, mesh in cases(args):
        nml = os.path.join(args.dir, name + '.nml')
        variant(os.path.join(WEAK, src), nml, obstacle, mesh)
        todo.append((name, nml, nsub))
    records = []
    for rep in range(1, args.reps + 1):
        for name, nml, _ in todo:
            if rep > 1 and name in ONCE:
                continue
            rec = run_case(args, name, nml, rep)
            print(json.dumps(rec), flush=True)
            records.append(rec)
    med = {}
    nsubs = {name: nsub for name, _, nsub in todo}
    print('\n| case | runs | total [s] | coarse work [s] | coarse share | polish | face: solves | products '
          '| peak [GB/rank] |')
    print('|---|---:|---:|---:|---:|---:|---:|---:|---:|')
    for name, _, _ in todo:
        ok = [r for r in records if r['case'] == name and 'total' in r]
        if not ok:
            print(f'| {name} | 0 (failed) | | | | | | |')
            continue
        m = {k: statistics.median(r.get(k, 0.0) for r in ok)
             for k in ('total', 'coarse', 'polish', 'face: solves', 'products', 'peak_gb')}
        med[name] = m
        print(f"| {name} | {len(ok)} | {m['total']:.3f} | {m['coarse']:.3f} | {m['coarse'] / m['total']:.0%} "
              f"| {m['polish']:.3f} | {m['face: solves']:.3f} | {m['products']:.0f} | {m['peak_gb']:.2f} |")

    # the reconstruction with what the solve spent on face matrices beside it: the standard formula's
    # G_A G_A^T is a face matrix too, which the polish's faces already paid for
    print('\n| case | rec new [s] | rec standard [s] | face: matrices in the solve [s] '
          '| face: solves in the solve [s] |')
    print('|---|---:|---:|---:|---:|')
    for name, _, _ in todo:
        ok = [r for r in records if r['case'] == name and 'total' in r]
        if ok:
            m = {k: statistics.median(r.get(k, 0.0) for r in ok)
                 for k in ('rec new', 'rec standard', 'face: matrices', 'face: solves')}
            print(f"| {name} | {m['rec new']:.4f} | {m['rec standard']:.4f} | {m['face: matrices']:.4f} "
                  f"| {m['face: solves']:.4f} |")

    def per_sub(a, b):
        return (med[a]['total'] / nsubs[a]) / (med[b]['total'] / nsubs[b])
    print()
    if 'h4_n512' in med and 'h4_n4096' in med:
        print(f"default settings: total per subdomain, 4096 / 512: {per_sub('h4_n4096', 'h4_n512'):.2f}x "
              f"(target <= 1.2x)")
    if 'h4_n4096_free' in med:
        for c, target in (('h4_n4096', 1.2), ('h4_n4096_r50', 1.3)):
            if c in med:
                print(f"{c} / no obstacle: {med[c]['total'] / med['h4_n4096_free']['total']:.2f}x "
                      f"(target <= {target}x)")
    if 'h4_n4096' in med:
        print(f"coarse work at 4096: {med['h4_n4096']['coarse'] / med['h4_n4096']['total']:.0%} of the total "
              f"(target <= 20%)")
    if 'h4_n32768' in med and 'h4_n4096' in med:
        print(f"default settings: total per subdomain, 32768 / 4096: {per_sub('h4_n32768', 'h4_n4096'):.2f}x "
              f"(target <= 1.3x); coarse work at 32768: "
              f"{med['h4_n32768']['coarse'] / med['h4_n32768']['total']:.0%} (target <= 20%)")
    if 'h3_n110592' in med and 'h3_n4096' in med:
        print(f"default settings, H/h = 3: total per subdomain, 110592 / 4096: "
              f"{per_sub('h3_n110592', 'h3_n4096'):.2f}x (target <= 1.5x)")
    defaults = [n for n in med if n.startswith('h4_n') and n.count('_') == 1]
    if defaults:
        print(f"default settings, cube_h4: most Hessian products {max(med[n]['products'] for n in defaults):.0f} "
              f"(target <= 22)")
    for g in ('faces', 'corners'):
        if f'h4_n512_{g}' in med and f'h4_n4096_{g}' in med:
            print(f"clusters ({g}): total per subdomain, 4096 / 512: "
                  f"{per_sub(f'h4_n4096_{g}', f'h4_n512_{g}'):.2f}x; against plain at 4096: "
                  f"{med[f'h4_n4096_{g}']['total'] / med['h4_n4096_plain']['total']:.2f}x")
    if 'h4_n32768_faces' in med and 'h4_n4096_faces' in med:
        print(f"clusters (faces): total per subdomain, 32768 / 4096: "
              f"{per_sub('h4_n32768_faces', 'h4_n4096_faces'):.2f}x (target <= 1.3x)")
    if 'h2_n32768' in med and 'h2_n4096' in med:
        print(f"H/h = 2, total per subdomain, 32768 / 4096: {per_sub('h2_n32768', 'h2_n4096'):.2f}x "
              f"(target <= 1.1x)")
    failed = [r for r in records if r['status'] != 0]
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
