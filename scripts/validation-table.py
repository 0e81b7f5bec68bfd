#!/usr/bin/env python3
"""Turns `edrnr reproduce`'s comparisons.csv into the calibration and
validation table of docs/simulator.md: one row per paper figure, our value
for each scene and their mean, the paper's value, the ratio, and whether the
figure was fitted (the one energy parameter, docs/energy.md) or validated.

    scripts/validation-table.py OUT/comparisons.csv
"""
import csv
import sys
from collections import OrderedDict

# The figures a parameter was fitted to; every other figure is validation
# (energy per pixel at 380 MHz follows from the fitted power and the simulated FPS).
FITTED = {("table1", "power at 380 MHz"): "fitted (core_cycle)", ("table2", "power"): "fitted (core_cycle)"}
SKIP = {"table1": ("SRAM",), "table2": ()}


def fmt(v):
    if v in ("", "nan", None):
        return ""
    v = float(v)
    return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    rows = OrderedDict()
    scenes = []
    with open(sys.argv[1]) as f:
        for r in csv.DictReader(f):
            key = (r["figure"], r["quantity"])
            rows.setdefault(key, {"paper": r["paper"], "unit": r["unit"], "by": {}})
            rows[key]["by"][r["scene"]] = r
            if r["scene"] != "all scenes" and r["scene"] not in scenes:
                scenes.append(r["scene"])
    print("| figure | quantity | " + " | ".join(scenes) + " | mean | paper | ratio | |")
    print("|---" * (len(scenes) + 6) + "|")
    for (fig, q), r in rows.items():
        if any(q.startswith(p) for p in SKIP.get(fig, ())):
            continue
        mean = r["by"].get("all scenes")
        if mean is None:
            continue
        cells = [fmt(r["by"][s]["ours"]) if s in r["by"] else "" for s in scenes]
        ratio = f"{float(mean['ratio']):.2f}" if mean["ratio"] not in ("", "nan") else ""
        kind = FITTED.get((fig, q), "validated") if r["paper"] not in ("", "nan") else ""

        print(f"| {fig} | {q} ({r['unit']}) | " + " | ".join(cells) +
              f" | {fmt(mean['ours'])} | {fmt(r['paper'])} | {ratio} | {kind} |")


if __name__ == "__main__":
    main()
