#!/usr/bin/env bash
# Cross-checks edrnr's DDR3 model (edrnr dram --trace) against DRAMsim3 on the
# same traces: mean and p99 read latency, achieved bandwidth and row-buffer
# hit rate (docs/dram.md has the results).
#
#   bench/dramsim3/run-crosscheck.sh DRAMSIM3_SOURCE [TRACE...]
#
# DRAMSIM3_SOURCE  a DRAMsim3 source checkout (github.com/umd-memsys/DRAMsim3);
#                  it is copied to and built in a scratch folder, never into
#                  this project.
# TRACE            extra traces to compare (e.g. one frame's DRAM requests from
#                  `edrnr simulate ... --dram-trace FILE`), besides the
#                  synthetic ones this script writes.
# Environment: EDRNR (the edrnr binary, default build-rel/edrnr),
# WORK (scratch folder, default /tmp/edrnr-dramsim3), PRESET (edrnr DRAM
# preset, default ddr3-1600-4gb-x16-16bit) and INI (the DRAMsim3 config that
# matches it, default bench/dramsim3/ddr3-1600-4gb-x16-16bit.ini).
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
if [ $# -lt 1 ] || [ ! -f "$1/src/memory_system.h" ]; then
  echo "usage: $0 DRAMSIM3_SOURCE [TRACE...]  (DRAMSIM3_SOURCE: a DRAMsim3 checkout with src/memory_system.h)" >&2
  exit 1
fi
SRC="$(cd "$1" && pwd)"
shift
EDRNR=${EDRNR:-$ROOT/build-rel/edrnr}
WORK=${WORK:-/tmp/edrnr-dramsim3}
PRESET=${PRESET:-ddr3-1600-4gb-x16-16bit}
INI=${INI:-$HERE/ddr3-1600-4gb-x16-16bit.ini}
[ -x "$EDRNR" ] || { echo "no edrnr binary at $EDRNR (set EDRNR)" >&2; exit 1; }
mkdir -p "$WORK"

# DRAMsim3 (its own CMake build, library only) and the replay driver.
# (DRAMsim3's CMakeLists puts the library at the top of its source tree.)
LIB="$WORK/src/libdramsim3.so"
if [ ! -f "$LIB" ] || [ "$SRC" -nt "$LIB" ]; then
  rm -rf "$WORK/src" "$WORK/build"
  cp -r "$SRC" "$WORK/src"
  cmake -S "$WORK/src" -B "$WORK/build" -DCMAKE_BUILD_TYPE=Release >/dev/null
  nice cmake --build "$WORK/build" --target dramsim3 -j "${JOBS:-1}" >"$WORK/build.log" 2>&1 ||
    { tail -n 30 "$WORK/build.log" >&2; exit 1; }
fi
DRIVER="$WORK/dramsim3_replay"
if [ ! -x "$DRIVER" ] || [ "$HERE/dramsim3_replay.cpp" -nt "$DRIVER" ] || [ "$LIB" -nt "$DRIVER" ]; then
  nice g++ -std=c++17 -O2 -I"$WORK/src/src" -I"$WORK/src/ext/headers" "$HERE/dramsim3_replay.cpp" -o "$DRIVER" \
    -L"$WORK/src" -Wl,-rpath,"$WORK/src" -ldramsim3
fi

# Synthetic traces (one 16-byte burst a line for the 16-bit preset): the
# same files go to both simulators.
TRACES="$WORK/traces"
mkdir -p "$TRACES"
BURST=$("$EDRNR" dram --preset "$PRESET" --stream 1 | sed -n 's/.* \([0-9]*\) B bursts.*/\1/p')
CAPACITY_MIB=$("$EDRNR" dram --preset "$PRESET" --stream 1 | sed -n 's/.* B bursts, \([0-9]*\) MiB.*/\1/p')
python3 - "$TRACES" "$BURST" "$CAPACITY_MIB" <<'EOF'
import random, sys
out, burst, cap = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]) << 20
bursts = cap // burst
def write(name, records):
    with open(f"{out}/{name}.trace", "w") as f:
        for addr, op, cycle in records:
            f.write(f"0x{addr:x} {op} {cycle}\n")
rng = random.Random(16)
# Saturating: everything arrives at cycle 0 and enters as the queue allows.
write("stream", [(i * burst, "READ", 0) for i in range(200000)])
write("random", [(rng.randrange(bursts) * burst, "READ", 0) for _ in range(100000)])
# Paced: a fixed offered load below saturation (one request every N clocks;
# a burst takes 4 clocks of the data bus).
write("stream_paced", [(i * burst, "READ", 6 * i) for i in range(100000)])
write("random_paced", [(rng.randrange(bursts) * burst, "READ", 12 * i) for i in range(50000)])
write("random_paced_high", [(rng.randrange(bursts) * burst, "READ", 9 * i) for i in range(50000)])
write("random_mixed", [(rng.randrange(bursts) * burst, "WRITE" if rng.random() < 0.3 else "READ", 0)
                       for _ in range(100000)])
