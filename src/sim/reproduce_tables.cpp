// Table I (operating points, SRAM) and Table II (comparison with other designs).
#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "sim/energy.h"
#include "sim/reproduce_explain.h"
#include "sim/reproduce_figures.h"
#include "sim/sram_budget.h"

namespace edrnr::sim {

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();

double energy_at_point(const nlohmann::json& run, const char* field) {
  auto it = run.find("energy_table1");
  if (it == run.end() || !it->contains(field)) return kNaN;
  return (*it)[field].get<double>();
}

// Table I's on-chip SRAM, in KB (1024 bytes), by class.
struct PaperSram {
  const char* sram_class;
  double KB;
};
constexpr PaperSram kPaperSram[] = {{"micro_grid", 8}, {"feature", 256}, {"mlp", 8.25}, {"others", 43.2}};

// Table II of the paper, one column per design; NaN where the paper gives none.
struct PaperDesign {
  const char* name;
  double technology_nm, fps, area_mm2, max_voltage_V, max_frequency_MHz, onchip_KB, throughput_MPps, throughput_per_mm2,
      power_W, nJ_per_pixel, norm_fps_per_W, norm_fps_per_mm2;
};
const PaperDesign kPaperDesigns[] = {
    {"[27]", 12, 2.9, kNaN, kNaN, 1400, kNaN, 1.86, kNaN, 15, kNaN, kNaN, kNaN},
    {"[28]", 5, 75.6, kNaN, kNaN, 2500, kNaN, 48.38, kNaN, 350, kNaN, kNaN, kNaN},
    {"[7]", 28, 110, 20.25, 0.95, 250, 2015, 1.44, 0.03, 0.90, 544.4, 36.92, 1.864},
    {"[20]", 28, 30.6, 5.07, 1.0, 200, 360, 19.58, 3.86, 0.13, 6.6, 78.77, 2.07},
    {"[6]", 28, 73.5, 20.25, 0.9, 200, 2112, 47.04, 2.32, 0.73, 15.5, 27.29, 1.253},
    {"[9]", 28, 120, 15, 0.9, 300, 2560, 76.8, 5.12, 1.9, 25, 24.46, 2.74},
    {"[8]", 40, 131, 19.38, 0.9, 400, 677.3, 83.84, 4.33, 1.30, 15.51, 55.58, 6.76},
    {"EDR-NR (paper)", 40, 85.9, 10.5, 1.21, 380, 315.5, 54.98, 5.23, 0.64, 11.7, 134.22, 8.18},
};

// Footnote 1 of Table II: s = technology / 40 nm, f ~ s, A ~ 1/s^2,
// P ~ (1/s) (1.21 V / V)^2, at the maximum rendering speed.
double normalised_fps_per_W(double tech_nm, double fps, double power_W, double voltage_V) {
  const double s = tech_nm / 40.0;
  return (fps * s) / (power_W / s * std::pow(1.21 / voltage_V, 2));
}
double normalised_fps_per_mm2(double tech_nm, double fps, double area_mm2) {
  const double s = tech_nm / 40.0;
  return (fps * s) / (area_mm2 / (s * s));
}

}  // namespace

std::string point_variant(double clock_MHz, const FigureContext& ctx) {
  if (std::abs(clock_MHz - ctx.preset_clock_MHz) < 1e-9) return "full";
  return RunVariant{RunVariant::Kind::OperatingPoint, "", clock_MHz}.name();
}

