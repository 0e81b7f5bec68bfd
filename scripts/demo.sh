#!/usr/bin/env bash
# The main job: installs what is missing, builds, and simulates one 800x800
# frame of the bundled model on the EDR-NR chip, cycle by cycle. It prints the
# report (FPS, nJ/pixel, power, cache hit rates, external traffic, and PSNR
# against the ground truth when the dataset is at hand) and writes the image,
# statistics JSON, resolved config and a Chrome trace to ./demo-out/.
#
# Overrides: MODEL=file.edrnr  DATASET=nerf_synthetic/<scene>  VIEW=N  OUT=dir
#
# ./scripts/demo.sh --serve: the same set-up and build, then the web app
# (edrnr serve, docs/web.md) on http://127.0.0.1:${PORT:-8080}/.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
./scripts/build.sh
if [ "${1:-}" = "--serve" ]; then
  echo "demo: open http://127.0.0.1:${PORT:-8080}/ in a browser (Ctrl-C stops the server)"
  exec ./build/edrnr serve --port "${PORT:-8080}"
fi
OUT=${OUT:-demo-out}
mkdir -p "$OUT"

MODEL=${MODEL:-assets/lego.edrnr}
DATASET=${DATASET:-../shared/data/nerf_synthetic/lego}
if [ ! -f "$MODEL" ]; then
  echo "demo: no bundled model at $MODEL; using the procedural 'several objects' scene"
  MODEL="$OUT/scene.edrnr"
  ./build/edrnr make-scene several --quantized-only -o "$MODEL"
  DATASET=""
fi

echo
./build/edrnr inspect "$MODEL"
echo
if [ -n "$DATASET" ] && [ -f "$DATASET/transforms_test.json" ]; then
  ./build/edrnr simulate "$MODEL" --dataset "$DATASET" --view "${VIEW:-0}" --threads 2 -o "$OUT"
else
  ./build/edrnr simulate "$MODEL" --orbit 30 --width 800 --threads 2 -o "$OUT"
fi
echo
echo "demo: image, stats.json, config.yaml and trace.json (open in ui.perfetto.dev) are in $OUT/"
