#!/usr/bin/env python3
"""Draws the Pareto report of an `edrnr sweep` folder: pareto.png.

Reads DIR/results.jsonl (every job's row) and DIR/pareto.csv (the front and
the base design, as `edrnr sweep` wrote them) and plots frame rate against
energy per pixel with on-chip SRAM as the colour, and frame rate against SRAM;
front points are outlined and joined, the base design is a star.

Usage: pareto.py DIR [--base-label TEXT] [--out FILE]
Exit status 3 when matplotlib is missing, 2 on bad input.
"""
import argparse
import csv
import json
import os
import sys


def load_points(folder):
    """Mean FPS and nJ/pixel and the largest SRAM per point with every job ok."""
    sums = {}
    with open(os.path.join(folder, "results.jsonl"), encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            row = json.loads(line)
            s = sums.setdefault(row["point"], {"n": 0, "ok": 0, "fps": 0.0, "nj": 0.0, "sram": 0})
            s["n"] += 1
            m = row.get("metrics", {})
            if row.get("status") != "ok" or m.get("fps") is None or m.get("nJ_per_pixel") is None:
                continue
            s["ok"] += 1
            s["fps"] += m["fps"]
            s["nj"] += m["nJ_per_pixel"]
            s["sram"] = max(s["sram"], m["sram_total_bytes"])
    return {p: (s["fps"] / s["ok"], s["nj"] / s["ok"], s["sram"]) for p, s in sums.items() if s["ok"] == s["n"]}


def load_front(folder):
    front, base = [], None
    with open(os.path.join(folder, "pareto.csv"), encoding="utf-8", newline="") as f:
        for r in csv.DictReader(f):
            p = (float(r["fps"]), float(r["nJ_per_pixel"]), float(r["sram_total_bytes"]))
            if r["on_front"] == "1":
                front.append(p)
            if r["design"] == "base":
                base = p
    return front, base


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?")
    ap.add_argument("--check", action="store_true", help="exit 0 if matplotlib is there, 3 if not")
    ap.add_argument("--base-label", default="base design")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        if not a.check:
            print("pareto.py: matplotlib is missing (Debian: python3-matplotlib)", file=sys.stderr)
        return 3
    if a.check:
        return 0
    if not a.folder:
        ap.error("the sweep folder is required")
    try:
        points = load_points(a.folder)
        front, base = load_front(a.folder)
    except (OSError, ValueError, KeyError) as e:
        print(f"pareto.py: {a.folder}: cannot read the sweep's results: {e}", file=sys.stderr)
        return 2
    if not points:
        print(f"pareto.py: {a.folder}: no point has results for all its jobs", file=sys.stderr)
        return 2

    fps = [v[0] for v in points.values()]
    nj = [v[1] for v in points.values()]
    kb = [v[2] / 1024 for v in points.values()]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    sc = ax1.scatter(fps, nj, c=kb, cmap="viridis", s=18, alpha=0.8, label="design points")
    fig.colorbar(sc, ax=ax1, label="on-chip SRAM (KB)")
    ax2.scatter(fps, kb, c=nj, cmap="magma", s=18, alpha=0.8)
    if front:
        f = sorted(front)
        ax1.scatter([p[0] for p in f], [p[1] for p in f], facecolors="none", edgecolors="red", s=60,
                    label="Pareto front (FPS, nJ/px, SRAM)")
        ax2.scatter([p[0] for p in f], [p[2] / 1024 for p in f], facecolors="none", edgecolors="red", s=60)
    if base:
        for ax, y in ((ax1, base[1]), (ax2, base[2] / 1024)):
            ax.scatter([base[0]], [y], marker="*", s=220, color="orange", edgecolors="black", zorder=5,
                       label=a.base_label if ax is ax1 else None)
    ax1.set_xlabel("frame rate (FPS)")
    ax1.set_ylabel("energy (nJ/pixel)")
    ax1.set_title("FPS against energy per pixel")
    ax1.legend(fontsize=8)
    ax2.set_xlabel("frame rate (FPS)")
    ax2.set_ylabel("on-chip SRAM (KB)")
    ax2.set_title("FPS against SRAM (colour: nJ/pixel)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out = a.out or os.path.join(a.folder, "pareto.png")
    tmp = out + ".tmp.%d.png" % os.getpid()
    fig.savefig(tmp, dpi=110, metadata={"Software": None})
    os.replace(tmp, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
