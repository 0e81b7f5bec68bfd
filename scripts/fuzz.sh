#!/usr/bin/env bash
# Fuzzes the .edrnr model loader with libFuzzer (AddressSanitizer and
# UndefinedBehaviorSanitizer) for N seconds: scripts/fuzz.sh [N], default 60.
# Builds with clang in build-fuzz/ (BUILD_DIR to change), writes a seed corpus
# of valid small models, then runs. Findings go to build-fuzz/fuzz-artifacts/.
# Not part of CI.
set -euo pipefail
cd "$(dirname "$0")/.."
RUN_SECONDS=${1:-60}
BUILD_DIR=${BUILD_DIR:-build-fuzz}
JOBS=${JOBS:-2}

SANITIZE="-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
CC=clang CXX=clang++ cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DEDRNR_FUZZ=ON -DEDRNR_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS="$SANITIZE" >/dev/null
cmake --build "$BUILD_DIR" --target fuzz_model_loader -j "$JOBS"

FUZZER="$BUILD_DIR/tests/fuzz_model_loader"
CORPUS="$BUILD_DIR/fuzz-corpus/model_loader"
ARTIFACTS="$BUILD_DIR/fuzz-artifacts/"
mkdir -p "$CORPUS" "$ARTIFACTS"
EDRNR_FUZZ_WRITE_SEEDS="$CORPUS" "$FUZZER"

echo "fuzz: running fuzz_model_loader for ${RUN_SECONDS} s on $CORPUS"
export ASAN_OPTIONS=${ASAN_OPTIONS:-allocator_may_return_null=0:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
"$FUZZER" -max_total_time="$RUN_SECONDS" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=512 \
  -artifact_prefix="$ARTIFACTS" -print_final_stats=1 "$CORPUS"
