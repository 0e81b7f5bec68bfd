#!/usr/bin/env bash
# Where the training dB go: trains variants of a preset on a validation split
# (scripts/make-val-split.py: every tenth training view held out, the test
# views never read) and prints a table of their validation PSNR.
#
#   scripts/train-ablation.sh SCENE_DIR OUT_DIR [--iters N] [--preset FILE] [--variants "a b ..."]
#
# A variant is the name of an overlay in configs/train/ablation/ (applied on
# top of the preset with a second --config), "base" (the preset alone), or
# "iters=N" (the preset with N steps) or "seed=S" (the preset with another
# random seed: rays, initial values, occupancy jitter; the spread between
# seeds is what a variant's gain must exceed). Every run is deterministic: the same
# command gives the same model bits on any machine with the same build.
# Runs whose model already exists in OUT_DIR are not repeated.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
edrnr=${EDRNR:-$root/build/edrnr}
if [ $# -lt 2 ]; then
  sed -n '2,14p' "$0" >&2
  exit 2
fi
scene=$1
out=$2
shift 2
iters=4000
preset=$root/configs/train/default.yaml
variants="base no-per-cv distortion-0.01 distortion-0.03 tv-1e-6 tv-1e-4 block-tv-1e-4 mlp-tie-1e-3"
while [ $# -gt 0 ]; do
  case $1 in
    --iters) iters=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --variants) variants=$2; shift 2 ;;
    *) echo "train-ablation: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[ -x "$edrnr" ] || { echo "train-ablation: no edrnr binary at $edrnr (build first, or set EDRNR)" >&2; exit 1; }
[ -f "$scene/transforms_train.json" ] || { echo "train-ablation: $scene has no transforms_train.json" >&2; exit 1; }
mkdir -p "$out"
name=$(basename "$scene")
val=$out/val_$name
[ -f "$val/transforms_test.json" ] || python3 "$root/scripts/make-val-split.py" "$scene" "$val"

for v in $variants; do
  n=$iters
  extra=()
  case $v in
    base) ;;
    iters=*) n=${v#iters=} ;;
    seed=*) extra=(--seed "${v#seed=}") ;;
    *)
      overlay=$root/configs/train/ablation/$v.yaml
      [ -f "$overlay" ] || { echo "train-ablation: no overlay $overlay" >&2; exit 1; }
      extra=(--config "$overlay")
      ;;
  esac
  model=$out/${name}_$v.edrnr
  log=$out/${name}_$v.txt
  if [ ! -f "$model" ]; then
    echo "train-ablation: $name $v ($n steps)" >&2
    "$edrnr" train "$val" -o "$model" --config "$preset" "${extra[@]}" --iters "$n" --eval-views 10 \
      --float-output "$out/${name}_${v}_float.edrnr" --profile >"$log" 2>&1
  fi
done

printf '| scene | variant | steps | training PSNR | validation PSNR float | validation PSNR quantized |\n'
printf '|---|---|---|---|---|---|\n'
for v in $variants; do
  log=$out/${name}_$v.txt
  [ -f "$log" ] || continue
  steps=$(sed -n 's/^trained \([0-9]*\) steps.*/\1/p' "$log")
  train=$(sed -n 's/^training PSNR (running): .*quantized \([0-9.]*\) dB/\1/p' "$log")
  pf=$(sed -n 's/^test PSNR ([0-9]* views): float \([0-9.]*\) dB.*/\1/p' "$log")
  pq=$(sed -n 's/^test PSNR ([0-9]* views): .*quantized \([0-9.]*\) dB/\1/p' "$log")
  printf '| %s | %s | %s | %s dB | %s dB | %s dB |\n' "$name" "$v" "$steps" "$train" "$pf" "$pq"
done
