#!/usr/bin/env bash
# Set up everything (Debian packages, a build with runtime checks and floating
# point traps) and run the whole test suite through CTest.
#   tools/test.sh [ctest args...]             Debug build in build-debug/ (-fcheck=all, FP traps)
#   tools/test.sh --release [ctest args...]   Release build in build-release/ (-O3 -march=native):
#                                             the same tests with FMA, vectorization and the BLAS
#                                             kernels an optimized build uses (the cluster test,
#                                             label `cluster`, and the tests whose outcome does not
#                                             depend on the build type, label `build_independent`:
#                                             input errors, run in the Debug pass only)
#   tools/test.sh --help                      this text (nothing is built)
set -euo pipefail

# --help / -h: the usage above, before any set-up or build
for arg in "$@"; do
  case "$arg" in
    -h|--help)
      sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'
      echo "ctest args: passed to ctest after the build (for example -R '<regex>', -L <label>; ctest --help)"
      exit 0 ;;
  esac
done

FETICONTACT_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
source "$FETICONTACT_ROOT/tools/setup.sh"

if [ "${1:-}" = "--release" ]; then
  shift
  build=${FETICONTACT_TEST_BUILD:-$FETICONTACT_ROOT/build-release}
  setup_build "$build" Release -DFETICONTACT_TESTS=ON
  cd "$build"
  exec ctest -j "$(nproc)" --output-on-failure --timeout 900 -LE "cluster|build_independent" "$@"
fi

build=${FETICONTACT_TEST_BUILD:-$FETICONTACT_ROOT/build-debug}
setup_build "$build" Debug -DFETICONTACT_TESTS=ON
cd "$build"
ctest -j "$(nproc)" --output-on-failure --timeout 900 "$@"
