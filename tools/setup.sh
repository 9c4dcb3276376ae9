#!/usr/bin/env bash
# Install the Debian 12 packages feticontact needs (only those missing), then
# configure and build. Sourced by tools/run.sh and tools/test.sh.
#   setup_build <build-dir> <build-type> [extra cmake args...]
set -euo pipefail

FETICONTACT_PACKAGES=(gfortran gcc cmake ninja-build make pkg-config
  libopenmpi-dev openmpi-bin libmumps-dev libmetis-dev libhdf5-openmpi-dev
  liblapack-dev libblas-dev libopenblas0-serial python3-numpy python3-matplotlib python3-h5py)

install_missing_packages() {
  local missing=()
  for p in "${FETICONTACT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    return 0
  fi
  echo "feticontact: installing Debian packages: ${missing[*]}"
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# Open MPI refuses to run as root without these; allow more ranks than cores.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_rmaps_base_oversubscribe=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none
# One BLAS thread per MPI rank unless the user chose otherwise (the program
# itself does the same, see FETICONTACT_BLAS_THREADS in docs/INPUT.md; this
# also covers the test programs that call MUMPS/LAPACK directly).
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}

setup_build() {
  local dir=$1 type=$2
  shift 2
  install_missing_packages
  cmake -S "$FETICONTACT_ROOT" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE="$type" "$@"
  cmake --build "$dir" -j "$(nproc)"
}
