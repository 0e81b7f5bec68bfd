// The paper's figures (3(c) to 17(c)) from the runs of `edrnr reproduce`.
#include "sim/reproduce_figures.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "chip/feature_cache.h"
#include "sim/reproduce_explain.h"

namespace edrnr::sim {

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
using Json = nlohmann::json;
using PerRun = std::function<double(const Json&)>;

// A figure computed from one variant's runs.
Averaged over(const RunTable& t, const std::string& variant, const PerRun& fn) {
  return average_over_views(
      t, [&](const std::string& s, int v) { return t.has(s, v, variant) ? fn(t.run(s, v, variant)) : kNaN; });
}
// A figure computed from two variants' runs of the same view.
Averaged over_pair(const RunTable& t, const std::string& a, const std::string& b,
                   const std::function<double(const Json&, const Json&)>& fn) {
  return average_over_views(t, [&](const std::string& s, int v) {
    return t.has(s, v, a) && t.has(s, v, b) ? fn(t.run(s, v, a), t.run(s, v, b)) : kNaN;
  });
}
PerRun stat(const std::string& name) {
  return [name](const Json& r) { return run_stat(r, name); };
}
double change_pct(double with, double without) { return without > 0 ? 100.0 * (with / without - 1.0) : kNaN; }

Json new_figure(const char* id, const char* title, const char* measures) {
  return {{"id", id},
          {"title", title},
          {"measures", measures},
          {"comparisons", Json::array()},
          {"tables", Json::array()},
          {"plot", Json::object()},
          {"notes", Json::array()}};
}

// A table with one row per scene and view: each column a per-run function of a list of variants' runs.
struct Column {
  std::string name;
  std::function<double(const RunTable&, const std::string&, int)> value;
};
Json per_view_table(const RunTable& t, const std::string& name, const std::string& title,
                    const std::vector<Column>& columns) {
  Json cols = {"scene", "view"}, rows = Json::array();
  for (const Column& c : columns) cols.push_back(c.name);
  for (const std::string& s : t.scenes())
    for (int v : t.views(s)) {
      Json row = {s, v};
      for (const Column& c : columns) row.push_back(number_or_null(c.value(t, s, v)));
      rows.push_back(row);
    }
  return {{"name", name}, {"title", title}, {"columns", cols}, {"rows", rows}};
}
Column stat_column(const std::string& name, const std::string& variant, const std::string& stat_name,
                   double scale = 1.0) {
  return {name, [=](const RunTable& t, const std::string& s, int v) {
            return t.has(s, v, variant) ? scale * run_stat_or_nan(t.run(s, v, variant), stat_name) : kNaN;
          }};
}

// Mean over every run of a variant of a stat ratio a/b ("per ray" figures in notes).
double mean_ratio(const RunTable& t, const std::string& variant, const std::string& a, const std::string& b) {
  return over(t, variant, [&](const Json& r) { return run_stat(r, a) / run_stat(r, b); }).mean;
}

Json scene_values(const Averaged& a) {
  Json j = {{"all scenes", number_or_null(a.mean)}};
  for (const auto& [s, v] : a.scenes) j[s] = number_or_null(v);
  return j;
}

}  // namespace

double paper_psnr_dB(const std::string& scene) {
  if (scene == "chair") return 30.96;
  if (scene == "lego") return 33.75;
  if (scene == "mic") return 34.09;
  if (scene == "hotdog") return 35.64;
  return kNaN;
}

