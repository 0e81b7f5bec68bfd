#!/usr/bin/env bash
# The main job: installs what is missing, builds, and renders the bundled
# default model, printing what it did. Output goes to ./demo-out/.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
./scripts/build.sh
OUT=${OUT:-demo-out}
mkdir -p "$OUT"
MODEL=assets/default.edrnr
if [ ! -f "$MODEL" ]; then
  echo "demo: no bundled model yet; building the procedural 'several objects' scene"
  MODEL="$OUT/scene.edrnr"
  ./build/edrnr make-scene several --quantized-only -o "$MODEL"
fi
./build/edrnr inspect "$MODEL"
./build/edrnr render "$MODEL" --orbit 30 --width 400 --height 400 -o "$OUT/view.png"
echo "demo: image written to $OUT/view.png"