nlohmann::json figure_table1(const RunTable& table, const FigureContext& ctx) {
  nlohmann::json f;
  f["id"] = "table1";
  f["title"] = "Table I: power, frame rate and energy at the five operating points; on-chip SRAM";
  f["measures"] =
      "Each operating point is simulated at its own core clock (the DRAM keeps its clock), and its event counts "
      "are priced at the point's voltage (energy_table1 of the run: average_power_W, nJ_per_pixel); FPS is the "
      "run's sim.fps. SRAM: every buffer the simulator models, summed per Table I class (the run's sram_budget).";
  nlohmann::json comparisons = nlohmann::json::array(), rows = nlohmann::json::array(), notes = nlohmann::json::array();
  nlohmann::json plot = {{"clock_MHz", nlohmann::json::array()},
                         {"paper",
                          {{"fps", nlohmann::json::array()},
                           {"power_mW", nlohmann::json::array()},
                           {"nJ_per_pixel", nlohmann::json::array()}}},
                         {"ours", nlohmann::json::object()}};
  std::map<double, std::array<Averaged, 3>> at;  // clock -> fps, mW, nJ/px
  for (const PaperOperatingPoint& p : table1_operating_points()) {
    const double mhz = p.point.frequency_MHz;
    const std::string variant = point_variant(mhz, ctx);
    auto per = [&](auto fn) {
      return average_over_views(table, [&](const std::string& s, int v) {
        return table.has(s, v, variant) ? fn(table.run(s, v, variant)) : kNaN;
      });
    };
    const Averaged fps = per([](const nlohmann::json& r) { return run_stat(r, "sim.fps"); });
    const Averaged mw = per([](const nlohmann::json& r) { return 1e3 * energy_at_point(r, "average_power_W"); });
    const Averaged nj = per([](const nlohmann::json& r) { return energy_at_point(r, "nJ_per_pixel"); });
    at[mhz] = {fps, mw, nj};
    add_comparisons(comparisons, fmt::format("FPS at {:g} MHz", mhz), fps, p.fps, "frames/s");
    add_comparisons(comparisons, fmt::format("power at {:g} MHz", mhz), mw, p.power_mW, "mW");
    add_comparisons(comparisons, fmt::format("energy at {:g} MHz", mhz), nj, p.nJ_per_pixel, "nJ/pixel");
    auto row = [&](const std::string& scene, double a, double b, double c) {
      rows.push_back({mhz, p.point.voltage_V, scene, number_or_null(a), p.fps, number_or_null(a / p.fps),
                      number_or_null(b), p.power_mW, number_or_null(b / p.power_mW), number_or_null(c), p.nJ_per_pixel,
                      number_or_null(c / p.nJ_per_pixel)});
    };
    row("all scenes", fps.mean, mw.mean, nj.mean);
    for (const std::string& s : table.scenes()) row(s, fps.scenes.at(s), mw.scenes.at(s), nj.scenes.at(s));
    plot["clock_MHz"].push_back(mhz);
    plot["paper"]["fps"].push_back(p.fps);
    plot["paper"]["power_mW"].push_back(p.power_mW);
    plot["paper"]["nJ_per_pixel"].push_back(p.nJ_per_pixel);
    auto push = [&](const std::string& scene, double a, double b, double c) {
      nlohmann::json& o = plot["ours"][scene];
      o["fps"].push_back(number_or_null(a));
      o["power_mW"].push_back(number_or_null(b));
      o["nJ_per_pixel"].push_back(number_or_null(c));
    };
    push("all scenes", fps.mean, mw.mean, nj.mean);
    for (const std::string& s : table.scenes()) push(s, fps.scenes.at(s), mw.scenes.at(s), nj.scenes.at(s));
  }

  // Notes: the fastest and the slowest point, and how FPS scales between them.
  const auto& points = table1_operating_points();
  const PaperOperatingPoint &lo = points.front(), &hi = points.back();
  const std::array<Averaged, 3>&a_lo = at[lo.point.frequency_MHz], &a_hi = at[hi.point.frequency_MHz];
  const std::string v_hi = point_variant(hi.point.frequency_MHz, ctx),
                    v_lo = point_variant(lo.point.frequency_MHz, ctx);
  if (differs(a_hi[0].mean, hi.fps))
    notes.push_back(fmt::format("FPS at {:g} MHz is {} against the paper's {} ({:.2f}x): {}.", hi.point.frequency_MHz,
                                format_number(a_hi[0].mean), hi.fps, a_hi[0].mean / hi.fps,
                                describe_cycles(profile_runs(table, v_hi))));
  const double ours_scaling = a_hi[0].mean / a_lo[0].mean, paper_scaling = hi.fps / lo.fps;
  if (differs(ours_scaling, paper_scaling)) {
    const RunProfile plo = profile_runs(table, v_lo), phi = profile_runs(table, v_hi);
    notes.push_back(fmt::format(
        "From {:g} to {:g} MHz our FPS grows {:.2f}x against the paper's {:.2f}x: the {} waits for memory {:.1f} % of "
        "the cycles at {:g} MHz and {:.1f} % at {:g} MHz (sim.unit.*.stall_memory_cycles), because the DRAM keeps "
        "its own clock while the core's rises.",
        lo.point.frequency_MHz, hi.point.frequency_MHz, ours_scaling, paper_scaling, phi.top_memory_unit,
        100 * phi.top_memory_unit_share, hi.point.frequency_MHz, 100 * plo.top_memory_unit_share,
        lo.point.frequency_MHz));
  }
  if (differs(a_hi[1].mean, hi.power_mW) || differs(a_hi[2].mean, hi.nJ_per_pixel))
    notes.push_back(
        fmt::format("At {:g} MHz our power is {} mW ({:.2f}x the paper's) and our energy {} nJ/pixel "
                    "({:.2f}x): {}.",
                    hi.point.frequency_MHz, format_number(a_hi[1].mean), a_hi[1].mean / hi.power_mW,
                    format_number(a_hi[2].mean), a_hi[2].mean / hi.nJ_per_pixel, describe_energy(table, v_hi)));
  if (differs(a_lo[2].mean, lo.nJ_per_pixel))
    notes.push_back(fmt::format("At {:g} MHz / {:g} V our energy is {} nJ/pixel against the paper's {}: {}.",
                                lo.point.frequency_MHz, lo.point.voltage_V, format_number(a_lo[2].mean),
                                lo.nJ_per_pixel, describe_energy(table, v_lo)));

  // SRAM by class, per scene (the sizes follow the model's shape), from the first view's full run.
  nlohmann::json sram_rows = nlohmann::json::array();
  std::map<std::string, Averaged> sram;
  for (const PaperSram& ps : kPaperSram) {
    const Averaged kb = average_over_views(table, [&](const std::string& s, int v) {
      const nlohmann::json& b = table.run(s, v, "full").at("sram_budget");
      return b.at("classes").at(ps.sram_class).at("bytes").get<double>() / 1024.0;
    });
    sram[ps.sram_class] = kb;
    add_comparisons(comparisons, fmt::format("SRAM {}", ps.sram_class), kb, ps.KB, "KB");
    for (const std::string& s : table.scenes()) {
      const nlohmann::json& c =
          table.run(s, table.views(s).front(), "full").at("sram_budget").at("classes").at(ps.sram_class);
      const double ours = c.at("bytes").get<double>() / 1024.0, budget = c.at("budget_bytes").get<double>() / 1024.0;
      sram_rows.push_back({s, ps.sram_class, ours, budget, ps.KB, ours / ps.KB, ours <= budget ? "yes" : "no"});
    }
    if (differs(kb.mean, ps.KB)) {
      // The largest buffers of the class, from the first scene's budget.
      const std::string& s0 = table.scenes().front();
      const nlohmann::json& buffers = table.run(s0, table.views(s0).front(), "full").at("sram_budget").at("buffers");
      std::vector<std::pair<double, std::string>> b;
      for (const nlohmann::json& x : buffers)
        if (x.at("class") == ps.sram_class) b.push_back({x.at("bytes").get<double>(), x.at("name").get<std::string>()});
      std::sort(b.rbegin(), b.rend());
      std::string largest;
      for (size_t i = 0; i < b.size() && i < 3; ++i)
        largest += fmt::format("{}{} ({} KB)", i ? ", " : "", b[i].second, format_number(b[i].first / 1024));
      notes.push_back(
          fmt::format("Our {} SRAM is {} KB against the paper's {} KB: the simulator's buffers of the "
                      "class are {} (sram_budget of the run; sram.*_bytes).",
                      ps.sram_class, format_number(kb.mean), ps.KB, largest.empty() ? "none" : largest));
    }
  }
  f["comparisons"] = comparisons;
  f["tables"] = {{{"name", "table1"},
                  {"title", "operating points (each simulated at its clock)"},
                  {"columns",
                   {"clock_MHz", "voltage_V", "scene", "fps", "paper_fps", "fps_ratio", "power_mW", "paper_power_mW",
                    "power_ratio", "nJ_per_pixel", "paper_nJ_per_pixel", "nJ_per_pixel_ratio"}},
                  {"rows", rows}},
                 {{"name", "table1_sram"},
                  {"title", "on-chip SRAM by Table I class"},
                  {"columns", {"scene", "class", "ours_KB", "budget_KB", "paper_KB", "ratio", "fits_budget"}},
                  {"rows", sram_rows}}};
  f["plot"] = plot;
  f["notes"] = notes;
  return f;
}

