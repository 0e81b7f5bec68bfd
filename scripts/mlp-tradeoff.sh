#!/usr/bin/env bash
# The MLP-size trade-off (docs/training.md, "MLP size"): trains each scene
# with each MLP preset on a train/validation split of its training views
# (scripts/make-val-split.py; the test views are not looked at), prints the
# validation PSNR of the quantized model and keeps the models for the
# simulator (scripts/mlp-tradeoff-sim.sh).
#
#   scripts/mlp-tradeoff.sh [OUT]   env: SCENES="lego mic" PRESETS="mlp4k mlp2k mlp1k" ITERS=3000 DATA=...
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-tradeoff-out}
DATA=${DATA:-../shared/data/nerf_synthetic}
SCENES=${SCENES:-lego mic}
PRESETS=${PRESETS:-mlp4k mlp2k mlp1k}
ITERS=${ITERS:-3000}
mkdir -p "$OUT"
for s in $SCENES; do
  [ -d "$OUT/val/$s" ] || ./scripts/make-val-split.py "$DATA/$s" "$OUT/val/$s"
  for p in $PRESETS; do
    m="$OUT/${s}_${p}.edrnr"
    [ -f "$m" ] && { echo "tradeoff: $m exists, skipped"; continue; }
    echo "tradeoff: $s $p"
    /usr/bin/time -v ./build/edrnr train "$OUT/val/$s" -o "$m" --config "configs/train/$p.yaml" \
      --iters "$ITERS" --threads 2 --eval-views 10 >"$OUT/${s}_${p}.log" 2>&1
    grep -iE "psnr|steps|wall|Maximum resident" "$OUT/${s}_${p}.log" | tail -6
  done
done