Json figure_fig3c(const RunTable& t) {
  Json f = new_figure("fig3c", "Fig. 3(c): traversal load with and without the AABB",
                      "Coarse load: coarse bitmap checks of the CTU (chip.ctu.coarse_checks; one per LFAU iteration, "
                      "chip.ctu.iterations); fine load: fine bitmap checks of the FTU (chip.ftu.fine_checks). The full "
                      "design against the run with the AABB off (the traversal box is the whole scene box).");
  const double paper_coarse = -70.4, paper_fine = -26.0;
  const Averaged coarse = over_pair(t, "full", "off_aabb", [](const Json& on, const Json& off) {
    return change_pct(run_stat(on, "chip.ctu.coarse_checks"), run_stat(off, "chip.ctu.coarse_checks"));
  });
  const Averaged fine = over_pair(t, "full", "off_aabb", [](const Json& on, const Json& off) {
    return change_pct(run_stat(on, "chip.ftu.fine_checks"), run_stat(off, "chip.ftu.fine_checks"));
  });
  add_comparisons(f["comparisons"], "coarse load change with the AABB", coarse, paper_coarse, "%");
  add_comparisons(f["comparisons"], "fine load change with the AABB", fine, paper_fine, "%");
  f["tables"].push_back(per_view_table(t, "fig3c", "bitmap checks with and without the AABB",
                                       {stat_column("coarse_checks_with_aabb", "full", "chip.ctu.coarse_checks"),
                                        stat_column("coarse_checks_without", "off_aabb", "chip.ctu.coarse_checks"),
                                        stat_column("ctu_iterations_with_aabb", "full", "chip.ctu.iterations"),
                                        stat_column("ctu_iterations_without", "off_aabb", "chip.ctu.iterations"),
                                        stat_column("fine_checks_with_aabb", "full", "chip.ftu.fine_checks"),
                                        stat_column("fine_checks_without", "off_aabb", "chip.ftu.fine_checks")}));
  f["plot"] = {{"ours", {{"coarse", scene_values(coarse)}, {"fine", scene_values(fine)}}},
               {"paper", {{"coarse", paper_coarse}, {"fine", paper_fine}}}};
  const double dropped = mean_ratio(t, "full", "chip.abt.rays_dropped", "chip.zorg.rays");
  if (differs(coarse.mean, paper_coarse))
    f["notes"].push_back(fmt::format(
        "The coarse load changes by {:.1f} % against the paper's {:.1f} %: the ABT drops {:.1f} % of the rays "
        "(chip.abt.rays_dropped / chip.zorg.rays) and the CTU does {} coarse checks per ray with the AABB and {} "
        "without (chip.ctu.coarse_checks / chip.zorg.rays); the saving depends on how much of the scene box the "
        "object's box leaves out.",
        coarse.mean, paper_coarse, 100 * dropped,
        format_number(mean_ratio(t, "full", "chip.ctu.coarse_checks", "chip.zorg.rays")),
        format_number(mean_ratio(t, "off_aabb", "chip.ctu.coarse_checks", "chip.zorg.rays"))));
  if (differs(fine.mean, paper_fine))
    f["notes"].push_back(fmt::format(
        "The fine load changes by {:.1f} % against the paper's {:.1f} %: {} fine checks per ray with the AABB, {} "
        "without (chip.ftu.fine_checks / chip.zorg.rays); fine checks happen only in occupied coarse voxels, which "
        "the AABB trims only where it cuts through them.",
        fine.mean, paper_fine, format_number(mean_ratio(t, "full", "chip.ftu.fine_checks", "chip.zorg.rays")),
        format_number(mean_ratio(t, "off_aabb", "chip.ftu.fine_checks", "chip.zorg.rays"))));
  return f;
}

namespace {
// The DRAM data types of a run ("mem.<type>.read_bytes").
std::vector<std::string> data_types(const Json& run) {
  std::vector<std::string> out;
  for (auto it = run.at("stats").begin(); it != run.at("stats").end(); ++it) {
    const std::string& k = it.key();
    const std::string suffix = ".read_bytes";
    if (k.rfind("mem.", 0) == 0 && k.size() > 4 + suffix.size() &&
        k.compare(k.size() - suffix.size(), suffix.size(), suffix) == 0)
      out.push_back(k.substr(4, k.size() - 4 - suffix.size()));
  }
  return out;
}
}  // namespace

