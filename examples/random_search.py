# %% [markdown]
# # Random search over EDR-NR designs with the Python API
#
# A notebook-style script (cells marked `# %%`, so Jupyter, VS Code or plain
# `python3` run it): a small random search over chip parameters with
# `edrnr.step`, the Pareto front of frame rate, energy per pixel and on-chip
# SRAM, and a plot of it with the paper's design marked.
#
#     PYTHONPATH=build/python python3 examples/random_search.py --samples 24 --out search-out
#
# It needs the module built (the normal CMake build makes build/python/edrnr*.so)
# and python3-numpy and python3-matplotlib.

# %%
import argparse
import csv
import os
import random

import edrnr

ap = argparse.ArgumentParser(description="random search over EDR-NR chip designs")
ap.add_argument("--samples", type=int, default=16, help="design points to simulate")
ap.add_argument("--seed", type=int, default=1)
ap.add_argument("--model", default=None, help="a .edrnr model (default: a procedural sphere)")
ap.add_argument("--width", type=int, default=48, help="image width and height")
ap.add_argument("--out", default="random-search-out", help="folder for front.csv and front.png")
args, _ = ap.parse_known_args()  # tolerate a notebook kernel's own arguments

# %% The scene, the view and the search space.
model = edrnr.load_model(args.model) if args.model else edrnr.make_scene("sphere", res=64, channels=8)
camera = edrnr.orbit_camera(args.width, azimuth=30, elevation=30)
space = {
    "rp_rob.entries": [4, 8, 16, 32],
    "rp_buffer_capacity": [32, 48, 64],
    "ooo_queue_depth": [8, 16, 32],
    "simulator.clock_MHz": [50, 100, 200, 300, 380],
    "simulator.timing.tme.macs_per_cycle": [256, 512, 1024, 2048],
}

# %% Search: each step() simulates one frame and returns the metrics as a dict.
rng = random.Random(args.seed)
results = []
paper = edrnr.step({}, model, camera)  # the preset as shipped: the paper's design
paper["config"] = {}
for i in range(args.samples):
    config = {k: rng.choice(v) for k, v in space.items()}
    m = edrnr.step(config, model, camera)
    m["config"] = config
    results.append(m)
    state = f"{m['fps']:9.1f} FPS {m['nJ_per_pixel']:7.2f} nJ/px" if m["status"] == "ok" else "error: " + m["error"]
    print(f"{i:3d} {config} -> {state}")

# %% The Pareto front: no other design at least as fast, as frugal and as small, and better in one.
ok = [r for r in results + [paper] if r["status"] == "ok"]


def dominates(a, b):
    no_worse = a["fps"] >= b["fps"] and a["nJ_per_pixel"] <= b["nJ_per_pixel"] and a["sram_total_bytes"] <= b["sram_total_bytes"]
    better = a["fps"] > b["fps"] or a["nJ_per_pixel"] < b["nJ_per_pixel"] or a["sram_total_bytes"] < b["sram_total_bytes"]
    return no_worse and better


front = [r for r in ok if not any(dominates(o, r) for o in ok)]
front.sort(key=lambda r: -r["fps"])
os.makedirs(args.out, exist_ok=True)
with open(os.path.join(args.out, "front.csv"), "w", newline="", encoding="utf-8") as f:
    w = csv.writer(f)
    w.writerow(list(space) + ["fps", "nJ_per_pixel", "sram_total_bytes", "paper_design"])
    for r in front:
        w.writerow([r["config"].get(k, "") for k in space] + [r["fps"], r["nJ_per_pixel"], r["sram_total_bytes"], int(r is paper)])
print(f"{len(front)} of {len(ok)} designs on the front: {args.out}/front.csv")

# %% Plot: FPS against nJ/pixel, SRAM as colour, the front outlined, the paper's design a star.
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(6.5, 4.5))
sc = ax.scatter([r["fps"] for r in ok], [r["nJ_per_pixel"] for r in ok], c=[r["sram_total_bytes"] / 1024 for r in ok], cmap="viridis", s=22)
fig.colorbar(sc, ax=ax, label="on-chip SRAM (KB)")
ax.plot([r["fps"] for r in front], [r["nJ_per_pixel"] for r in front], "o", mfc="none", mec="red", ms=9, label="Pareto front")
ax.scatter([paper["fps"]], [paper["nJ_per_pixel"]], marker="*", s=250, color="orange", edgecolors="black", zorder=5, label="paper design (edr_nr_40nm)")
ax.set_xlabel("frame rate (FPS)")
ax.set_ylabel("energy (nJ/pixel)")
ax.set_title(f"random search, {len(ok)} designs")
ax.grid(alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(args.out, "front.png"), dpi=110)
print(f"plot: {args.out}/front.png")
