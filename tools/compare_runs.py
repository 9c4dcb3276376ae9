#!/usr/bin/python3
"""Run two feticontact binaries on the same inputs and compare the results exactly.

    tools/compare_runs.py BIN_A BIN_B INPUT.nml [INPUT.nml ...] [--ranks 2] [--work DIR]
                          [--renamed /case/GROUP/OLD=/case/GROUP/NEW ...] [--keep-a] [--only-a]

Each input is run by both binaries (`mpirun --bind-to none -n RANKS`) into its
own output directory (the `&output directory` of the input is replaced). Then
- report.json: every number, string and logical outside the timing, memory
  and machine sections (`timings`, `memory`, `blas`, `performance`, keys with
  `seconds`, `bandwidth`, `time`, the reconstruction's phase times) must be
  equal (counts, KKT residuals, histories, ...); settings that only binary B
  echoes (new options) are left out, a setting B renamed (--renamed) is
  compared under its new name;
- every HDF5 dataset of the run must be bit-identical (numpy.array_equal on
  the raw arrays, NaN included); a floating-point dataset that differs is
  listed with its largest difference relative to its largest entry.
Prints one line per input and exits 1 if any differs.
--keep-a reuses the runs of BIN_A already in the work folder (a baseline run
once, e.g. by --only-a, which runs BIN_A alone and compares nothing).
"""
import argparse
import json
import os
import re
import subprocess
import sys

import h5py
import numpy as np

SKIP_TOP = {'timings', 'memory', 'blas', 'timing', 'performance'}
# times that are not under a key with 'seconds' in its name
SKIP_PATH = re.compile(r'^/reconstruction/(new|standard)/(assembly|factorization|solve)$')
SKIP_KEY = re.compile(r'seconds|bandwidth|time|version|commit|date|host|directory|file', re.I)


def group_span(text, name):
    """(start, end) of the body of group &name (end at its unquoted '/'), or None."""
    m = re.search(r'&%s\b' % name, text, re.I)
    if m is None:
        return None
    quote = None
    for i in range(m.end(), len(text)):
        c = text[i]
        if quote:
            if c == quote:
                quote = None
        elif c in '\'"':
            quote = c
        elif c == '/':
            return m.end(), i
    return None


def with_directory(text, directory):
    """The input text with its &output directory replaced (or an &output group added)."""
    entry = "directory = '%s'" % directory
    span = group_span(text, 'output')
    if span is None:
        return text + "\n&output %s /\n" % entry
    body = text[span[0]:span[1]]
    if re.search(r'\bdirectory\s*=', body, re.I):
        body = re.sub(r"\bdirectory\s*=\s*('[^']*'|\"[^\"]*\")", entry, body, flags=re.I)
    else:
        body = ' ' + entry + ',' + body
    return text[:span[0]] + body + text[span[1]:]


def run(binary, nml, outdir, ranks, keep=False):
    done = os.path.join(outdir, 'exit_code.txt')
    if keep and os.path.exists(done):
        with open(done) as f:
            return int(f.read())
    os.makedirs(outdir, exist_ok=True)
    with open(nml) as f:
        text = f.read()
    case = os.path.join(outdir, 'input.nml')
    with open(case, 'w') as f:
        f.write(with_directory(text, outdir))
    cmd = ['mpirun', '--bind-to', 'none', '-n', str(ranks), binary, case]
    with open(os.path.join(outdir, 'log.txt'), 'w') as log:
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT)
    with open(done, 'w') as f:
        f.write('%d\n' % rc)
    return rc


def flatten(obj, prefix=''):
    if isinstance(obj, dict):
        for k, v in obj.items():
            if not prefix and k in SKIP_TOP:
                continue
            if SKIP_KEY.search(k):
                continue
            yield from flatten(v, prefix + '/' + k)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from flatten(v, '%s[%d]' % (prefix, i))
    elif not SKIP_PATH.match(prefix):
        yield prefix, obj