Json figure_fig4c(const RunTable& t) {
  Json f = new_figure("fig4c", "Fig. 4(c): external memory reads, row order against Z order",
                      "DRAM bytes read (dram.read_bytes, whole bursts), the full design (Z order) against the run "
                      "with ZORG in row order; by data type from mem.<type>.read_bytes.");
  const double paper = -65.4;
  const Averaged change = over_pair(t, "full", "off_zorder", [](const Json& on, const Json& off) {
    return change_pct(run_stat(on, "dram.read_bytes"), run_stat(off, "dram.read_bytes"));
  });
  add_comparisons(f["comparisons"], "DRAM bytes read, Z order against row order", change, paper, "%");
  const std::string& s0 = t.scenes().front();
  const std::vector<std::string> types = data_types(t.run(s0, t.views(s0).front(), "full"));
  std::vector<Column> cols = {stat_column("dram_read_MB_z_order", "full", "dram.read_bytes", 1e-6),
                              stat_column("dram_read_MB_row_order", "off_zorder", "dram.read_bytes", 1e-6)};
  Json plot_types = Json::array(), z = Json::array(), row = Json::array();
  std::string biggest;
  double biggest_delta = -1;
  for (const std::string& type : types) {
    const std::string name = "mem." + type + ".read_bytes";
    cols.push_back(stat_column(type + "_MB_z_order", "full", name, 1e-6));
    cols.push_back(stat_column(type + "_MB_row_order", "off_zorder", name, 1e-6));
    const double a = over(t, "full", stat(name)).mean / 1e6, b = over(t, "off_zorder", stat(name)).mean / 1e6;
    plot_types.push_back(type);
    z.push_back(number_or_null(a));
    row.push_back(number_or_null(b));
    if (b - a > biggest_delta) biggest_delta = b - a, biggest = type;
  }
  f["tables"].push_back(per_view_table(t, "fig4c", "DRAM MB read by data type", cols));
  f["plot"] = {{"types", plot_types},
               {"z_order_MB", z},
               {"row_order_MB", row},
               {"ours_change_pct", scene_values(change)},
               {"paper_change_pct", paper}};
  if (differs(change.mean, paper))
    f["notes"].push_back(fmt::format(
        "Z order changes the DRAM reads by {:.1f} % against the paper's {:.1f} %: most of the difference is {} "
        "(mem.{}.read_bytes: {} MB in row order, {} MB in Z order per frame); with row order the feature hit rate "
        "is {:.1f} % (Z order {:.1f} %) and the MLP hit rate {:.1f} % ({:.1f} %) (cache.features.hit_rate, "
        "cache.mlp.hit_rate).",
        change.mean, paper, biggest, biggest,
        format_number(over(t, "off_zorder", stat("mem." + biggest + ".read_bytes")).mean / 1e6),
        format_number(over(t, "full", stat("mem." + biggest + ".read_bytes")).mean / 1e6),
        100 * over(t, "off_zorder", stat("cache.features.hit_rate")).mean,
        100 * over(t, "full", stat("cache.features.hit_rate")).mean,
        100 * over(t, "off_zorder", stat("cache.mlp.hit_rate")).mean,
        100 * over(t, "full", stat("cache.mlp.hit_rate")).mean));
  return f;
}

Json figure_fig5b(const RunTable& t) {
  Json f = new_figure("fig5b", "Fig. 5(b): rays marching together per RP, coarse and fine",
                      "Rays the LFAU advances together per iteration (sim.coarse_rays_per_iteration = "
                      "chip.ctu rays advanced / iterations; sim.fine_rays_per_iteration for the FTU), with lag-first "
                      "(the full design) and without (the first live ray's voxel leads).");
  const double paper_coarse = 3.89, paper_fine = 3.48;
  const Averaged c_on = over(t, "full", stat("sim.coarse_rays_per_iteration")),
                 f_on = over(t, "full", stat("sim.fine_rays_per_iteration")),
                 c_off = over(t, "off_lagfirst", stat("sim.coarse_rays_per_iteration")),
                 f_off = over(t, "off_lagfirst", stat("sim.fine_rays_per_iteration"));
  add_comparisons(f["comparisons"], "coarse rays per iteration, lag-first", c_on, paper_coarse, "rays");
  add_comparisons(f["comparisons"], "fine rays per iteration, lag-first", f_on, paper_fine, "rays");
  add_comparisons(f["comparisons"], "coarse rays per iteration, without lag-first", c_off, kNaN, "rays");
  add_comparisons(f["comparisons"], "fine rays per iteration, without lag-first", f_off, kNaN, "rays");
  f["tables"].push_back(per_view_table(t, "fig5b", "rays advancing together per RP",
                                       {stat_column("coarse_lag_first", "full", "sim.coarse_rays_per_iteration"),
                                        stat_column("coarse_without", "off_lagfirst", "sim.coarse_rays_per_iteration"),
                                        stat_column("fine_lag_first", "full", "sim.fine_rays_per_iteration"),
                                        stat_column("fine_without", "off_lagfirst", "sim.fine_rays_per_iteration")}));
  f["plot"] = {{"ours",
                {{"coarse_lag_first", scene_values(c_on)},
                 {"coarse_without", scene_values(c_off)},
                 {"fine_lag_first", scene_values(f_on)},
                 {"fine_without", scene_values(f_off)}}},
               {"paper", {{"coarse_lag_first", paper_coarse}, {"fine_lag_first", paper_fine}}}};
  if (differs(c_on.mean, paper_coarse) || differs(f_on.mean, paper_fine)) {
    const double live = over(t, "full", [](const Json& r) {
                          const double rays = run_stat(r, "chip.zorg.rays") - run_stat(r, "chip.abt.rays_dropped") -
                                              run_stat(r, "chip.tsps.rays_dropped");
                          const double rps = run_stat(r, "chip.zorg.packets") - run_stat(r, "chip.packets_dropped");
                          return rps > 0 ? rays / rps : kNaN;
                        }).mean;
    f["notes"].push_back(fmt::format(
        "Our RPs advance {} rays together in coarse and {} in fine traversal (paper {} and {}): an RP enters "
        "traversal with {} live rays on average ((chip.zorg.rays - chip.abt.rays_dropped - chip.tsps.rays_dropped) / "
        "(chip.zorg.packets - chip.packets_dropped)), the bound on both; rays leave an RP when they terminate or exit "
        "the box (chip.vru.rays_terminated).",
        format_number(c_on.mean), format_number(f_on.mean), paper_coarse, paper_fine, format_number(live)));
  }
  return f;
}

