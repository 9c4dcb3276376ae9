#!/bin/sh
# The bit-identity comparison of a restructuring against a baseline binary:
# cube, block, hertz, the 18 hard inputs, the weak members up to 4096 and one
# load history (tools/compare_runs.py; docs/RESULTS.md "Restructuring").
#   tools/compare_solver_parts.sh BASE_BIN NEW_BIN [WORK] [--only-a | --keep-a]
# --only-a runs the baseline alone into WORK; --keep-a reuses those runs.
set -e
base=$1; new=$2; work=${3:-compare_runs}; shift 2; [ $# -gt 0 ] && shift
here=$(dirname "$0")/..
cd "$here"
exec /usr/bin/python3 tools/compare_runs.py "$base" "$new" --work "$work" "$@" \
    inputs/cube.nml inputs/block.nml inputs/hertz.nml inputs/hard/*.nml \
    inputs/weak/cube_h4_n8.nml inputs/weak/cube_h4_n64.nml inputs/weak/cube_h4_n512.nml \
    inputs/weak/cube_h8_n8.nml inputs/weak/cube_h8_n64.nml inputs/weak/cube_h4_n4096.nml \
    inputs/history/hertz.nml
