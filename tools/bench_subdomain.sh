#!/usr/bin/env bash
# Cost of the local solver K^+ of one subdomain (assembly, factorization,
# solves, factor size) for METIS and AMD orderings, as a Markdown table.
#   tools/bench_subdomain.sh [repetitions] [nel ...]    default: 5 4 8 12 16
# Builds the Release configuration in $FETICONTACT_BENCH_BUILD (default
# build-local-rel) and runs tools/bench/bench_subdomain on one rank.
set -euo pipefail
FETICONTACT_ROOT=${FETICONTACT_ROOT:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}
source "$FETICONTACT_ROOT/tools/setup.sh"

build=${FETICONTACT_BENCH_BUILD:-$FETICONTACT_ROOT/build-local-rel}
install_missing_packages
cmake -S "$FETICONTACT_ROOT" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
if ! cmake --build "$build" --target bench_subdomain -j "$(nproc)" >/dev/null; then
  echo "bench_subdomain.sh: cannot build the target bench_subdomain; is tools/bench hooked into" \
       "the top-level CMakeLists.txt (add_subdirectory(tools/bench))?" >&2
  exit 1
fi
echo "bench_subdomain $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
echo "BLAS: $(readlink -f /usr/lib/x86_64-linux-gnu/libblas.so.3), MUMPS 5.5.1 (Debian), Release build"
echo
exec mpirun --bind-to none -n 1 "$build/bin/bench_subdomain" "$@"