Json figure_fig6d(const RunTable& t) {
  Json f = new_figure("fig6d", "Fig. 6(d): CCRPs per CV tag switch, with and without RP reordering",
                      "CCRPs the RP-ROB schedules per run of one CV tag (sim.rps_per_tag_switch = "
                      "chip.rp_rob.schedules / chip.rp_rob.tag_runs), the full design against the RP-ROB as a FIFO.");
  const double paper = 24.24;
  const Averaged gain = over_pair(t, "full", "off_reorder", [](const Json& on, const Json& off) {
    return run_stat(on, "sim.rps_per_tag_switch") / run_stat(off, "sim.rps_per_tag_switch");
  });
  const Averaged on = over(t, "full", stat("sim.rps_per_tag_switch")),
                 off = over(t, "off_reorder", stat("sim.rps_per_tag_switch"));
  add_comparisons(f["comparisons"], "CCRPs per tag switch, reordering on / off", gain, paper, "x");
  add_comparisons(f["comparisons"], "CCRPs per tag switch with reordering", on, kNaN, "CCRPs");
  add_comparisons(f["comparisons"], "CCRPs per tag switch without reordering", off, kNaN, "CCRPs");
  f["tables"].push_back(per_view_table(t, "fig6d", "CCRPs per CV tag switch",
                                       {stat_column("with_reordering", "full", "sim.rps_per_tag_switch"),
                                        stat_column("without", "off_reorder", "sim.rps_per_tag_switch"),
                                        stat_column("tag_runs_with", "full", "chip.rp_rob.tag_runs"),
                                        stat_column("tag_runs_without", "off_reorder", "chip.rp_rob.tag_runs"),
                                        stat_column("mlp_switches_with", "full", "sim.mlp_switches"),
                                        stat_column("mlp_switches_without", "off_reorder", "sim.mlp_switches")}));
  f["plot"] = {{"ours", {{"with", scene_values(on)}, {"without", scene_values(off)}, {"gain", scene_values(gain)}}},
               {"paper_gain", paper}};
  if (differs(gain.mean, paper))
    f["notes"].push_back(fmt::format(
        "Reordering multiplies the CCRPs per tag switch by {:.2f} against the paper's {:.2f}: {} per switch with it "
        "and {} without (sim.rps_per_tag_switch). The CCRPs of one tag are bounded by the RPs in flight: at most {} "
        "at once (chip.peak_rp_buffer); the recent-tags recorder chose the next tag {} times per tag switch "
        "(chip.rp_rob.recorder_hits / chip.rp_rob.tag_runs).",
        gain.mean, paper, format_number(on.mean), format_number(off.mean),
        format_number(over(t, "full", stat("chip.peak_rp_buffer")).mean),
        format_number(mean_ratio(t, "full", "chip.rp_rob.recorder_hits", "chip.rp_rob.tag_runs"))));
  return f;
}

