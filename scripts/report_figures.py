#!/usr/bin/env python3
"""Draws the figures of an `edrnr reproduce` report and writes report.html.

usage: report_figures.py OUT/results.json [--no-figures]
       report_figures.py --check

Reads results.json (written by `edrnr reproduce`, docs/reproduction.md) and
writes, beside it:
  figures/<id>.png and figures/<id>.svg   one per table or figure that has a plot
  report.html                             self-contained: the figures inlined as PNG

Needs only the standard library for report.html and matplotlib (Debian's
python3-matplotlib) for the figures. Exit status: 0 when everything was
written; 3 when matplotlib is missing (report.html is written without
figures); 1 on a bad results.json. Every file is written atomically.
--check writes nothing: exit status 0 when matplotlib can be imported, 3 when not.
"""
import base64
import html
import json
import math
import os
import sys
import tempfile

NO_MATPLOTLIB = 3


def public_mode():
    """The mode a new file gets under the process umask (mkstemp makes 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic(path, data):
    """Writes bytes or text to a temporary file beside `path` and renames it over `path`."""
    d = os.path.dirname(path) or "."
    fd, tmp = tempfile.mkstemp(prefix=os.path.basename(path) + ".tmp.", dir=d)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
        os.chmod(tmp, public_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def fmt_number(v, ratio=False):
    """Numbers for people, as the Markdown report writes them."""
    if v is None:
        return "–"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return str(v)
    if not math.isfinite(v):
        return "n/a"
    if ratio:
        return "%.2f" % v
    a = abs(v)
    if a >= 1000 or (a < 1e15 and v == math.floor(v)):
        return "%.0f" % v
    if a >= 100:
        return "%.1f" % v
    if a >= 10:
        return "%.2f" % v
    if a >= 0.01 or a == 0:
        return "%.3f" % v
    return "%.3g" % v


def is_ratio_column(name):
    return name == "ratio" or name.endswith("ratio") or " / " in name


def scene_names(results):
    return [s["name"] for s in results["scenes"]]


def val(x):
    return float("nan") if x is None else x


# ----------------------------------------------------------------- figures


def draw_figures(results, out_dir):
    """Draws every figure; returns {id: [png path, svg path]}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 9, "axes.grid": True, "grid.alpha": 0.3, "svg.hashsalt": "edrnr"})
    scenes = scene_names(results)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig_dir = os.path.join(out_dir, "figures")
    os.makedirs(fig_dir, exist_ok=True)
    written = {}

    def save(fig, fid):
        paths = []
        for ext in ("png", "svg"):
            path = os.path.join(fig_dir, fid + "." + ext)
            fd, tmp = tempfile.mkstemp(prefix=fid + ".tmp.", suffix="." + ext, dir=fig_dir)
            os.close(fd)
            fig.savefig(tmp, dpi=110, bbox_inches="tight", metadata={"Date": None} if ext == "svg" else None)
            os.chmod(tmp, public_mode())
            os.replace(tmp, path)
            paths.append(path)
        plt.close(fig)
        written[fid] = paths

    def bars_vs_paper(ax, labels, ours_by_scene, paper, unit, title):
        """Grouped bars: each label's value for all scenes and each scene; the paper's as a black tick."""
        groups = ["all scenes"] + scenes
        width = 0.8 / len(groups)
        for gi, g in enumerate(groups):
            xs = [i + (gi - (len(groups) - 1) / 2) * width for i in range(len(labels))]
            ys = [val(ours_by_scene[l].get(g)) for l in labels]
            ax.bar(xs, ys, width, label="ours, " + g, color=colours[gi % len(colours)], alpha=1.0 if gi == 0 else 0.6)
        for i, l in enumerate(labels):
            if paper.get(l) is not None:
                ax.hlines(paper[l], i - 0.45, i + 0.45, colors="black", linewidth=2,
                          label="paper" if i == 0 else None)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels)
        ax.set_ylabel(unit)
        ax.set_title(title)
        ax.legend(fontsize=7)

    by_id = {f["id"]: f for f in results["figures"]}

    if "table1" in by_id:
        p = by_id["table1"]["plot"]
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
        for ax, key, unit in zip(axes, ("fps", "power_mW", "nJ_per_pixel"), ("frames/s", "mW", "nJ/pixel")):
            ax.plot(p["clock_MHz"], p["paper"][key], "k-o", label="paper")
            for i, (name, series) in enumerate(p["ours"].items()):
                ax.plot(p["clock_MHz"], [val(v) for v in series[key]], "-s" if i == 0 else "--.",
                        color=colours[i % len(colours)], linewidth=2 if i == 0 else 1, label="ours, " + name)
            ax.set_xlabel("core clock [MHz]")
            ax.set_ylabel(unit)
            ax.legend(fontsize=7)
        fig.suptitle("Table I: the five operating points, ours against the paper")
        save(fig, "table1")

    if "table2" in by_id:
        designs = by_id["table2"]["plot"]["designs"]
        fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
        for ax, key, unit in zip(axes, ("norm_fps_per_W", "norm_fps_per_mm2"), ("FPS/W", "FPS/mm²")):
            names = [d["name"] for d in designs if d[key] is not None]
            ys = [d[key] for d in designs if d[key] is not None]
            cs = ["tab:red" if n == "ours" else ("tab:blue" if "EDR-NR" in n else "tab:gray") for n in names]
            ax.bar(names, ys, color=cs)
            ax.set_ylabel(unit + " (normalised to 40 nm, 1.21 V)")
            ax.tick_params(axis="x", rotation=30)
        axes[0].set_title("normalised energy efficiency")
        axes[1].set_title("normalised area efficiency")
        save(fig, "table2")

    if "fig3c" in by_id:
        p = by_id["fig3c"]["plot"]
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars_vs_paper(ax, ["coarse", "fine"], p["ours"], p["paper"], "load change with the AABB [%]",
                      "Fig. 3(c): traversal load, AABB on against off")
        save(fig, "fig3c")

    if "fig4c" in by_id:
        p = by_id["fig4c"]["plot"]
        fig, ax = plt.subplots(figsize=(6, 3.8))
        bottom = [0.0, 0.0]
        for i, t in enumerate(p["types"]):
            ys = [val(p["row_order_MB"][i]), val(p["z_order_MB"][i])]
            ax.bar(["row order", "Z order"], ys, bottom=bottom, label=t, color=colours[i % len(colours)])
            bottom = [b + (y if math.isfinite(y) else 0) for b, y in zip(bottom, ys)]
        ours = p["ours_change_pct"]["all scenes"]
        ax.set_title("Fig. 4(c): DRAM reads per frame: %s %% (paper %s %%)" % (fmt_number(ours), p["paper_change_pct"]))
        ax.set_ylabel("MB read (mean of scenes and views)")
        ax.legend(fontsize=7)
        save(fig, "fig4c")

    if "fig5b" in by_id:
        p = by_id["fig5b"]["plot"]
        labels = ["coarse_lag_first", "coarse_without", "fine_lag_first", "fine_without"]
        fig, ax = plt.subplots(figsize=(7, 3.6))
        bars_vs_paper(ax, labels, p["ours"], p["paper"], "rays advancing together per RP",
                      "Fig. 5(b): rays marching together, with and without lag-first")
        ax.set_xticklabels(["coarse\nlag-first", "coarse\nwithout", "fine\nlag-first", "fine\nwithout"])
        ax.set_ylim(0, 4.2)
        save(fig, "fig5b")

    if "fig6d" in by_id:
        p = by_id["fig6d"]["plot"]
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars_vs_paper(ax, ["with", "without"], p["ours"], {}, "CCRPs per CV tag switch",
                      "Fig. 6(d): reordering gains %sx (paper %sx)"
                      % (fmt_number(p["ours"]["gain"]["all scenes"]), p["paper_gain"]))
        ax.set_xticklabels(["with reordering", "without (FIFO)"])
        save(fig, "fig6d")

    if "fig7b" in by_id:
        p = by_id["fig7b"]["plot"]
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars_vs_paper(ax, ["in_order", "ooo"], p["ours"], {}, "samples per cycle",
                      "Fig. 7(b): OoO issue gains %s %% (paper +%s %%)"
                      % (fmt_number(p["ours"]["gain_pct"]["all scenes"]), p["paper_gain_pct"]))
        ax.set_xticklabels(["in-order issue", "OoO issue"])
        save(fig, "fig7b")

    if "fig8" in by_id:
        p = by_id["fig8"]["plot"]
        names = [("micro_grid", "(a) micro-grid bitmap"), ("features", "(b) feature vectors (per batch)"),
                 ("mlp_weights", "(c) MLP weights (per batch)")]
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
        for ax, (key, title) in zip(axes, names):
            for i, (scene, s) in enumerate(p["series"].get(key, {}).items()):
                xs = [c / 1e6 for c in s["start_cycle"]]
                ys = [val(v) for v in s["hit_rate_pct"]]
                ax.plot(xs, ys, color=colours[i % len(colours)], linewidth=1, label=scene)
            ax.axhline(p["paper_pct"][key], color="black", linestyle="--", label="paper, steady state")
            ax.set_title(title)
            ax.set_xlabel("cycle [M]")
            ax.set_ylabel("hit rate [%]")
            ax.legend(fontsize=7)
        fig.suptitle("Fig. 8: cache hit rates over the frame (first view of each scene)")
        save(fig, "fig8")

    if "fig9" in by_id:
        p = by_id["fig9"]["plot"]
        fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), sharey=True)
        for ax, key, paper_key, title in ((axes[0], "direct", "paper_direct", "(b) direct mapping"),
                                          (axes[1], "balanced", "paper_balanced", "(c) balanced mapping")):
            n = len(p["scenes"]) or 1
            width = 0.8 / n
            for i, (scene, d) in enumerate(p["scenes"].items()):
                xs = [b + (i - (n - 1) / 2) * width for b in range(8)]
                ax.bar(xs, d[key], width, label="ours, " + scene, color=colours[i % len(colours)])
            ax.plot(range(8), p[paper_key], "k_", markersize=18, markeredgewidth=2, label="paper")
            ax.set_xticks(range(8))
            ax.set_xlabel("feature bank (vertex ID)")
            ax.set_title(title)
            ax.legend(fontsize=7)
        axes[0].set_ylabel("feature vectors per fine voxel")
        fig.suptitle("Fig. 9: feature vectors per bank")
        save(fig, "fig9")

    if "fig16" in by_id:
        import matplotlib.image as mpimg

        images = by_id["fig16"]["plot"]["images"]
        if images:
            has_gt = any(im["ground_truth"] for im in images)
            cols = 2 if has_gt else 1
            rows = len(images)
            per_row = min(rows, 3)
            grid_rows = math.ceil(rows / per_row)
            fig, axes = plt.subplots(grid_rows, per_row * cols, figsize=(2.4 * per_row * cols, 2.6 * grid_rows),
                                     squeeze=False)
            for ax in axes.flat:
                ax.axis("off")
            for k, im in enumerate(images):
                r, c = divmod(k, per_row)
                ours = mpimg.imread(os.path.join(out_dir, im["image"]))
                if has_gt and im["ground_truth"]:
                    gt = mpimg.imread(os.path.join(out_dir, im["ground_truth"]))
                    axes[r][c * cols].imshow(gt)
                    axes[r][c * cols].set_title("%s view %d: ground truth" % (im["scene"], im["view"]), fontsize=7)
                ax = axes[r][c * cols + cols - 1]
                ax.imshow(ours)
                title = "%s view %d: ours" % (im["scene"], im["view"])
                if im["psnr_dB"] is not None:
                    title += "\n%.2f dB" % im["psnr_dB"]
                    if im["paper_psnr_dB"] is not None:
                        title += " (paper %.2f)" % im["paper_psnr_dB"]
                ax.set_title(title, fontsize=7)
            fig.suptitle("Fig. 16: the simulated chip's images")
            save(fig, "fig16")

    if "fig17c" in by_id:
        p = by_id["fig17c"]["plot"]
        groups = ["all scenes"] + scenes
        fig, ax = plt.subplots(figsize=(8, 4))
        xs = list(range(len(groups))) + [len(groups)]
        for gi, g in enumerate(groups):
            total = val(p["total_gain"].get(g))
            base = 1.0
            ax.bar(gi, 1.0, color="lightgray", label="1x (all off)" if gi == 0 else None)
            for si, seg in enumerate(p["segments"]):
                h = val(seg["share_pct"].get(g)) / 100 * (total - 1)
                if not math.isfinite(h):
                    continue
                ax.bar(gi, h, bottom=base, color=colours[si % len(colours)], label=seg["label"] if gi == 0 else None)
                base += h
        pt = p["paper"]["total_gain"]
        share = p["paper"]["zorg_ooo_share_pct"] / 100
        ax.bar(len(groups), 1.0, color="lightgray")
        ax.bar(len(groups), share * (pt - 1), bottom=1.0, color="black", label="paper: ZORG + OoO-SI")
        ax.bar(len(groups), (1 - share) * (pt - 1), bottom=1.0 + share * (pt - 1), color="darkgray",
               label="paper: the others")
        ax.set_xticks(xs)
        ax.set_xticklabels(["ours, " + g for g in groups] + ["paper"])
        ax.set_ylabel("throughput, all on / all off [x]")
        ax.set_title("Fig. 17(c): throughput gained by the techniques")
        ax.legend(fontsize=7, bbox_to_anchor=(1.02, 1), loc="upper left")
        save(fig, "fig17c")

    return written