def compare_reports(a, b, renamed=()):
    """Differences between two report.json; `renamed`: (key in A, key in B) pairs of a
    setting that binary B spells differently (compared under B's key)."""
    diffs = []
    fa = dict(flatten(json.load(open(a))))
    fb = dict(flatten(json.load(open(b))))
    for old, new in renamed:
        if old in fa:
            fa[new] = fa.pop(old)
    for k in sorted(set(fa) | set(fb)):
        if k.startswith('/case/') and k not in fa:
            continue    # a setting that binary A does not have (a new option, echoed with its default)
        va, vb = fa.get(k, '<missing>'), fb.get(k, '<missing>')
        if k == '/solver/variant' and isinstance(va, str) and isinstance(vb, str):
            va, vb = sorted(va.split(', ')), sorted(vb.split(', '))   # the order of the settings may differ
        if va != vb and not (isinstance(va, float) and isinstance(vb, float) and va != va and vb != vb):
            diffs.append('%s: %r != %r' % (k, va, vb))
    return diffs, fa


def datasets(path):
    found = {}
    with h5py.File(path, 'r') as f:
        f.visititems(lambda name, obj: found.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return found


def compare_hdf5(dir_a, dir_b):
    diffs = []
    files = sorted(f for f in os.listdir(dir_a) if f.endswith('.h5'))
    if sorted(f for f in os.listdir(dir_b) if f.endswith('.h5')) != files:
        return ['different HDF5 files'], 0
    n = 0
    for name in files:
        da, db = datasets(os.path.join(dir_a, name)), datasets(os.path.join(dir_b, name))
        if set(da) != set(db):
            diffs.append('%s: different datasets' % name)
            continue
        for k in da:
            n += 1
            a, b = np.asarray(da[k]), np.asarray(db[k])
            if not np.array_equal(a, b, equal_nan=a.dtype.kind == 'f'):
                if a.dtype.kind == 'f' and a.shape == b.shape and a.size and np.max(np.abs(a)) > 0:
                    diffs.append('%s:%s differs (max |a - b| / max |a| = %.2e)'
                                 % (name, k, np.max(np.abs(a - b)) / np.max(np.abs(a))))
                else:
                    diffs.append('%s:%s differs' % (name, k))
    return diffs, n


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('bin_a')
    ap.add_argument('bin_b')
    ap.add_argument('inputs', nargs='+')
    ap.add_argument('--ranks', type=int, default=2)
    ap.add_argument('--work', default='compare_runs', help='folder for the runs (default: ./compare_runs)')
    ap.add_argument('--renamed', action='append', default=[], metavar='OLD=NEW',
                    help='a report.json key that binary B renamed, e.g. /case/solver/power_iterations='
                         '/case/solver/lanczos_steps (repeatable)')
    ap.add_argument('--keep-a', action='store_true', help='reuse the runs of BIN_A already in --work')
    ap.add_argument('--only-a', action='store_true', help='run BIN_A alone (a baseline for --keep-a)')
    args = ap.parse_args()
    bad = 0
    for nml in args.inputs:
        name = os.path.splitext(os.path.basename(nml))[0]
        sub = os.path.basename(os.path.dirname(os.path.abspath(nml)))
        dirs = [os.path.join(args.work, sub + '_' + name, tag) for tag in ('a', 'b')]
        if args.only_a:
            rc = run(os.path.abspath(args.bin_a), nml, dirs[0], args.ranks, args.keep_a)
            print('%-40s baseline run (exit %d)' % (sub + '/' + name, rc))
            sys.stdout.flush()
            continue
        rcs = [run(os.path.abspath(args.bin_a), nml, dirs[0], args.ranks, args.keep_a),
               run(os.path.abspath(args.bin_b), nml, dirs[1], args.ranks)]
        diffs = []
        if rcs[0] != rcs[1]:
            diffs.append('exit codes %d != %d' % tuple(rcs))
        rep = [os.path.join(d, 'report.json') for d in dirs]
        info = ''
        if all(os.path.exists(r) for r in rep):
            d, flat = compare_reports(*rep, renamed=[tuple(r.split('=', 1)) for r in args.renamed])
            diffs += d
            info = 'hessian %s outer %s' % (flat.get('/solver/hessian_multiplications'),
                                             flat.get('/solver/outer_iterations'))
        else:
            diffs.append('report.json missing')
        hd, n = compare_hdf5(*dirs)
        diffs += hd
        status = 'IDENTICAL' if not diffs else 'DIFFERENT'
        print('%-40s %s (exit %d, %s, %d HDF5 datasets)' % (sub + '/' + name, status, rcs[0], info, n))
        for line in diffs[:20]:
            print('    ' + line)
        bad += bool(diffs)
        sys.stdout.flush()
    sys.exit(1 if bad else 0)


if __name__ == '__main__':
    main()