Json figure_fig7b(const RunTable& t) {
  Json f = new_figure("fig7b", "Fig. 7(b): sample throughput with and without out-of-order issue",
                      "Samples per core cycle (sim.samples_per_cycle = chip.cfiu.samples / sim.cycles), the full "
                      "design against in-order issue.");
  const double paper = 8.45;
  const Averaged gain = over_pair(t, "full", "off_ooo", [](const Json& on, const Json& off) {
    return change_pct(run_stat(on, "sim.samples_per_cycle"), run_stat(off, "sim.samples_per_cycle"));
  });
  add_comparisons(f["comparisons"], "sample throughput gain from OoO issue", gain, paper, "%");
  add_comparisons(f["comparisons"], "samples per cycle, OoO issue", over(t, "full", stat("sim.samples_per_cycle")),
                  kNaN, "samples");
  add_comparisons(f["comparisons"], "samples per cycle, in order", over(t, "off_ooo", stat("sim.samples_per_cycle")),
                  kNaN, "samples");
  f["tables"].push_back(per_view_table(
      t, "fig7b", "samples per cycle",
      {stat_column("ooo", "full", "sim.samples_per_cycle"), stat_column("in_order", "off_ooo", "sim.samples_per_cycle"),
       stat_column("fill_waits_ooo", "full", "chip.ooo.fill_waits"),
       stat_column("fill_waits_in_order", "off_ooo", "chip.ooo.fill_waits")}));
  f["plot"] = {{"ours",
                {{"ooo", scene_values(over(t, "full", stat("sim.samples_per_cycle")))},
                 {"in_order", scene_values(over(t, "off_ooo", stat("sim.samples_per_cycle")))},
                 {"gain_pct", scene_values(gain)}}},
               {"paper_gain_pct", paper}};
  if (differs(gain.mean, paper)) {
    const RunProfile p = profile_runs(t, "off_ooo");
    f["notes"].push_back(fmt::format(
        "OoO issue gains {:.2f} % sample throughput against the paper's {:.2f} %: it issues {:.1f} % of the batches "
        "out of order (chip.ooo.issued_out_of_order / chip.ooo.issued), and in order the issue waits for a feature "
        "block {} times per frame against {} (chip.ooo.fill_waits); in order, the {} waits for memory {:.1f} % of "
        "the cycles (sim.unit.{}.stall_memory_cycles), which OoO issue can hide only where features are the wait.",
        gain.mean, paper, 100 * mean_ratio(t, "full", "chip.ooo.issued_out_of_order", "chip.ooo.issued"),
        format_number(over(t, "off_ooo", stat("chip.ooo.fill_waits")).mean),
        format_number(over(t, "full", stat("chip.ooo.fill_waits")).mean), p.top_memory_unit,
        100 * p.top_memory_unit_share, p.top_memory_unit));
  }
  return f;
}

Json figure_fig8(const RunTable& t) {
  Json f = new_figure(
      "fig8", "Fig. 8: cache hit rates over time and in steady state",
      "Hit rates of the full design: micro-grid words read by the FTU (cache.micro_grid.hit_rate); feature "
      "blocks and MLPs per sample access (cache.features.per_access.hit_rate, cache.mlp.per_access.hit_rate: a batch "
      "that misses is one miss and n - 1 hits) and per batch (cache.features.hit_rate, cache.mlp.hit_rate). The "
      "curves are SimResult::hit_rate_series of each scene's first view (window: hit_rate_series.*.window_cycles).");
  struct Rate {
    const char* quantity;
    const char* stat;
    double paper;
  };
  const Rate rates[] = {{"micro-grid hit rate", "cache.micro_grid.hit_rate", 96.27},
                        {"feature hit rate, per access", "cache.features.per_access.hit_rate", 98.65},
                        {"MLP hit rate, per access", "cache.mlp.per_access.hit_rate", 96.38},
                        {"feature hit rate, per batch", "cache.features.hit_rate", 98.65},
                        {"MLP hit rate, per batch", "cache.mlp.hit_rate", 96.38}};
  std::vector<Column> cols;
  for (const Rate& r : rates) {
    const std::string name = r.stat;
    const Averaged a = over(t, "full", [&](const Json& run) { return 100 * run_stat(run, name); });
    add_comparisons(f["comparisons"], r.quantity, a, r.paper, "%");
    cols.push_back(stat_column(name, "full", name, 100.0));
    if (!differs(a.mean, r.paper)) continue;
    std::string why;
    if (name.find("micro_grid") != std::string::npos)
      why = fmt::format(
          "the FTU reads {} micro-grid words per frame (chip.ftu.micro_word_reads) and the {}-byte "
          "cache misses {} of them (cache.micro_grid.misses)",
          format_number(over(t, "full", stat("chip.ftu.micro_word_reads")).mean),
          format_number(over(t, "full", stat("cache.micro_grid.size_bytes")).mean),
          format_number(over(t, "full", stat("cache.micro_grid.misses")).mean));
    else if (name.find("features") != std::string::npos)
      why = fmt::format(
          "the feature cache holds {} blocks (chip.feature_cache.lines) and fetches {} per frame "
          "(cache.features.misses_issued) for {} block requests (cache.features.accesses)",
          format_number(over(t, "full", stat("chip.feature_cache.lines")).mean),
          format_number(over(t, "full", stat("cache.features.misses_issued")).mean),
          format_number(over(t, "full", stat("cache.features.accesses")).mean));
    else
      why = fmt::format(
          "the TME switches MLP {} times per frame (sim.mlp_switches) for {} batches (cache.mlp.batches); "
          "an MLP is {} bytes (chip.tme.mlp_bytes) and the MLP cache {} bytes "
          "(cache.mlp_weights.size_bytes)",
          format_number(over(t, "full", stat("sim.mlp_switches")).mean),
          format_number(over(t, "full", stat("cache.mlp.batches")).mean),
          format_number(over(t, "full", stat("chip.tme.mlp_bytes")).mean),
          format_number(over(t, "full", stat("cache.mlp_weights.size_bytes")).mean));
    f["notes"].push_back(
        fmt::format("The {} is {:.2f} % against the paper's {:.2f} %: {}.", r.quantity, a.mean, r.paper, why));
  }
  f["tables"].push_back(per_view_table(t, "fig8", "hit rates of the full design, %", cols));
  // Curves: each scene's first view.
  Json series = Json::object();
  for (const char* cache : {"micro_grid", "features", "mlp_weights"})
    for (const std::string& s : t.scenes()) {
      const Json& h = t.run(s, t.views(s).front(), "full").at("hit_rate_series");
      if (!h.contains(cache)) continue;
      Json cycles = Json::array(), rate = Json::array();
      for (const Json& w : h.at(cache).at("windows")) {
        cycles.push_back(w.at("start_cycle"));
        rate.push_back(w.at("hit_rate").is_null() ? Json(nullptr) : Json(100 * w.at("hit_rate").get<double>()));
      }
      series[cache][s] = {
          {"start_cycle", cycles}, {"hit_rate_pct", rate}, {"window_cycles", h.at(cache).at("window_cycles")}};
    }
  f["plot"] = {{"series", series}, {"paper_pct", {{"micro_grid", 96.27}, {"features", 98.65}, {"mlp_weights", 96.38}}}};
  return f;
}

