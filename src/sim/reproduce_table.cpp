#include "sim/reproduce_table.h"

#include <cmath>
#include <limits>
#include <tuple>

#include "core/error.h"

namespace edrnr::sim {

namespace fs = std::filesystem;

RunTable::RunTable(const std::vector<ReproScene>& scenes, const std::vector<RunSpec>& plan, const fs::path& runs_dir)
    : runs_dir_(runs_dir) {
  for (const ReproScene& s : scenes) {
    scenes_.push_back(s.name);
    std::vector<int>& v = views_[s.name];
    for (const ReproView& view : s.views) v.push_back(view.index);
  }
  for (const RunSpec& spec : plan) {
    const ReproScene& scene = scenes[spec.scene];
    const int view = scene.views[spec.view].index;
    const std::string variant = spec.variant.name();
    auto it = by_key_.find(spec.key);
    if (it == by_key_.end()) {
      std::optional<nlohmann::json> j = load_cached_run(runs_dir, spec.key);
      if (!j)
        fail("no finished run for {} view {} ({}): '{}' is missing or unreadable", scene.name, view, variant,
             run_json_path(runs_dir, spec.key).string());
      it = by_key_.emplace(spec.key, std::move(*j)).first;
    }
    entries_[{scene.name, view, variant}] = {spec.key, &it->second};
    variant_order_[{scene.name, view}].push_back(variant);
  }
}

const std::vector<int>& RunTable::views(const std::string& scene) const {
  auto it = views_.find(scene);
  if (it == views_.end()) fail("no scene '{}' in the runs", scene);
  return it->second;
}

bool RunTable::has(const std::string& scene, int view, const std::string& variant) const {
  return entries_.count({scene, view, variant}) > 0;
}

const nlohmann::json& RunTable::run(const std::string& scene, int view, const std::string& variant) const {
  auto it = entries_.find({scene, view, variant});
  if (it == entries_.end()) fail("no run of {} view {} with variant {}", scene, view, variant);
  return *it->second.json;
}

const std::string& RunTable::key(const std::string& scene, int view, const std::string& variant) const {
  auto it = entries_.find({scene, view, variant});
  if (it == entries_.end()) fail("no run of {} view {} with variant {}", scene, view, variant);
  return it->second.key;
}

std::vector<std::string> RunTable::variants(const std::string& scene, int view) const {
  auto it = variant_order_.find({scene, view});
  return it == variant_order_.end() ? std::vector<std::string>{} : it->second;
}

double run_stat_or_nan(const nlohmann::json& run, const std::string& name) {
  const nlohmann::json& stats = run.at("stats");
  auto it = stats.find(name);
  if (it == stats.end() || !it->is_object()) return std::numeric_limits<double>::quiet_NaN();
  auto v = it->find("value");
  if (v == it->end() || !v->is_number()) return std::numeric_limits<double>::quiet_NaN();
  return v->get<double>();
}

double run_stat(const nlohmann::json& run, const std::string& name) {
  const double v = run_stat_or_nan(run, name);
  if (std::isnan(v))
    fail("run {} view {} ({}) has no statistic '{}'", run.value("scene", "?"), run.value("view", -1),
         run.value("variant", "?"), name);
  return v;
}

Averaged average_over_views(const RunTable& table, const std::function<double(const std::string&, int)>& per_view) {
  Averaged a;
  double sum = 0;
  int n = 0;
  for (const std::string& scene : table.scenes()) {
    double s = 0;
    int k = 0;
    for (int view : table.views(scene)) {
      const double v = per_view(scene, view);
      if (std::isfinite(v)) s += v, ++k;
    }
    const double mean = k ? s / k : std::numeric_limits<double>::quiet_NaN();
    a.scenes[scene] = mean;
    if (k) sum += mean, ++n;
  }
  a.mean = n ? sum / n : std::numeric_limits<double>::quiet_NaN();
  return a;
}

nlohmann::json number_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

nlohmann::json comparison(const std::string& quantity, const std::string& scene, double ours, double paper,
                          const std::string& unit) {
  const double ratio = std::isfinite(ours) && std::isfinite(paper) && paper != 0
                           ? ours / paper
                           : std::numeric_limits<double>::quiet_NaN();
  return {{"quantity", quantity},           {"scene", scene},
          {"ours", number_or_null(ours)},   {"paper", number_or_null(paper)},
          {"ratio", number_or_null(ratio)}, {"unit", unit}};
}

void add_comparisons(nlohmann::json& out, const std::string& quantity, const Averaged& ours, double paper,
                     const std::string& unit) {
  out.push_back(comparison(quantity, "all scenes", ours.mean, paper, unit));
  for (const auto& [scene, v] : ours.scenes) out.push_back(comparison(quantity, scene, v, paper, unit));
}

bool differs(double ours, double paper, double tolerance) {
  if (!std::isfinite(ours) || !std::isfinite(paper) || paper == 0) return false;
  return std::abs(ours / paper - 1.0) > tolerance;
}

}  // namespace edrnr::sim