# ----------------------------------------------------------------- HTML


def html_table(columns, rows):
    out = ["<table><thead><tr>"]
    out += ["<th>%s</th>" % html.escape(str(c)) for c in columns]
    out.append("</tr></thead><tbody>")
    for row in rows:
        out.append("<tr>")
        for i, v in enumerate(row):
            ratio = i < len(columns) and is_ratio_column(str(columns[i]))
            cls = ' class="num"' if isinstance(v, (int, float)) and not isinstance(v, bool) else ""
            out.append("<td%s>%s</td>" % (cls, html.escape(fmt_number(v, ratio))))
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


STYLE = """
body { font-family: sans-serif; max-width: 1200px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #f0f0f0; }
img { max-width: 100%; }
.note { background: #fff8e0; padding: 0.3em 0.6em; }
details { margin: 0.5em 0; }
"""


def write_html(results, out_dir, figures):
    quick = results["mode"] == "quick"
    h = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>EDR-NR reproduction report</title>",
         "<style>%s</style></head><body>" % STYLE, "<h1>EDR-NR reproduction report</h1>"]
    intro = "Made by <code>%s</code> with the chip preset <code>%s</code> (%g MHz). " % (
        html.escape(results["command"]), html.escape(results["chip_preset"]), results["clock_MHz"])
    if quick:
        intro += ("<b>Quick mode</b>: procedural scenes at a low resolution with orbit cameras and no ground truth; "
                  "the paper's numbers are for the Synthetic-NeRF scenes at 800x800, so the ratios only show that "
                  "every figure is computed. ")
    intro += "Every number is also in <code>results.json</code> and the CSV files beside this page."
    h.append("<p>%s</p>" % intro)
    covered = "; ".join("%s (views %s, %dx%d, model <code>%s</code>)" % (
        html.escape(s["name"]), " ".join(str(v) for v in s["views"]), s["width"], s["height"],
        html.escape(s["model"])) for s in results["scenes"])
    h.append("<p><b>Scenes covered:</b> %s.</p>" % covered)
    if results["skipped"]:
        h.append("<p><b>Skipped:</b></p><ul>%s</ul>" % "".join(
            "<li>%s: %s</li>" % (html.escape(s["name"]), html.escape(s["reason"])) for s in results["skipped"]))
    sims = results["simulations"]
    h.append("<p><b>Simulations:</b> %d distinct, %d cached from an earlier run, %d run now in %.0f s.</p>" % (
        sims["distinct"], sims["cached"], sims["ran"], sims["seconds"]))
    if not figures:
        h.append("<p class='note'>No figures: matplotlib (python3-matplotlib) was not available.</p>")
    h.append("<p>Each figure is computed per view from that view's runs, then averaged over the views of a scene "
             "and over the scenes (\"all scenes\"). The ratio is ours / the paper's. Where a figure differs from "
             "the paper's by more than 10 %, a note says why, from the runs' own counters.</p>")
    h.append("<h2>Summary</h2>")
    rows = []
    for f in results["figures"]:
        for c in f["comparisons"]:
            if c["scene"] == "all scenes" and c["paper"] is not None:
                rows.append([f["id"], c["quantity"], c["ours"], c["paper"], c["ratio"], c["unit"]])
    h.append(html_table(["figure", "quantity", "ours", "paper", "ratio", "unit"], rows))
    for f in results["figures"]:
        h.append("<h2 id='%s'>%s</h2><p>%s</p>" % (f["id"], html.escape(f["title"]), html.escape(f["measures"])))
        if f["id"] in figures:
            with open(figures[f["id"]][0], "rb") as img:
                data = base64.b64encode(img.read()).decode("ascii")
            h.append("<img alt='%s' src='data:image/png;base64,%s'>" % (html.escape(f["title"]), data))
        rows = [[c["quantity"], c["scene"], c["ours"], c["paper"], c["ratio"], c["unit"]] for c in f["comparisons"]]
        h.append(html_table(["quantity", "scene", "ours", "paper", "ratio", "unit"], rows))
        if f["notes"]:
            h.append("<p><b>Why it differs:</b></p><ul>%s</ul>" % "".join(
                "<li class='note'>%s</li>" % html.escape(n) for n in f["notes"]))
        for t in f["tables"]:
            h.append("<details><summary>%s (<code>%s.csv</code>)</summary>%s</details>" % (
                html.escape(t["title"]), html.escape(t["name"]), html_table(t["columns"], t["rows"])))
    h.append("</body></html>\n")
    write_atomic(os.path.join(out_dir, "report.html"), "\n".join(h))


def main(argv):
    args = [a for a in argv[1:] if not a.startswith("--")]
    flags = [a for a in argv[1:] if a.startswith("--")]
    if flags == ["--check"] and not args:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            return NO_MATPLOTLIB
        return 0
    if len(args) != 1 or any(f not in ("--no-figures",) for f in flags):
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 1
    path = args[0]
    try:
        with open(path, encoding="utf-8") as f:
            results = json.load(f)
        if results.get("format") != "edrnr-reproduce-results-1":
            raise ValueError("not an edrnr reproduce results file (format %r)" % results.get("format"))
    except (OSError, ValueError) as e:
        print("report_figures.py: %s: %s" % (path, e), file=sys.stderr)
        return 1
    out_dir = os.path.dirname(os.path.abspath(path))
    figures = {}
    status = 0
    if "--no-figures" not in flags:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print("report_figures.py: matplotlib is not installed (Debian: apt-get install python3-matplotlib); "
                  "writing report.html without figures", file=sys.stderr)
            status = NO_MATPLOTLIB
        else:
            figures = draw_figures(results, out_dir)
    write_html(results, out_dir, figures)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv))