Json figure_fig9(const RunTable& t) {
  Json f = new_figure("fig9", "Fig. 9(b)/(c): feature vectors per bank, direct and balanced mapping",
                      "Rows each of the 8 feature banks needs to hold the whole feature cache "
                      "(chip.feature_cache.bank<b>_depth), per cached fine-voxel block (/ chip.feature_cache.lines), "
                      "with the direct vertex-ID-to-bank mapping (balanced off) and the balanced one (the full "
                      "design). The paper's (b): a 5x5x5 block by vertex ID, 27/18/18/18/12/12/12/8; (c): uniform.");
  // Vertices of a 5x5x5 block by vertex ID (x + 2y + 4z of the corner parity).
  const std::vector<double> paper_direct = {27, 18, 18, 12, 18, 12, 12, 8};
  const double paper_mean = 125.0 / 8;
  auto depths = [](const Json& r) {
    std::vector<double> d;
    const double lines = run_stat(r, "chip.feature_cache.lines");
    for (int b = 0; b < chip::kFeatureBanks; ++b)
      d.push_back(run_stat(r, "chip.feature_cache.bank" + std::to_string(b) + "_depth") / lines);
    return d;
  };
  auto imbalance = [&](const Json& r) {
    const std::vector<double> d = depths(r);
    double sum = 0;
    for (double x : d) sum += x;
    return *std::max_element(d.begin(), d.end()) / (sum / double(d.size()));
  };
  const Averaged direct = over(t, "off_balanced", imbalance), balanced = over(t, "full", imbalance);
  add_comparisons(f["comparisons"], "largest / mean bank depth, direct", direct, 27.0 / paper_mean, "x");
  add_comparisons(f["comparisons"], "largest / mean bank depth, balanced", balanced, 1.0, "x");
  add_comparisons(f["comparisons"], "bank conflict cycles, balanced",
                  over(t, "full", stat("cache.features.bank_conflict_cycles")), kNaN, "cycles");
  Json cols = {"scene",
               "bank",
               "direct_rows_per_block",
               "balanced_rows_per_block",
               "paper_direct_rows_per_block",
               "direct_depth_rows",
               "balanced_depth_rows"};
  Json rows = Json::array(), plot_scenes = Json::object();
  for (const std::string& s : t.scenes()) {
    const int v = t.views(s).front();
    const Json &on = t.run(s, v, "full"), &off = t.run(s, v, "off_balanced");
    const std::vector<double> a = depths(off), b = depths(on);
    for (int k = 0; k < chip::kFeatureBanks; ++k)
      rows.push_back({s, k, a[size_t(k)], b[size_t(k)], paper_direct[size_t(k)],
                      run_stat(off, "chip.feature_cache.bank" + std::to_string(k) + "_depth"),
                      run_stat(on, "chip.feature_cache.bank" + std::to_string(k) + "_depth")});
    plot_scenes[s] = {{"direct", a}, {"balanced", b}};
  }
  f["tables"].push_back(
      {{"name", "fig9"}, {"title", "bank depths (first view of each scene)"}, {"columns", cols}, {"rows", rows}});
  f["plot"] = {
      {"scenes", plot_scenes}, {"paper_direct", paper_direct}, {"paper_balanced", std::vector<double>(8, paper_mean)}};
  if (differs(direct.mean, 27.0 / paper_mean) || differs(balanced.mean, 1.0))
    f["notes"].push_back(fmt::format(
        "Our largest bank is {:.3f}x the mean with the direct mapping and {:.3f}x with the balanced one (paper "
        "{:.3f}x and 1x): the balanced layout rotates the mapping over groups of 8 blocks, so a cache of {} lines "
        "(chip.feature_cache.lines) evens out only over whole groups.",
        direct.mean, balanced.mean, 27.0 / paper_mean,
        format_number(over(t, "full", stat("chip.feature_cache.lines")).mean)));
  return f;
}

