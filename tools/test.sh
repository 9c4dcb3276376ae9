#!/usr/bin/env bash
# Set up everything (Debian packages, a build with runtime checks and floating
# point traps) and run the whole test suite through CTest.
#   tools/test.sh [ctest args...]
set -euo pipefail
FETICONTACT_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
source "$FETICONTACT_ROOT/tools/setup.sh"

build=${FETICONTACT_TEST_BUILD:-$FETICONTACT_ROOT/build-debug}
setup_build "$build" Debug -DFETICONTACT_TESTS=ON
cd "$build"
ctest -j "$(nproc)" --output-on-failure --timeout 900 "$@"
