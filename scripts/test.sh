#!/usr/bin/env bash
# The test command: installs what is missing, builds, and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
./scripts/setup.sh
./scripts/build.sh
built=$(date +%s)
echo "test: build took $((built - start)) s"
ctest --test-dir "${BUILD_DIR:-build}" --output-on-failure -j "$(nproc)"
echo "test: tests took $(( $(date +%s) - built )) s"