Json figure_fig16(const RunTable& t) {
  Json f = new_figure("fig16", "Fig. 16: rendered images beside the ground truth",
                      "The full design's image of each view (runs/<key>.png) beside the dataset's test view "
                      "composited on the chip's background (ground_truth/), with the PSNR the run measured "
                      "(quality.psnr_vs_ground_truth). Every variant of a view must render the same image: the "
                      "image hashes of all its runs are compared.");
  const Averaged ours =
      over(t, "full", [](const Json& r) { return run_stat_or_nan(r, "quality.psnr_vs_ground_truth"); });
  double paper_sum = 0;
  int paper_n = 0;
  for (const std::string& s : t.scenes())
    if (std::isfinite(paper_psnr_dB(s))) paper_sum += paper_psnr_dB(s), ++paper_n;
  f["comparisons"].push_back(comparison("PSNR", "all scenes", ours.mean, paper_n ? paper_sum / paper_n : kNaN, "dB"));
  for (const auto& [s, v] : ours.scenes) f["comparisons"].push_back(comparison("PSNR", s, v, paper_psnr_dB(s), "dB"));

  Json rows = Json::array(), images = Json::array();
  size_t differing_views = 0, views = 0;
  for (const std::string& s : t.scenes())
    for (int v : t.views(s)) {
      const Json& full = t.run(s, v, "full");
      std::set<std::string> hashes;
      std::string first_other;
      for (const std::string& variant : t.variants(s, v)) {
        const std::string h = t.run(s, v, variant).at("image").at("hash");
        if (h != full.at("image").at("hash") && first_other.empty()) first_other = variant;
        hashes.insert(h);
      }
      ++views;
      if (hashes.size() > 1) ++differing_views;
      const double p = run_stat_or_nan(full, "quality.psnr_vs_ground_truth");
      rows.push_back({s, v, number_or_null(p), number_or_null(paper_psnr_dB(s)), t.variants(s, v).size(),
                      hashes.size() == 1 ? "yes" : "no (" + first_other + " differs)"});
      images.push_back(
          {{"scene", s},
           {"view", v},
           {"image", "runs/" + full.at("image").at("file").get<std::string>()},
           {"ground_truth", std::isfinite(p) ? Json(fmt::format("ground_truth/{}_view{}.png", s, v)) : Json(nullptr)},
           {"psnr_dB", number_or_null(p)},
           {"paper_psnr_dB", number_or_null(paper_psnr_dB(s))}});
    }
  f["tables"].push_back({{"name", "fig16"},
                         {"title", "PSNR of the full design's image; the same image in every variant"},
                         {"columns", {"scene", "view", "psnr_dB", "paper_psnr_dB", "variants", "identical_image"}},
                         {"rows", rows}});
  f["plot"] = {{"images", images}};
  if (differing_views)
    f["notes"].push_back(
        fmt::format("In {} of {} views a variant renders another image than the full design "
                    "(image.hash of the runs): a scheduling technique changed pixels, which the "
                    "design forbids.",
                    differing_views, views));
  for (const auto& [s, v] : ours.scenes)
    if (differs(v, paper_psnr_dB(s)))
      f["notes"].push_back(fmt::format(
          "{}: {:.2f} dB against the paper's {:.2f} dB. The PSNR is the trained model's ({}), not the schedule's: "
          "{}.",
          s, v, paper_psnr_dB(s), t.run(s, t.views(s).front(), "full").value("model", "?"),
          differing_views ? "but see the note on differing images"
                          : fmt::format("every view renders the same image in all {} variants (image.hash)",
                                        t.variants(s, t.views(s).front()).size())));
  return f;
}

