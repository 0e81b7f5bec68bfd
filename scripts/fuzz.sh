#!/usr/bin/env bash
# Fuzzes edrnr's input readers with libFuzzer (AddressSanitizer and
# UndefinedBehaviorSanitizer): scripts/fuzz.sh [SECONDS] [HARNESS...]
#   SECONDS   per harness, default 60
#   HARNESS   any of the tests/fuzz/fuzz_*.cpp names (default: all of them):
#             fuzz_model_loader      the .edrnr loader
#             fuzz_data_transforms   the NeRF transforms JSON parser
#             fuzz_sim_chip_config   the chip preset loader (functional + simulator sections)
#             fuzz_sim_dram_config   the DRAM preset loader
#             fuzz_sim_dram_trace    the DRAM trace reader and workload driver
#             fuzz_train_checkpoint  the training checkpoint reader and resume
# Builds with clang in build-fuzz/ (BUILD_DIR to change), writes each
# harness's seed corpus, then runs. Findings go to build-fuzz/fuzz-artifacts/.
# Not part of CI (docs/reliability.md reports the runs).
set -euo pipefail
cd "$(dirname "$0")/.."
RUN_SECONDS=${1:-60}
shift || true
BUILD_DIR=${BUILD_DIR:-build-fuzz}
JOBS=${JOBS:-2}
if [ $# -gt 0 ]; then
  HARNESSES=("$@")
else
  HARNESSES=()
  for f in tests/fuzz/fuzz_*.cpp; do HARNESSES+=("$(basename "$f" .cpp)"); done
fi

SANITIZE="-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
# clang builds the trainer's 8-wide vector kernels (src/train/mlp_kernels.cpp)
# only with AVX enabled.
if grep -qw avx2 /proc/cpuinfo 2>/dev/null; then SANITIZE="$SANITIZE -mavx2"; fi
CC=clang CXX=clang++ cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DEDRNR_FUZZ=ON -DEDRNR_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS="$SANITIZE" >/dev/null
cmake --build "$BUILD_DIR" --target "${HARNESSES[@]}" -j "$JOBS"

export ASAN_OPTIONS=${ASAN_OPTIONS:-allocator_may_return_null=0:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
ARTIFACTS="$BUILD_DIR/fuzz-artifacts/"
mkdir -p "$ARTIFACTS"
status=0
for h in "${HARNESSES[@]}"; do
  FUZZER="$BUILD_DIR/tests/$h"
  CORPUS="$BUILD_DIR/fuzz-corpus/${h#fuzz_}"
  mkdir -p "$CORPUS"
  EDRNR_FUZZ_WRITE_SEEDS="$CORPUS" "$FUZZER"
  echo "fuzz: running $h for ${RUN_SECONDS} s on $CORPUS"
  "$FUZZER" -max_total_time="$RUN_SECONDS" -max_len=262144 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=10 \
    -artifact_prefix="$ARTIFACTS$h-" -print_final_stats=1 "$CORPUS" || status=1
done
exit $status
