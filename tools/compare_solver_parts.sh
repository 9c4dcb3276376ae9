#!/bin/sh
# The bit-identity comparison of a restructuring against a baseline binary
# (tools/compare_runs.py; docs/RESULTS.md "Restructuring"): cube, block,
# hertz, the 18 hard inputs, the weak members up to 4096, one load history
# (also with recycling and checkpoints), and the three inputs whose coarse problem sits on one group of 2 ranks
# (elongated_16, cube_h4_n512, cube_h4_n4096: MUMPS's parallel factorization
# differs from run to run) again with `&solver coarse_ranks = 1`
# (deterministic; written to WORK/variants).
#   tools/compare_solver_parts.sh BASE_BIN NEW_BIN [WORK [--only-a | --keep-a]]
# --only-a runs the baseline alone into WORK; --keep-a reuses those runs.
# Prints one line per input; exit status 1 when any differs.
set -e
base=$(realpath "$1"); new=$(realpath "$2"); work=$(realpath -m "${3:-compare_runs}")
shift 2; [ $# -gt 0 ] && shift
cd "$(dirname "$0")/.."
mkdir -p "$work/variants"
for f in inputs/hard/elongated_16.nml inputs/weak/cube_h4_n512.nml inputs/weak/cube_h4_n4096.nml; do
    sed 's/&solver /\&solver coarse_ranks = 1, /' "$f" > "$work/variants/$(basename "$f" .nml)_coarse1.nml"
done
# the load history again with its face CG directions recycled (and checkpointed)
sed 's/&history /\&history recycle = .true., checkpoint = .true., /' inputs/history/hertz.nml \
    > "$work/variants/hertz_history_recycle.nml"
exec /usr/bin/python3 tools/compare_runs.py "$base" "$new" --work "$work" "$@" \
    inputs/cube.nml inputs/block.nml inputs/hertz.nml inputs/hard/*.nml \
    inputs/weak/cube_h4_n8.nml inputs/weak/cube_h4_n64.nml inputs/weak/cube_h4_n512.nml \
    inputs/weak/cube_h8_n8.nml inputs/weak/cube_h8_n64.nml inputs/weak/cube_h4_n4096.nml \
    inputs/history/hertz.nml "$work"/variants/*_coarse1.nml "$work"/variants/hertz_history_recycle.nml
