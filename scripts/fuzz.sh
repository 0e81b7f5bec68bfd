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
# Builds with clang in build-fuzz/ (BUILD_DIR to change; JOBS compile jobs,
# default 1), writes each harness's seed corpus, then runs the harnesses one
# after another, each as one process at the lowest priority (nice -n 19).
# RUNS=N also stops each harness after N executions; BUILD=0 runs the
# harnesses as last built. Findings go to build-fuzz/fuzz-artifacts/, each
# run's log to build-fuzz/fuzz-logs/HARNESS-DATE.log, and a summary line per
# harness (executions, exec/s, corpus, cov, ft) is printed at the end. Installs clang and libclang-rt-14-dev (Debian) if they are missing.
# Not part of CI (docs/reliability.md reports the runs).
set -euo pipefail
cd "$(dirname "$0")/.."
RUN_SECONDS=${1:-60}
shift || true
BUILD_DIR=${BUILD_DIR:-build-fuzz}
JOBS=${JOBS:-1}
RUNS=${RUNS:-}
BUILD=${BUILD:-1}
if [ $# -gt 0 ]; then
  HARNESSES=("$@")
else
  HARNESSES=()
  for f in tests/fuzz/fuzz_*.cpp; do HARNESSES+=("$(basename "$f" .cpp)"); done
fi

# The compiler and the libFuzzer/sanitizer runtimes.
if ! command -v clang++ >/dev/null || ! dpkg -s libclang-rt-14-dev >/dev/null 2>&1; then
  echo "fuzz: installing clang and libclang-rt-14-dev"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; fi
  $SUDO apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends clang libclang-rt-14-dev
fi

SANITIZE="-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
# clang builds the trainer's 8-wide vector kernels (src/train/mlp_kernels.cpp)
# only with AVX enabled.
if grep -qw avx2 /proc/cpuinfo 2>/dev/null; then SANITIZE="$SANITIZE -mavx2"; fi
if [ "$BUILD" != 0 ]; then
  CC=clang CXX=clang++ cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DEDRNR_FUZZ=ON -DEDRNR_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS="$SANITIZE" >/dev/null
  nice cmake --build "$BUILD_DIR" --target "${HARNESSES[@]}" -j "$JOBS"
fi

export ASAN_OPTIONS=${ASAN_OPTIONS:-allocator_may_return_null=0:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
ARTIFACTS="$BUILD_DIR/fuzz-artifacts/"
LOGS="$BUILD_DIR/fuzz-logs"
mkdir -p "$ARTIFACTS" "$LOGS"
RUNS_FLAG=()
if [ -n "$RUNS" ]; then RUNS_FLAG=(-runs="$RUNS"); fi
status=0
declare -A LOG
for h in "${HARNESSES[@]}"; do
  FUZZER="$BUILD_DIR/tests/$h"
  CORPUS="$BUILD_DIR/fuzz-corpus/${h#fuzz_}"
  mkdir -p "$CORPUS"
  EDRNR_FUZZ_WRITE_SEEDS="$CORPUS" "$FUZZER"
  LOG[$h]="$LOGS/$h-$(date +%Y%m%d-%H%M%S).log"
  echo "fuzz: running $h for ${RUN_SECONDS} s${RUNS:+ or $RUNS executions} on $CORPUS (log ${LOG[$h]})"
  nice -n 19 "$FUZZER" -max_total_time="$RUN_SECONDS" "${RUNS_FLAG[@]}" -max_len=262144 -rss_limit_mb=2048 \
    -malloc_limit_mb=1024 -timeout=10 -artifact_prefix="$ARTIFACTS$h-" -print_final_stats=1 "$CORPUS" \
    >"${LOG[$h]}" 2>&1 || status=1
  tail -n 12 "${LOG[$h]}"
done

# One line per harness from its log: executions, exec/s, corpus files, and the
# last coverage report (cov: edges, ft: features).
echo
printf "%-24s %12s %8s %8s %8s %8s %s\n" harness executions exec/s corpus cov ft result
for h in "${HARNESSES[@]}"; do
  log="${LOG[$h]}"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n 1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -n 1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corpus=$(find "$BUILD_DIR/fuzz-corpus/${h#fuzz_}" -type f | wc -l)
  result=ok
  if grep -qE '^==[0-9]+==ERROR|^SUMMARY: |deadly signal|runtime error' "$log"; then result=FINDING; fi
  printf "%-24s %12s %8s %8s %8s %8s %s\n" "$h" "${execs:-?}" "${rate:-?}" "$corpus" "${cov:-?}" "${ft:-?}" "$result"
done
exit $status
