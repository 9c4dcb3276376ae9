#!/usr/bin/python3
"""The memory estimate of a run (`memory estimate: about M MB per rank` in the
log, the one `--check` prints) against the peak the run measures
(report.json `memory.peak_rss_bytes.max`, the largest VmHWM over the ranks).

    tools/memory_estimate.py INPUT.nml [INPUT.nml ...] [--program BIN] [--ranks 2]
                             [--mpiexec mpirun] [--work DIR] [--within 0.25]

Each input runs once into its own folder under --work (its `&output
directory` replaced, HDF5 off: the fields' writing is not what the estimate
models). Prints per input the estimate, the measured peak and their ratio;
exits 1 when a ratio is outside [1 - within, 1 + within] or a run fails.
Memory, not time: the result does not depend on the machine's load.
"""
import argparse
import json
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_runs import with_directory  # noqa: E402

ESTIMATE = re.compile(r'memory estimate: about (\d+) MB per rank')


def run_one(args, nml):
    name = os.path.splitext(os.path.basename(nml))[0]
    outdir = os.path.abspath(os.path.join(args.work, name))
    os.makedirs(outdir, exist_ok=True)
    with open(nml) as f:
        text = with_directory(f.read(), outdir)
    text += "\n&output write_hdf5 = .false. /\n" if '&output' not in text else ''
    text = re.sub(r'write_hdf5\s*=\s*\.(true|false)\.', 'write_hdf5 = .false.', text, flags=re.I)
    if 'write_hdf5' not in text:
        text = re.sub(r'(&output\b)', r'\1 write_hdf5 = .false.,', text, count=1, flags=re.I)
    case = os.path.join(outdir, 'input.nml')
    with open(case, 'w') as f:
        f.write(text)
    cmd = [args.mpiexec, '--bind-to', 'none', '-n', str(args.ranks), args.program, case]
    with open(os.path.join(outdir, 'log.txt'), 'w') as log:
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT)
    with open(os.path.join(outdir, 'log.txt')) as f:
        m = ESTIMATE.search(f.read())
    report = os.path.join(outdir, 'report.json')
    if rc != 0 or m is None or not os.path.exists(report):
        return name, None, None, rc
    with open(report) as f:
        peak = json.load(f)['memory']['peak_rss_bytes']['max'] / 1e6
    return name, float(m.group(1)), peak, rc


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('inputs', nargs='+')
    ap.add_argument('--program', default='build-release/bin/feticontact')
    ap.add_argument('--mpiexec', default='mpirun')
    ap.add_argument('--ranks', type=int, default=2)
    ap.add_argument('--work', default='memory_estimate')
    ap.add_argument('--within', type=float, default=0.25,
                    help='largest accepted |estimate / peak - 1| (default 0.25)')
    args = ap.parse_args()
    args.program = os.path.abspath(args.program)
    bad = 0
    print('%-28s %12s %12s %7s' % ('input', 'estimate MB', 'peak MB', 'ratio'))
    for nml in args.inputs:
        name, est, peak, rc = run_one(args, nml)
        if est is None:
            print('%-28s run failed (exit %d)' % (name, rc))
            bad += 1
            continue
        ratio = est / peak
        ok = abs(ratio - 1) <= args.within
        bad += not ok
        print('%-28s %12.0f %12.1f %7.2f%s' % (name, est, peak, ratio, '' if ok else '  OUTSIDE'))
    sys.exit(1 if bad else 0)


if __name__ == '__main__':
    main()
