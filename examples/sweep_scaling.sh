#!/usr/bin/env bash
# Throughput of `edrnr sweep` with 1 and 2 worker processes, and with 1 and 2
# MPI ranks, on examples/sweep_scaling.yaml (8 points); prints the wall times,
# the speedups and the load average before and after (docs/sweeps.md).
# Usage: examples/sweep_scaling.sh [EDRNR] [SPEC]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
edrnr=${1:-$here/../build/edrnr}
spec=${2:-$here/sweep_scaling.yaml}
work=$(mktemp -d /tmp/edrnr-scaling.XXXXXX)
trap 'rm -rf "$work"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
wall() {  # wall seconds of a command; its CPU seconds (user + system) go to $work/cpu
  local t0 t1
  t0=$(date +%s.%N)
  /usr/bin/time -f "%U %S" -o "$work/time" "$@" >"$work/log" 2>&1 || { cat "$work/log" >&2; exit 1; }
  t1=$(date +%s.%N)
  awk '{ print $1 + $2 }' "$work/time" >"$work/cpu"
  awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }'
}
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
w1=$(wall "$edrnr" sweep "$spec" --out "$work/w1" --workers 1 --no-plot --quiet)
c1=$(cat "$work/cpu")
w2=$(wall "$edrnr" sweep "$spec" --out "$work/w2" --workers 2 --no-plot --quiet)
c2=$(cat "$work/cpu")
cmp "$work/w1/results.jsonl" "$work/w2/results.jsonl"
printf 'workers 1: %.2f s (%.2f CPU s)   workers 2: %.2f s (%.2f CPU s)   speedup %.2f\n' "$w1" "$c1" "$w2" "$c2" \
  "$(awk -v a="$w1" -v b="$w2" 'BEGIN { print a / b }')"
if command -v mpirun >/dev/null; then
  m1=$(wall mpirun --oversubscribe -np 1 "$edrnr" sweep "$spec" --out "$work/m1" --no-plot --quiet)
  d1=$(cat "$work/cpu")
  m2=$(wall mpirun --oversubscribe -np 2 "$edrnr" sweep "$spec" --out "$work/m2" --no-plot --quiet)
  d2=$(cat "$work/cpu")
  cmp "$work/w1/results.jsonl" "$work/m2/results.jsonl"
  printf 'ranks 1:   %.2f s (%.2f CPU s)   ranks 2:   %.2f s (%.2f CPU s)   speedup %.2f\n' "$m1" "$d1" "$m2" "$d2" \
    "$(awk -v a="$m1" -v b="$m2" 'BEGIN { print a / b }')"
fi
echo "load average after:  $(cut -d' ' -f1-3 /proc/loadavg)"
