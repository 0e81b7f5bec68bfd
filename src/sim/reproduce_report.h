#pragma once
// The files of an `edrnr reproduce` report (docs/reproduction.md):
//   results.json      every number: settings, scenes covered and skipped, the
//                     simulations, one entry per run (figures copied from its
//                     JSON), and the figures of reproduce_figures.h
//   comparisons.csv   every figure beside the paper's value and the ratio
//   runs.csv          one row per run
//   <table>.csv       each figure's detail tables (table1.csv, fig3c.csv, ...)
//   report.md         the report for people; figures/<id>.png where drawn
// (report.html and the figures are drawn by scripts/report_figures.py from
// results.json.) Every file is written atomically.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "sim/reproduce_runs.h"
#include "sim/reproduce_table.h"

namespace edrnr::sim {

struct ReportSettings {
  bool quick = false;
  std::string chip_preset;  // the preset file
  double clock_MHz = 0;     // the preset's clock
  std::string command_line;
  std::vector<std::pair<std::string, std::string>> skipped;  // scene, why
};

// results.json's content (see the top of this file).
nlohmann::json build_results(const ReportSettings& settings, const std::vector<ReproScene>& scenes,
                             const RunTable& table, const ExecuteSummary& simulations, const nlohmann::json& figures);

// Writes results.json and the CSV files into out_dir; returns their paths.
std::vector<std::filesystem::path> write_results(const std::filesystem::path& out_dir, const nlohmann::json& results);

// The Markdown report; a figure's image is linked when
// out_dir/figures/<id>.png exists.
std::string markdown_report(const nlohmann::json& results, const std::filesystem::path& out_dir);

// One CSV field: quoted when it holds a comma, quote or line break.
std::string csv_field(const nlohmann::json& value);

}  // namespace edrnr::sim
