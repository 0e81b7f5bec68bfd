#pragma once
// The finished runs of `edrnr reproduce`, looked up by scene, view and variant,
// and the arithmetic every figure shares: read a statistic of a run, average a
// per-view figure over the views of a scene and then over the scenes, and
// write a comparison with the paper's value.
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>
#include <vector>

#include "sim/reproduce_runs.h"

namespace edrnr::sim {

class RunTable {
 public:
  // Reads the JSON of every run of the plan from runs_dir. Throws Error naming
  // the scene, view, variant and file of a run that is missing.
  RunTable(const std::vector<ReproScene>& scenes, const std::vector<RunSpec>& plan,
           const std::filesystem::path& runs_dir);

  const std::vector<std::string>& scenes() const { return scenes_; }
  const std::vector<int>& views(const std::string& scene) const;
  // The run's JSON (execute_runs' format); Error naming it if there is none.
  const nlohmann::json& run(const std::string& scene, int view, const std::string& variant) const;
  const std::string& key(const std::string& scene, int view, const std::string& variant) const;
  bool has(const std::string& scene, int view, const std::string& variant) const;
  // Every variant name of a view, in plan order.
  std::vector<std::string> variants(const std::string& scene, int view) const;
  const std::filesystem::path& runs_dir() const { return runs_dir_; }

 private:
  struct Entry {
    std::string key;
    const nlohmann::json* json = nullptr;
  };
  std::filesystem::path runs_dir_;
  std::vector<std::string> scenes_;
  std::map<std::string, std::vector<int>> views_;
  std::map<std::string, nlohmann::json> by_key_;
  std::map<std::tuple<std::string, int, std::string>, Entry> entries_;
  std::map<std::pair<std::string, int>, std::vector<std::string>> variant_order_;
};

// A counter or value of the run's statistics ("sim.fps"). Throws Error naming
// the statistic and the run if it is not there.
double run_stat(const nlohmann::json& run, const std::string& name);
// The same, or NaN when the run does not have it.
double run_stat_or_nan(const nlohmann::json& run, const std::string& name);

// A figure's value per scene (the mean over the scene's views) and over the
// scenes (the mean of those). Views whose value is NaN are left out.
struct Averaged {
  double mean = 0;                       // NaN when no scene has a value
  std::map<std::string, double> scenes;  // NaN for a scene with no value
};
Averaged average_over_views(const RunTable& table, const std::function<double(const std::string&, int)>& per_view);

// One figure beside the paper's: {"quantity", "scene", "ours", "paper",
// "ratio" (ours / paper), "unit"}; a NaN or missing value is null.
nlohmann::json comparison(const std::string& quantity, const std::string& scene, double ours, double paper,
                          const std::string& unit);
// The comparisons of an averaged figure: one row for the mean ("all scenes")
// and one per scene.
void add_comparisons(nlohmann::json& out, const std::string& quantity, const Averaged& ours, double paper,
                     const std::string& unit);

// A JSON number, or null for NaN and infinities.
nlohmann::json number_or_null(double v);

// True when ours and paper differ by more than `tolerance` (relative to the paper's).
bool differs(double ours, double paper, double tolerance = 0.10);

}  // namespace edrnr::sim
