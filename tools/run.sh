#!/usr/bin/env bash
# Set up everything (Debian packages, optimized build) and run a case.
#   tools/run.sh [input.nml] [ranks]     default: inputs/cube.nml on 2 ranks
set -euo pipefail
FETICONTACT_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
source "$FETICONTACT_ROOT/tools/setup.sh"

input=${1:-$FETICONTACT_ROOT/inputs/cube.nml}
ranks=${2:-2}
build=${FETICONTACT_BUILD:-$FETICONTACT_ROOT/build}
setup_build "$build" Release -DFETICONTACT_TESTS=OFF
exec mpirun --bind-to none -n "$ranks" "$build/bin/feticontact" "$input"
