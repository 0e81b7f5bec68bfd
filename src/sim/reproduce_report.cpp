#include "sim/reproduce_report.h"

#include <fmt/format.h>

#include <cmath>

#include "core/error.h"
#include "core/file_io.h"
#include "sim/reproduce_explain.h"

namespace edrnr::sim {

namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

constexpr const char* kResultsFormat = "edrnr-reproduce-results-1";

Json energy_value(const Json& run, const char* report, const char* field) {
  auto it = run.find(report);
  if (it == run.end() || !it->is_object() || !it->contains(field)) return nullptr;
  return (*it)[field];
}

// A cell for people: numbers to 3 significant digits (ratios to 2 decimals), null as a dash.
std::string cell(const Json& v, bool ratio = false) {
  if (v.is_null()) return "–";
  if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
  if (v.is_number()) return ratio ? fmt::format("{:.2f}", v.get<double>()) : format_number(v.get<double>());
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

bool is_ratio_column(const std::string& name) {
  return name == "ratio" || (name.size() >= 5 && name.compare(name.size() - 5, 5, "ratio") == 0) ||
         name.find(" / ") != std::string::npos;
}

std::string markdown_table(const Json& columns, const Json& rows) {
  std::string s = "|";
  for (const Json& c : columns) s.append(" ").append(c.get<std::string>()).append(" |");
  s += "\n|";
  for (size_t i = 0; i < columns.size(); ++i) s += "---|";
  s += "\n";
  for (const Json& row : rows) {
    s += "|";
    for (size_t i = 0; i < row.size(); ++i)
      s.append(" ")
          .append(cell(row[i], i < columns.size() && is_ratio_column(columns[i].get<std::string>())))
          .append(" |");
    s += "\n";
  }
  return s;
}

std::string csv_text(const Json& columns, const Json& rows) {
  std::string s;
  for (size_t i = 0; i < columns.size(); ++i) s.append(i ? "," : "").append(csv_field(columns[i]));
  s += "\n";
  for (const Json& row : rows) {
    for (size_t i = 0; i < row.size(); ++i) s.append(i ? "," : "").append(csv_field(row[i]));
    s += "\n";
  }
  return s;
}

const Json kComparisonColumns = {"figure", "quantity", "scene", "ours", "paper", "ratio", "unit"};

Json comparison_rows(const Json& results, bool all_scenes_only) {
  Json rows = Json::array();
  for (const Json& f : results.at("figures"))
    for (const Json& c : f.at("comparisons")) {
      if (all_scenes_only && c.at("scene") != "all scenes") continue;
      rows.push_back(
          {f.at("id"), c.at("quantity"), c.at("scene"), c.at("ours"), c.at("paper"), c.at("ratio"), c.at("unit")});
    }
  return rows;
}

}  // namespace

std::string csv_field(const Json& v) {
  if (v.is_null()) return "";
  if (!v.is_string()) return v.dump();
  const std::string s = v.get<std::string>();
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

Json build_results(const ReportSettings& settings, const std::vector<ReproScene>& scenes, const RunTable& table,
                   const ExecuteSummary& simulations, const Json& figures) {
  Json j;
  j["format"] = kResultsFormat;
  j["mode"] = settings.quick ? "quick" : "full";
  j["command"] = settings.command_line;
  j["chip_preset"] = settings.chip_preset;
  j["clock_MHz"] = settings.clock_MHz;
  j["scenes"] = Json::array();
  for (const ReproScene& s : scenes) {
    Json views = Json::array();
    for (const ReproView& v : s.views) views.push_back(v.index);
    const Camera& c = s.views.front().camera;
    j["scenes"].push_back({{"name", s.name},
                           {"model", s.model_source},
                           {"model_hash", s.model_hash},
                           {"data", s.data_source.empty() ? Json(nullptr) : Json(s.data_source)},
                           {"width", c.width},
                           {"height", c.height},
                           {"views", views}});
  }
  j["skipped"] = Json::array();
  for (const auto& [name, why] : settings.skipped) j["skipped"].push_back({{"name", name}, {"reason", why}});
  j["simulations"] = {{"distinct", simulations.distinct},
                      {"cached", simulations.cached},
                      {"ran", simulations.ran},
                      {"seconds", simulations.seconds}};
  j["runs"] = Json::array();
  for (const std::string& s : table.scenes())
    for (int v : table.views(s))
      for (const std::string& variant : table.variants(s, v)) {
        const Json& r = table.run(s, v, variant);
        const Json& st = r.at("stats");
        auto value = [&](const char* name) { return st.contains(name) ? st[name].at("value") : Json(nullptr); };
        Json power = energy_value(r, "energy", "average_power_W");
        j["runs"].push_back({{"scene", s},
                             {"view", v},
                             {"variant", variant},
                             {"key", table.key(s, v, variant)},
                             {"file", "runs/" + table.key(s, v, variant) + ".json"},
                             {"clock_MHz", value("sim.clock_MHz")},
                             {"cycles", value("sim.cycles")},
                             {"fps", value("sim.fps")},
                             {"samples_per_cycle", value("sim.samples_per_cycle")},
                             {"dram_read_bytes", value("dram.read_bytes")},
                             {"dram_write_bytes", value("dram.write_bytes")},
                             {"power_mW", power.is_null() ? power : Json(1e3 * power.get<double>())},
                             {"nJ_per_pixel", energy_value(r, "energy", "nJ_per_pixel")},
                             {"psnr_dB", value("quality.psnr_vs_ground_truth")},
                             {"host_seconds", value("host.seconds")}});
      }
  j["figures"] = figures;
  return j;
}

std::vector<fs::path> write_results(const fs::path& out_dir, const Json& results) {
  std::vector<fs::path> written;
  auto put = [&](const std::string& name, const std::string& text) {
    write_file_atomic(out_dir / name, text);
    written.push_back(out_dir / name);
  };
  put("results.json", results.dump(1) + "\n");
  put("comparisons.csv", csv_text(kComparisonColumns, comparison_rows(results, false)));
  Json run_columns = {"scene",
                      "view",
                      "variant",
                      "key",
                      "file",
                      "clock_MHz",
                      "cycles",
                      "fps",
                      "samples_per_cycle",
                      "dram_read_bytes",
                      "dram_write_bytes",
                      "power_mW",
                      "nJ_per_pixel",
                      "psnr_dB",
                      "host_seconds"};
  Json run_rows = Json::array();
  for (const Json& r : results.at("runs")) {
    Json row = Json::array();
    for (const Json& c : run_columns) row.push_back(r.at(c.get<std::string>()));
    run_rows.push_back(row);
  }
  put("runs.csv", csv_text(run_columns, run_rows));
  for (const Json& f : results.at("figures"))
    for (const Json& t : f.at("tables"))
      put(t.at("name").get<std::string>() + ".csv", csv_text(t.at("columns"), t.at("rows")));
  return written;
}

std::string markdown_report(const Json& results, const fs::path& out_dir) {
  const bool quick = results.at("mode") == "quick";
  std::string md = "# EDR-NR reproduction report\n\n";
  md += fmt::format("Made by `{}` with the chip preset `{}` ({:g} MHz). ", results.at("command").get<std::string>(),
                    results.at("chip_preset").get<std::string>(), results.at("clock_MHz").get<double>());
  if (quick)
    md +=
        "**Quick mode**: procedural scenes at a low resolution with orbit cameras and no ground truth; the "
        "paper's numbers are for the Synthetic-NeRF scenes at 800x800, so the ratios only show that every figure "
        "is computed. ";
  md +=
      "Every number is also in `results.json` and the CSV files beside this report; each run's own statistics "
      "are in `runs/<key>.json`.\n\n";
  md += "**Scenes covered:** ";
  bool first = true;
  for (const Json& s : results.at("scenes")) {
    md += fmt::format("{}{} (views", first ? "" : "; ", s.at("name").get<std::string>());
    for (const Json& v : s.at("views")) md.append(" ").append(v.dump());
    md += fmt::format(", {}x{}, model `{}`)", s.at("width").get<int>(), s.at("height").get<int>(),
                      s.at("model").get<std::string>());
    first = false;
  }
  md += ".\n\n";
  if (!results.at("skipped").empty()) {
    md += "**Skipped:**\n\n";
    for (const Json& s : results.at("skipped"))
      md += fmt::format("- {}: {}\n", s.at("name").get<std::string>(), s.at("reason").get<std::string>());
    md += "\n";
  }
  const Json& sims = results.at("simulations");
  md += fmt::format("**Simulations:** {} distinct, {} cached from an earlier run, {} run now in {:.0f} s.\n\n",
                    sims.at("distinct").get<size_t>(), sims.at("cached").get<size_t>(), sims.at("ran").get<size_t>(),
                    sims.at("seconds").get<double>());
  md +=
      "Each figure is computed per view from that view's runs, then averaged over the views of a scene and over "
      "the scenes (\"all scenes\"). The ratio is ours / the paper's. Where a figure differs from the paper's by "
      "more than 10 %, a note says why, from the runs' own counters.\n\n";

  md += "## Summary\n\n";
  Json summary = Json::array();
  for (const Json& r : comparison_rows(results, true))
    if (!r[4].is_null()) summary.push_back({r[0], r[1], r[3], r[4], r[5], r[6]});
  md.append(markdown_table({"figure", "quantity", "ours", "paper", "ratio", "unit"}, summary)).append("\n");

  for (const Json& f : results.at("figures")) {
    const std::string id = f.at("id");
    md += fmt::format("## {}\n\n{}\n\n", f.at("title").get<std::string>(), f.at("measures").get<std::string>());
    std::error_code ec;
    if (fs::is_regular_file(out_dir / "figures" / (id + ".png"), ec))
      md += fmt::format("![{}](figures/{}.png)\n\n", f.at("title").get<std::string>(), id);
    Json rows = Json::array();
    for (const Json& c : f.at("comparisons"))
      rows.push_back({c.at("quantity"), c.at("scene"), c.at("ours"), c.at("paper"), c.at("ratio"), c.at("unit")});
    md.append(markdown_table({"quantity", "scene", "ours", "paper", "ratio", "unit"}, rows)).append("\n");
    if (!f.at("notes").empty()) {
      md += "**Why it differs:**\n\n";
      for (const Json& n : f.at("notes")) md.append("- ").append(n.get<std::string>()).append("\n");
      md += "\n";
    }
    for (const Json& t : f.at("tables"))
      md.append(fmt::format("*{}* (`{}.csv`)\n\n", t.at("title").get<std::string>(), t.at("name").get<std::string>()))
          .append(markdown_table(t.at("columns"), t.at("rows")))
          .append("\n");
  }
  return md;
}

}  // namespace edrnr::sim
