#!/usr/bin/env bash
# Installs everything kelvin needs to build, test and benchmark, from Debian packages
# (gmsh: meshing a specimen's surface, see the README; OpenMPI: kelvin-mpi).
set -euo pipefail
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  build-essential cmake pkg-config \
  libsundials-dev libsuitesparse-dev libeigen3-dev libnlopt-dev libnlopt-cxx-dev \
  libyaml-cpp-dev libcli11-dev libfmt-dev libgtest-dev libbenchmark-dev gmsh \
  libopenmpi-dev openmpi-bin >/dev/null
