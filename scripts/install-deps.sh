#!/bin/bash
# scripts/install-deps.sh: install the Debian 12 packages the toolchain needs, only when missing.
# Idempotent: a machine that has them all returns in well under a second.
set -euo pipefail
PKGS=(gcc g++ make pkg-config
      libgmsh-dev gmsh libhdf5-dev hdf5-tools libopenblas-dev liblapacke-dev libarpack2-dev
      libsuitesparse-dev libcgal-dev libyaml-dev zlib1g-dev libdeflate-dev
      python3-h5py python3-numpy python3-scipy python3-matplotlib python3-meshio calculix-ccx valgrind
      clang-format bsdutils util-linux man-db groff-base
      # issue 13: the batch example (/usr/bin/time; bc for bench/batch.sh) and fe2cb-mpi
      # (PETSc/SLEPc with MUMPS over OpenMPI: 85 packages, 62 MB download, 259 MB installed)
      time bc libpetsc-real-dev libslepc-real-dev openmpi-bin)
# `make fuzz` only (not make check): clang and its libFuzzer runtime
if [ "${1:-}" = --fuzz ]; then PKGS=(clang libclang-rt-14-dev); fi
missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "install-deps: installing ${missing[*]}" >&2
SUDO=
if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