# 1 KiB blocks at random 1 KiB-aligned addresses, like feature blocks:
# saturating, and one block every 512 clocks (half the bus).
per_block = 1024 // burst
blocks = [rng.randrange(cap // 1024) * 1024 for _ in range(3000)]
write("blocks_1k", [(b + j * burst, "READ", 0) for b in blocks for j in range(per_block)])
write("blocks_1k_paced", [(b + j * burst, "READ", 512 * i) for i, b in enumerate(blocks[:2000])
                          for j in range(per_block)])
EOF

ALL=("$TRACES"/stream.trace "$TRACES"/stream_paced.trace "$TRACES"/random.trace "$TRACES"/random_paced.trace
     "$TRACES"/random_paced_high.trace "$TRACES"/random_mixed.trace "$TRACES"/blocks_1k.trace "$TRACES"/blocks_1k_paced.trace "$@")
RESULTS="$WORK/results"
mkdir -p "$RESULTS"
for t in "${ALL[@]}"; do
  name=$(basename "$t" .trace)
  echo "crosscheck: $name" >&2
  nice "$EDRNR" dram --preset "$PRESET" --trace "$t" --json "$RESULTS/$name.edrnr.json" >/dev/null
  mkdir -p "$RESULTS/$name.dramsim3"
  nice "$DRIVER" "$INI" "$t" "$RESULTS/$name.dramsim3" >"$RESULTS/$name.dramsim3.txt"
done

python3 - "$RESULTS" "$BURST" "${ALL[@]}" <<'EOF'
import json, os, sys
res, burst = sys.argv[1], int(sys.argv[2])
def signed(x, unit):
    return f"{x:+.1f} {unit}" if round(x, 1) != 0 else f"0.0 {unit}"
def rel(a, b):
    return signed(100.0 * (b - a) / a, "%") if a else "n/a"
def pair(a, b, fmt):
    return f"{a:{fmt}} / {b:{fmt}} ({rel(a, b)})"
print("edrnr / DRAMsim3 (difference of DRAMsim3 from edrnr); latencies in DRAM clocks of 1.25 ns; "
      "'entry': from entering the controller, 'arrival': from the trace's cycle")
print()
print("| trace | requests | offered GB/s | mean read latency, entry | p99, entry | mean, arrival | p99, arrival "
      "| reads in flight | bandwidth GB/s | row hit rate |")
print("|---|---|---|---|---|---|---|---|---|---|")
for t in sys.argv[3:]:
    name = os.path.basename(t)[:-len(".trace")] if t.endswith(".trace") else os.path.basename(t)
    last = 0
    with open(t) as f:
        for line in f:
            w = line.split()
            if len(w) == 3 and not w[0].startswith("#"):
                last = int(w[2])
    s = json.load(open(f"{res}/{name}.edrnr.json"))["stats"]
    lat, arr = s["dram.read_latency"], s["workload.read_latency_from_arrival"]
    cycles = s["dram.cycles"]["value"]
    e = dict(mean=lat["mean"], p99=lat["p99"], amean=arr["mean"], ap99=arr["p99"],
             bw=s["dram.bandwidth_GBps"]["value"], hit=s["dram.row_hit_rate"]["value"],
             inflight=lat["mean"] * lat["count"] / cycles)
    d = {}
    for line in open(f"{res}/{name}.dramsim3.txt"):
        k, v = line.split()
        d[k] = float(v)
    x = dict(mean=d["read_latency_mean"], p99=d["read_latency_p99"], amean=d["arrival_latency_mean"],
             ap99=d["arrival_latency_p99"], bw=d["bandwidth_GBps"], hit=d["row_hit_rate"],
             inflight=d["read_latency_mean"] * d["reads"] / d["cycles"])
    offered = "saturating" if last == 0 else f"{d['requests'] * burst / ((last + 1) * 1.25):.2f}"
    print(f"| {name} | {int(d['requests'])} | {offered} | {pair(e['mean'], x['mean'], '.1f')} "
          f"| {pair(e['p99'], x['p99'], '.0f')} | {pair(e['amean'], x['amean'], '.0f')} "
          f"| {pair(e['ap99'], x['ap99'], '.0f')} | {e['inflight']:.1f} / {x['inflight']:.1f} "
          f"| {pair(e['bw'], x['bw'], '.3f')} | {e['hit']:.3f} / {x['hit']:.3f} ({signed(100 * (x['hit'] - e['hit']), 'pt')}) |")
EOF
