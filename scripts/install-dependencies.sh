#!/usr/bin/env bash
# Installs every Debian 12 package BrainShift needs to build, test and run the demo.
# The single source of the dependency list: README.md and .ci/run both call this script.
set -euo pipefail

packages=(
  # build tools
  build-essential cmake ninja-build ccache pkg-config git
  # imaging and geometry
  libinsighttoolkit5-dev libvtk9-dev libeigen3-dev libcgal-dev libnanoflann-dev
  # finite elements and parallel solve
  petsc-dev libopenmpi-dev openmpi-bin
  # desktop
  qtbase5-dev libvtk9-qt-dev
  # into the operating room's systems: OpenIGTLink out, DICOM out (DCMTK), and the DICOM tools of
  # the interoperability tests (dcmdump/dcmodify, dciodvfy)
  libopenigtlink-dev libdcmtk-dev dcmtk dicom3tools
  # command line, JSON, tests
  libcli11-dev nlohmann-json3-dev libgtest-dev
  # file formats: whole-buffer gzip for the written volumes, HDF5 for the transform files (ITK's)
  libdeflate-dev libhdf5-dev
  # data: the Colin27 T1 template of the built-in case; python3 for the command-line tests
  mricron-data python3
  # an independent finite element solver: the cross-check test and the built-in case's finite element truth
  calculix-ccx
  # the trust benchmark's damaged segmentations (Testing/Benchmarks/trust)
  python3-numpy python3-scipy
  # offscreen rendering and GUI tests
  xvfb xauth
  # fast BLAS for the direct solvers (switches the system alternative)
  libopenblas0
)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-dependencies: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-dependencies: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
