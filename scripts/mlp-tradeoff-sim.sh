#!/usr/bin/env bash
# The simulator half of the MLP-size trade-off (docs/training.md, "MLP size"):
# simulates each model scripts/mlp-tradeoff.sh trained on validation views of
# its split (held-out training views, never the test views) with the chip
# preset, and prints one table row per model: validation PSNR of the
# quantized model (from the training log), DRAM bytes per pixel, FPS and
# nJ/pixel at 380 MHz, each the mean over the views.
#
#   scripts/mlp-tradeoff-sim.sh [OUT]   env: VIEWS="0 4 8" CHIP=edr_nr_40nm
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-tradeoff-out}
VIEWS=${VIEWS:-0 4 8}
CHIP=${CHIP:-edr_nr_40nm}
printf "| model | MLP bytes | validation PSNR | DRAM B/pixel | MLP B/pixel | FPS | nJ/pixel |\n|---|---|---|---|---|---|---|\n"
for m in "$OUT"/*.edrnr; do
  name=$(basename "$m" .edrnr)
  scene=${name%%_*}
  psnr=$(grep -o "quantized [0-9.]* dB" "$OUT/$name.log" | tail -1 | awk '{print $2}')
  bytes=$(./build/edrnr inspect --json "$m" | python3 -c "import json,sys; print(json.load(sys.stdin)['mlps']['q8_bytes_per_mlp'])" 2>/dev/null || echo "?")
  rows=""
  for v in $VIEWS; do
    d="$OUT/sim/$name/v$v"
    mkdir -p "$d"
    [ -f "$d/stats.json" ] || ./build/edrnr simulate "$m" --chip "$CHIP" --dataset "$OUT/val/$scene" --view "$v" \
      --allow-over-budget -q -o "$d" >"$d/report.txt" 2>&1
    rows="$rows $d/stats.json"
  done
  python3 - "$name" "$bytes" "$psnr" $rows <<'PY'
import json, sys
name, mlp_bytes, psnr, files = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
def stat(d, n):
    return d["stats"][n]["value"]
fps = dram = mlp = nj = 0
for f in files:
    d = json.load(open(f))
    px = stat(d, "sim.pixels")
    fps += stat(d, "sim.fps")
    dram += (stat(d, "dram.read_bytes") + stat(d, "dram.write_bytes")) / px
    mlp += stat(d, "mem.mlp_weights.read_bytes") / px
    nj += stat(d, "energy.nJ_per_pixel")
k = len(files)
print(f"| {name} | {mlp_bytes} | {psnr} dB | {dram/k:.1f} | {mlp/k:.1f} | {fps/k:.1f} | {nj/k:.2f} |")
PY
done
