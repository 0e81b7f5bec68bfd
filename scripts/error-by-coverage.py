#!/usr/bin/env python3
"""Where a model's image error sits: the share of pixels and of squared error
on the background, on partly covered pixels (0 < alpha < 1 in the ground
truth: edges, meshes) and on opaque ones, over a dataset split's views.

    scripts/error-by-coverage.py DATASET_DIR RENDER_DIR [--split test]

RENDER_DIR holds the renders of `edrnr eval MODEL DATASET_DIR --save-dir
RENDER_DIR` (<split>_<view>.png, white background)."""
import argparse
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("renders")
    ap.add_argument("--split", default="test")
    a = ap.parse_args()
    tf_path = os.path.join(a.dataset, f"transforms_{a.split}.json")
    try:
        frames = json.load(open(tf_path))["frames"]
    except (OSError, ValueError, KeyError) as e:
        sys.exit(f"error-by-coverage: cannot read {tf_path}: {e}")
    err, px = {}, {}
    for v, fr in enumerate(frames):
        gt_path = os.path.join(a.dataset, fr["file_path"].removeprefix("./") + ".png")
        out_path = os.path.join(a.renders, f"{a.split}_{v:03d}.png")
        for p in (gt_path, out_path):
            if not os.path.isfile(p):
                sys.exit(f"error-by-coverage: missing image {p}")
        gt = mpimg.imread(gt_path)
        if gt.ndim != 3 or gt.shape[2] != 4:
            sys.exit(f"error-by-coverage: {gt_path} has no alpha channel")
        alpha = gt[..., 3]
        target = gt[..., :3] * alpha[..., None] + (1 - alpha[..., None])
        out = mpimg.imread(out_path)[..., :3]
        if out.shape != target.shape:
            sys.exit(f"error-by-coverage: {out_path} is {out.shape[:2]}, the ground truth {target.shape[:2]}")
        se = ((out - target) ** 2).mean(-1)
        for name, mask in (("background", alpha == 0), ("partly covered", (alpha > 0) & (alpha < 1)),
                           ("opaque", alpha == 1)):
            err[name] = err.get(name, 0.0) + float(se[mask].sum())
            px[name] = px.get(name, 0) + int(mask.sum())
    total_err, total_px = sum(err.values()), sum(px.values())
    print(f"{len(frames)} views of {a.dataset} ({a.split})")
    for name in err:
        print(f"  {name:15s} {100 * px[name] / total_px:5.1f} % of pixels, "
              f"{100 * err[name] / max(total_err, 1e-30):5.1f} % of squared error")


if __name__ == "__main__":
    main()
