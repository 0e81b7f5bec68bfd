#!/usr/bin/env python3
"""Makes a train/validation split of a NeRF-synthetic dataset, for choices
that must not look at the test views.

    scripts/make-val-split.py DATASET OUT [--every 10]

OUT gets a transforms_train.json with the training views that are kept and a
transforms_test.json (the "test" split that `edrnr train --eval-views` and
`edrnr eval` read) holding every N-th training view instead, plus a link to
DATASET's train/ folder. The dataset's own test views are not used.
"""
import argparse
import json
import os
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--every", type=int, default=10, help="hold out every N-th training view (default 10)")
    a = ap.parse_args()
    if a.every < 2:
        sys.exit("make-val-split: --every must be at least 2")
    src = os.path.join(a.dataset, "transforms_train.json")
    try:
        with open(src) as f:
            meta = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"make-val-split: cannot read {src}: {e}")
    frames = meta.get("frames")
    if not isinstance(frames, list) or len(frames) < a.every:
        sys.exit(f"make-val-split: {src} has too few frames")
    keep = [fr for i, fr in enumerate(frames) if i % a.every != a.every - 1]
    held = [fr for i, fr in enumerate(frames) if i % a.every == a.every - 1]
    os.makedirs(a.out, exist_ok=True)
    link = os.path.join(a.out, "train")
    if not os.path.lexists(link):
        os.symlink(os.path.abspath(os.path.join(a.dataset, "train")), link)
    for name, fr in (("transforms_train.json", keep), ("transforms_test.json", held)):
        out = dict(meta)
        out["frames"] = fr
        tmp = os.path.join(a.out, name + ".tmp")
        with open(tmp, "w") as f:
            json.dump(out, f, indent=1)
        os.replace(tmp, os.path.join(a.out, name))
    print(f"make-val-split: {len(keep)} training views, {len(held)} validation views in {a.out}")


if __name__ == "__main__":
    main()
