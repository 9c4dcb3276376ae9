#!/usr/bin/python3
"""Fit the constants of the automatic choice of clusters (src/input/params.f90
`auto_cluster`, docs/THEORY.md "Automatic choice of clusters") to measured
runs, and print the model against the measurements.

Each argument is a report.json (or a folder holding one, searched
recursively) of a run of the cube family with plain TFETI or with face-glued
clusters, on the machine the constants are for. Runs of the same case
(subdomains, elements per subdomain, cluster) are reduced to their median
total. The model of a run of N subdomains of n = 3 prod(nel + 1) dofs in
N_u units (subdomains or clusters) of n_u = n N / N_u dofs, H/h = the
elements along a unit's longest edge:

    k     = c_k (H/h)^e                      Hessian products
    T     = N n k (v + a n_u^(1/3)) + k b (6 N_u)^p + cf (6 N_u)^2

c_k and e by a least-squares line through log(products) against log(H/h);
p (1.2 .. 2 in steps of 0.05) as the one whose fit has the least error;
cf from the G G^T factorization times over (6 N_u)^2 (median over the runs
of at least 24576 coarse rows); v, a and b by non-negative least squares on the
relative error of T, cf fixed.

  /usr/bin/python3 tools/cluster_model_fit.py DIR1 DIR2 ...

Standard library and numpy only.
"""
import json
import os
import statistics
import sys

import numpy as np


def reports(paths):
    for p in paths:
        if os.path.isdir(p):
            for root, _, files in os.walk(p):
                if 'report.json' in files:
                    yield os.path.join(root, 'report.json')
        else:
            yield p


def case_of(r):
    mesh = r['case']['mesh']
    nsub = mesh['nsub']
    nel = mesh['nel']
    t = mesh['cluster'] if mesh.get('cluster') else [1, 1, 1]
    return (int(np.prod(nsub)), tuple(nel), tuple(t))


def coarse_factorization(r):
    """The G G^T factorization time [s] of the set-up (max over ranks)."""
    for phase in r['timings']['total']['children']:
        if phase['name'] == 'coarse setup':
            for part in phase.get('children', []):
                if part['name'] == 'coarse: factorization':
                    return part['max']
    return 0.0


def main():
    if len(sys.argv) < 2 or sys.argv[1] in ('-h', '--help'):
        print(__doc__)
        return 0 if len(sys.argv) >= 2 else 2
    runs = {}
    for path in reports(sys.argv[1:]):
        r = json.load(open(path))
        if r['case']['mesh'].get('cluster_gluing', 'faces') != 'faces' and max(case_of(r)[2]) > 1:
            continue
        runs.setdefault(case_of(r), []).append(r)
    if len(runs) < 3:
        sys.exit('cluster_model_fit: need runs of at least 3 different cases')
    cases = sorted(runs)
    total = {c: statistics.median(r['timings']['total']['max'] for r in runs[c]) for c in cases}
    products = {c: statistics.median(r['solver']['hessian_multiplications'] for r in runs[c]) for c in cases}

    def sizes(c):
        nsub, nel, t = c
        n = 3 * np.prod([e + 1 for e in nel])
        units = nsub / np.prod(t)
        hh = max(e * k for e, k in zip(nel, t))
        return nsub, n, units, n * nsub / units, hh

    hh = np.array([sizes(c)[4] for c in cases], float)
    e, logc = np.polyfit(np.log(hh), np.log([products[c] for c in cases]), 1)
    ck = np.exp(logc)
    plain = [c for c in cases if max(c[2]) == 1]
    # G G^T's factorization over (6 N_u)^2, median over the runs of at least 24576 coarse rows
    # (the N^2 regime of nested dissection; below, fixed costs dominate)
    big = [statistics.median(coarse_factorization(r) for r in runs[c]) / (6.0 * sizes(c)[2]) ** 2
           for c in cases if 6 * sizes(c)[2] >= 24576]
    cf = statistics.median(big) if big else 0.0
    def fit(p):
        """v, a, b for the coarse solve exponent p, the kept terms and the squared relative error"""
        rows, rhs = [], []
        for c in cases:
            nsub, n, units, nu, h = sizes(c)
            k = ck * h ** e
            rows.append(np.array([nsub * n * k, nsub * n * k * nu ** (1 / 3), k * (6 * units) ** p]) / total[c])
            rhs.append(1 - cf * (6 * units) ** 2 / total[c])
        rows, rhs = np.array(rows), np.array(rhs)
        keep = [0, 1, 2]
        while True:  # non-negative least squares for 3 unknowns: drop a negative term, refit
            sol, *_ = np.linalg.lstsq(rows[:, keep], rhs, rcond=None)
            if min(sol) >= 0 or len(keep) == 1:
                break
            keep.pop(int(np.argmin(sol)))
        const = np.array([float(sol[keep.index(i)]) if i in keep else 0.0 for i in range(3)])
        return const, keep, rows, float(np.sum((rows @ const - rhs) ** 2))

    # the coarse solve's exponent p by a grid (nested dissection in 3D: 4/3 for the factor's
    # entries; the polish's face solves and the Schur rows of the contact zone grow faster)
    p = min(np.arange(1.2, 2.001, 0.05), key=lambda q: fit(q)[3])
    (v, a, b), keep, rows, _ = fit(p)
    print(f'products k = {ck:.3g} (H/h)^{e:.3g};  v = {v:.3g}, a = {a:.3g}, b = {b:.3g}, p = {p:.2f}, cf = {cf:.3g}')
    print(f"{'subdomains':>10} {'nel':>7} {'cluster':>7} {'runs':>4} {'products':>8} {'model k':>7} "
          f"{'total [s]':>9} {'model [s]':>9} {'model/meas':>10}")
    for c, row in zip(cases, rows):
        nsub, n, units, nu, h = sizes(c)
        model = (row @ np.array([v, a, b])) * total[c] + cf * (6 * units) ** 2
        print(f"{nsub:>10} {'x'.join(map(str, c[1])):>7} {'x'.join(map(str, c[2])):>7} {len(runs[c]):>4} "
              f"{products[c]:>8.0f} {ck * h ** e:>7.1f} {total[c]:>9.3f} {model:>9.3f} {model / total[c]:>10.2f}")
    if len(keep) < 3:
        print('cluster_model_fit: a term came out negative and was set to 0: add runs that separate the terms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