Json figure_fig17c(const RunTable& t) {
  Json f = new_figure(
      "fig17c", "Fig. 17(c): throughput gained by the techniques",
      "FPS of the full design over FPS with all six techniques off (sim.fps). Each technique's share: the "
      "logarithm of its gain alone (FPS all on / FPS with only it off), over the sum of those logarithms; the "
      "stacked bar splits the total gain above 1x in those shares.");
  const double paper_total = 6.95, paper_zorg_ooo = 45.76;
  const Averaged total = over_pair(t, "full", "all_off", [](const Json& on, const Json& off) {
    return run_stat(on, "sim.fps") / run_stat(off, "sim.fps");
  });
  const std::vector<std::string>& techs = technique_names();
  // Per view: the shares of every technique.
  auto shares = [&](const std::string& s, int v) {
    std::vector<double> logs;
    double sum = 0;
    const double on = run_stat(t.run(s, v, "full"), "sim.fps");
    for (const std::string& k : techs) {
      const double g = on / run_stat(t.run(s, v, "off_" + k), "sim.fps");
      logs.push_back(std::max(0.0, std::log(g)));
      sum += logs.back();
    }
    for (double& x : logs) x = sum > 0 ? 100 * x / sum : 0.0;
    return logs;
  };
  const Averaged zorg_ooo = average_over_views(t, [&](const std::string& s, int v) {
    const std::vector<double> sh = shares(s, v);
    return sh[0] + sh[4];  // zorder, ooo
  });
  add_comparisons(f["comparisons"], "throughput gain, all techniques", total, paper_total, "x");
  add_comparisons(f["comparisons"], "share of ZORG and OoO-SI", zorg_ooo, paper_zorg_ooo, "%");
  Json rows = Json::array(), segments = Json::array();
  std::string largest;
  double largest_gain = 0;
  for (size_t i = 0; i < techs.size(); ++i) {
    const Averaged fps_off = over(t, "off_" + techs[i], stat("sim.fps"));
    const Averaged gain = over_pair(t, "full", "off_" + techs[i], [](const Json& on, const Json& off) {
      return run_stat(on, "sim.fps") / run_stat(off, "sim.fps");
    });
    const Averaged share = average_over_views(t, [&](const std::string& s, int v) { return shares(s, v)[i]; });
    rows.push_back({techs[i], technique_label(techs[i]), number_or_null(fps_off.mean), number_or_null(gain.mean),
                    number_or_null(share.mean)});
    if (gain.mean > largest_gain) largest_gain = gain.mean, largest = techs[i];
    Json seg = {{"technique", techs[i]}, {"label", technique_label(techs[i])}, {"share_pct", scene_values(share)}};
    segments.push_back(seg);
  }
  rows.push_back({"all", "all six off", number_or_null(over(t, "all_off", stat("sim.fps")).mean),
                  number_or_null(total.mean), 100.0});
  f["tables"].push_back({{"name", "fig17c"},
                         {"title", "FPS with each technique off alone, gain and share (all scenes)"},
                         {"columns", {"technique", "unit", "fps_off", "gain_alone", "share_pct"}},
                         {"rows", rows}});
  f["plot"] = {{"total_gain", scene_values(total)},
               {"segments", segments},
               {"full_fps", scene_values(over(t, "full", stat("sim.fps")))},
               {"paper", {{"total_gain", paper_total}, {"zorg_ooo_share_pct", paper_zorg_ooo}}}};
  if (differs(total.mean, paper_total))
    f["notes"].push_back(
        fmt::format("All six techniques together gain {:.2f}x against the paper's {:.2f}x. With "
                    "them all off, {}. With them on, {}.",
                    total.mean, paper_total, describe_cycles(profile_runs(t, "all_off")),
                    describe_cycles(profile_runs(t, "full"))));
  if (differs(zorg_ooo.mean, paper_zorg_ooo))
    f["notes"].push_back(fmt::format(
        "ZORG and OoO-SI take {:.1f} % of the gain against the paper's {:.2f} %: alone, row order costs {:.2f}x and "
        "in-order issue {:.2f}x (sim.fps), while the largest single loss is {} ({:.2f}x).",
        zorg_ooo.mean, paper_zorg_ooo, rows[0][3].is_null() ? kNaN : rows[0][3].get<double>(),
        rows[4][3].is_null() ? kNaN : rows[4][3].get<double>(), technique_label(largest), largest_gain));
  return f;
}

Json compute_figures(const RunTable& t, const FigureContext& ctx) {
  return Json::array({figure_table1(t, ctx), figure_table2(t, ctx), figure_fig3c(t), figure_fig4c(t), figure_fig5b(t),
                      figure_fig6d(t), figure_fig7b(t), figure_fig8(t), figure_fig9(t), figure_fig16(t),
                      figure_fig17c(t)});
}

}  // namespace edrnr::sim