nlohmann::json figure_table2(const RunTable& table, const FigureContext& ctx) {
  nlohmann::json f;
  f["id"] = "table2";
  f["title"] = "Table II: comparison with other designs, normalised to 40 nm and 1.21 V";
  f["measures"] =
      "Our column: the full design at the preset clock (mean FPS and power over scenes and views), the paper's "
      "10.5 mm2 die, the voltage of Table I's point at that clock. Normalised as footnote 1: s = technology / 40 nm, "
      "f ~ s, A ~ 1/s^2, P ~ (1/s) (1.21 V / V)^2; energy efficiency FPS/W and area efficiency FPS/mm2 at the "
      "maximum rendering speed. The 'by footnote 1' rows recompute each design's normalised figures from its "
      "other columns.";
  auto full = [&](auto fn) {
    return average_over_views(table, [&](const std::string& s, int v) { return fn(table.run(s, v, "full")); });
  };
  const Averaged fps = full([](const nlohmann::json& r) { return run_stat(r, "sim.fps"); });
  const Averaged power_W = full([](const nlohmann::json& r) { return energy_at_point(r, "average_power_W"); });
  const Averaged nj = full([](const nlohmann::json& r) { return energy_at_point(r, "nJ_per_pixel"); });
  const Averaged voltage = full([](const nlohmann::json& r) { return energy_at_point(r, "voltage_V"); });
  const Averaged pixels = full([](const nlohmann::json& r) { return run_stat(r, "sim.pixels"); });
  const Averaged sram_KB =
      full([](const nlohmann::json& r) { return r.at("sram_budget").at("total_bytes").get<double>() / 1024.0; });
  const double V = std::isfinite(voltage.mean) ? voltage.mean : 1.21;
  PaperDesign ours{"ours",
                   ctx.technology_nm,
                   fps.mean,
                   ctx.area_mm2,
                   V,
                   ctx.preset_clock_MHz,
                   sram_KB.mean,
                   fps.mean * pixels.mean / 1e6,
                   fps.mean * pixels.mean / 1e6 / ctx.area_mm2,
                   power_W.mean,
                   nj.mean,
                   normalised_fps_per_W(ctx.technology_nm, fps.mean, power_W.mean, V),
                   normalised_fps_per_mm2(ctx.technology_nm, fps.mean, ctx.area_mm2)};

  struct Quantity {
    const char* name;
    const char* unit;
    double PaperDesign::*field;
  };
  const Quantity quantities[] = {
      {"technology", "nm", &PaperDesign::technology_nm},
      {"rendering speed", "FPS", &PaperDesign::fps},
      {"area", "mm2", &PaperDesign::area_mm2},
      {"voltage at max speed", "V", &PaperDesign::max_voltage_V},
      {"max frequency", "MHz", &PaperDesign::max_frequency_MHz},
      {"on-chip memory", "KB", &PaperDesign::onchip_KB},
      {"max throughput", "Mpixel/s", &PaperDesign::throughput_MPps},
      {"throughput per area", "Mpixel/s/mm2", &PaperDesign::throughput_per_mm2},
      {"power", "W", &PaperDesign::power_W},
      {"energy efficiency", "nJ/pixel", &PaperDesign::nJ_per_pixel},
      {"normalised energy efficiency", "FPS/W", &PaperDesign::norm_fps_per_W},
      {"normalised area efficiency", "FPS/mm2", &PaperDesign::norm_fps_per_mm2},
  };
  nlohmann::json columns = {"quantity", "unit"};
  for (const PaperDesign& d : kPaperDesigns) columns.push_back(d.name);
  columns.push_back("ours");
  columns.push_back("ours / EDR-NR (paper)");
  const PaperDesign& paper = kPaperDesigns[std::size(kPaperDesigns) - 1];
  nlohmann::json rows = nlohmann::json::array(), comparisons = nlohmann::json::array();
  for (const Quantity& q : quantities) {
    nlohmann::json row = {q.name, q.unit};
    for (const PaperDesign& d : kPaperDesigns) row.push_back(number_or_null(d.*q.field));
    row.push_back(number_or_null(ours.*q.field));
    row.push_back(number_or_null(ours.*q.field / (paper.*q.field)));
    rows.push_back(row);
    if (q.field != &PaperDesign::technology_nm && q.field != &PaperDesign::area_mm2)
      comparisons.push_back(comparison(q.name, "all scenes", ours.*q.field, paper.*q.field, q.unit));
  }
  // The normalised figures recomputed by footnote 1 from each design's own columns.
  nlohmann::json ee = {"normalised energy efficiency, by footnote 1", "FPS/W"},
                 ae = {"normalised area efficiency, by footnote 1", "FPS/mm2"};
  for (const PaperDesign& d : kPaperDesigns) {
    ee.push_back(number_or_null(normalised_fps_per_W(d.technology_nm, d.fps, d.power_W, d.max_voltage_V)));
    ae.push_back(number_or_null(normalised_fps_per_mm2(d.technology_nm, d.fps, d.area_mm2)));
  }
  ee.push_back(number_or_null(ours.norm_fps_per_W));
  ee.push_back(number_or_null(ours.norm_fps_per_W / paper.norm_fps_per_W));
  ae.push_back(number_or_null(ours.norm_fps_per_mm2));
  ae.push_back(number_or_null(ours.norm_fps_per_mm2 / paper.norm_fps_per_mm2));
  rows.push_back(ee);
  rows.push_back(ae);

  nlohmann::json notes = nlohmann::json::array();
  if (ctx.quick)
    notes.push_back(
        "These --quick runs render procedural scenes at a low resolution: their FPS and power are not "
        "comparable with the paper's 800x800 figures.");
  if (differs(ours.norm_fps_per_W, paper.norm_fps_per_W))
    notes.push_back(
        fmt::format("Our normalised energy efficiency is {} FPS/W against the paper's {} ({:.2f}x): at "
                    "40 nm and {:g} V it is our FPS ({}, {:.2f}x the paper's) over our power ({} W, "
                    "{:.2f}x); {}.",
                    format_number(ours.norm_fps_per_W), paper.norm_fps_per_W,
                    ours.norm_fps_per_W / paper.norm_fps_per_W, V, format_number(ours.fps), ours.fps / paper.fps,
                    format_number(ours.power_W), ours.power_W / paper.power_W, describe_energy(table, "full")));
  if (differs(ours.norm_fps_per_mm2, paper.norm_fps_per_mm2))
    notes.push_back(
        fmt::format("Our normalised area efficiency is {} FPS/mm2 against the paper's {}: the area is the "
                    "paper's {} mm2, so it follows our FPS alone: {}.",
                    format_number(ours.norm_fps_per_mm2), paper.norm_fps_per_mm2, ctx.area_mm2,
                    describe_cycles(profile_runs(table, "full"))));
  f["comparisons"] = comparisons;
  f["tables"] = {{{"name", "table2"}, {"title", "Table II with our column"}, {"columns", columns}, {"rows", rows}}};
  f["plot"] = {{"designs", nlohmann::json::array()}};
  for (const PaperDesign& d : kPaperDesigns)
    f["plot"]["designs"].push_back({{"name", d.name},
                                    {"norm_fps_per_W", number_or_null(d.norm_fps_per_W)},
                                    {"norm_fps_per_mm2", number_or_null(d.norm_fps_per_mm2)}});
  f["plot"]["designs"].push_back({{"name", "ours"},
                                  {"norm_fps_per_W", number_or_null(ours.norm_fps_per_W)},
                                  {"norm_fps_per_mm2", number_or_null(ours.norm_fps_per_mm2)}});
  f["notes"] = notes;
  return f;
}

}  // namespace edrnr::sim
