#!/usr/bin/env bash
# Configures and builds edrnr in ./build (Release), and the web front end in
# web/dist (scripts/build-web.sh). Extra arguments go to cmake.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$BUILD_DIR" -j "$(nproc)"
# The web front end of `edrnr serve` (skipped with a message when npm is missing).
./scripts/build-web.sh --if-possible
