#!/usr/bin/env bash
# Installs every Debian package edrnr needs to build, test and benchmark.
# Idempotent and non-interactive; run as root (or with sudo available).
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  libcli11-dev nlohmann-json3-dev libyaml-cpp-dev libfmt-dev
  libspng-dev zlib1g-dev libeigen3-dev libhwy-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-matplotlib   # scripts/report_figures.py (edrnr reproduce)
  pybind11-dev python3-dev python3-numpy   # the Python module (python/)
  openmpi-bin libopenmpi-dev   # edrnr sweep across MPI ranks
  libcpp-httplib-dev           # edrnr serve
  nodejs chromium              # scripts/build-web.sh (the front end) and its browser tests (tests/web)
)
# npm comes with some nodejs builds (NodeSource's) and is a package of its own on Debian.
command -v npm >/dev/null 2>&1 || PACKAGES+=(npm)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
  SUDO="sudo"
fi
echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
