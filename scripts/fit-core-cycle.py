#!/usr/bin/env python3
"""Fits the energy table's `core_cycle` row (docs/energy.md, "Calibration")
to Table I's power at 380 MHz / 1.21 V, 643.5 mW.

    scripts/fit-core-cycle.py STATS.json [STATS.json ...] [--target-mW 643.5]

Each STATS.json is `edrnr simulate -o DIR`'s DIR/stats.json of a run at
380 MHz with the preset (one per scene and view). The power is linear in the
row's value: P_i(e) = P_i(e0) + (e - e0) * cycles_i * fps_i / 1e9 mW at
1.21 V (cycles_i * fps_i is the clock), so the value that makes the mean
power of the runs equal the target is printed, with the runs' power and
energy per pixel before and after.

The row is fitted to power, not to energy per pixel: it is an energy per
clock cycle, so at a fixed clock the power it implies is the same however
fast a scene renders, while the energy per pixel also follows the frame
rate, which depends on the scene's model.
"""
import argparse
import csv
import json
import os
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("stats", nargs="+")
    ap.add_argument("--target-mW", dest="target", type=float, default=643.5, help="mW (Table I, 380 MHz)")
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
        try:
            d = json.load(open(p))["stats"]
            if abs(d["energy.voltage_V"]["value"] - 1.21) > 1e-9:
                sys.exit(f"fit-core-cycle: {p} is not at 1.21 V")
            nj = d["energy.nJ_per_pixel"]["value"]
            pixels = d["sim.pixels"]["value"]
            fps = d["sim.fps"]["value"]
            cycles = d["sim.cycles"]["value"]
        except (OSError, ValueError, KeyError) as e:
            sys.exit(f"fit-core-cycle: {p}: not a simulator statistics file ({e})")
        runs.append((p, nj, nj * pixels * fps / 1e6, cycles * fps / 1e9, cycles / pixels))
    mean_p = sum(r[2] for r in runs) / len(runs)
    mean_k = sum(r[3] for r in runs) / len(runs)
    e = e0 + (a.target - mean_p) / mean_k
    print(f"core_cycle: {e0:.1f} pJ -> {e:.1f} pJ per cycle at 1.21 V (mean power {mean_p:.1f} -> {a.target} mW over {len(runs)} runs)")
    for p, nj, mw, k, cpp in runs:
        print(f"  {p}: {mw:.1f} -> {mw + (e - e0) * k:.1f} mW, {nj:.3f} -> {nj + (e - e0) * cpp / 1000:.3f} nJ/pixel")


if __name__ == "__main__":
    main()
