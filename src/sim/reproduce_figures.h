#pragma once
// The paper's tables and figures, measured on the runs of `edrnr reproduce`
// (docs/reproduction.md says what each measures and how).
//
// Each figure is a JSON object:
//   id           "table1", "table2", "fig3c", ... (its files are figures/<id>.png/.svg, <id>*.csv)
//   title        "Fig. 3(c): ..."
//   measures     what is measured and from which statistics
//   comparisons  [{quantity, scene ("all scenes" or a scene), ours, paper, ratio, unit}]
//   tables       [{name, title, columns, rows}]: the detail, every number also in a CSV
//   plot         what scripts/report_figures.py draws (figure-specific)
//   notes        sentences for every "all scenes" comparison more than 10 % from the paper's,
//                generated from the runs' counters
// Every per-view figure is computed from that view's runs, averaged over the
// views of a scene, then over the scenes.
#include <nlohmann/json.hpp>
#include <string>

#include "sim/reproduce_table.h"

namespace edrnr::sim {

struct FigureContext {
  double preset_clock_MHz = 380;  // the clock of the "full" runs
  double area_mm2 = 10.5;         // ours is the paper's die (Table II)
  double technology_nm = 40;
  bool quick = false;  // procedural scenes at low resolution: the paper's values are not comparable
};

// The paper's PSNR of a Synthetic-NeRF scene (Fig. 16), NaN for another name.
double paper_psnr_dB(const std::string& scene);

// The variant name of Table I's point at `clock_MHz`: "full" at the preset's clock.
std::string point_variant(double clock_MHz, const FigureContext& ctx);

nlohmann::json figure_table1(const RunTable& table, const FigureContext& ctx);
nlohmann::json figure_table2(const RunTable& table, const FigureContext& ctx);
nlohmann::json figure_fig3c(const RunTable& table);
nlohmann::json figure_fig4c(const RunTable& table);
nlohmann::json figure_fig5b(const RunTable& table);
nlohmann::json figure_fig6d(const RunTable& table);
nlohmann::json figure_fig7b(const RunTable& table);
nlohmann::json figure_fig8(const RunTable& table);
nlohmann::json figure_fig9(const RunTable& table);
nlohmann::json figure_fig16(const RunTable& table);
nlohmann::json figure_fig17c(const RunTable& table);

// All of them, in the order above.
nlohmann::json compute_figures(const RunTable& table, const FigureContext& ctx);

}  // namespace edrnr::sim
