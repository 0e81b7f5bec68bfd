#!/usr/bin/env python3
"""Fits the energy table's `core_cycle` row (docs/energy.md, "Calibration")
to Table I's 11.7 nJ/pixel at 380 MHz / 1.21 V.

    scripts/fit-core-cycle.py STATS.json [STATS.json ...] [--target 11.7]

Each STATS.json is `edrnr simulate -o DIR`'s DIR/stats.json of a run at
380 MHz with the preset (one per scene and view). The energy is linear in
the row's value: E_i(e) = E_i(e0) + (e - e0) * cycles_i / pixels_i / 1000
nJ/pixel at 1.21 V, so the value that makes the mean of the runs equal the
target is printed, with the runs' figures before and after.
"""
import argparse
import csv
import json
import os
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("stats", nargs="+")
    ap.add_argument("--target", type=float, default=11.7, help="nJ/pixel (Table I, 380 MHz)")
    ap.add_argument("--events", default=os.path.join(os.path.dirname(__file__), "..", "configs", "energy", "events.csv"))
    a = ap.parse_args()
    e0 = None
    with open(a.events) as f:
        for row in csv.reader(line for line in f if line.strip() and not line.startswith("#")):
            if row[0] == "core_cycle":
                e0 = float(row[1])
    if e0 is None:
        sys.exit(f"fit-core-cycle: no core_cycle row in {a.events}")
    runs = []
    for p in a.stats:
        d = json.load(open(p))["stats"]
        if abs(d["energy.voltage_V"]["value"] - 1.21) > 1e-9:
            sys.exit(f"fit-core-cycle: {p} is not at 1.21 V")
        runs.append((p, d["energy.nJ_per_pixel"]["value"], d["sim.cycles"]["value"] / d["sim.pixels"]["value"]))
    mean_e = sum(r[1] for r in runs) / len(runs)
    mean_cpp = sum(r[2] for r in runs) / len(runs)
    e = e0 + (a.target - mean_e) / (mean_cpp / 1000.0)
    print(f"core_cycle: {e0:.1f} pJ -> {e:.1f} pJ per cycle at 1.21 V (mean {mean_e:.3f} -> {a.target} nJ/pixel over {len(runs)} runs)")
    for p, nj, cpp in runs:
        print(f"  {p}: {nj:.3f} -> {nj + (e - e0) * cpp / 1000:.3f} nJ/pixel, {cpp:.3f} cycles/pixel")


if __name__ == "__main__":
    main()
