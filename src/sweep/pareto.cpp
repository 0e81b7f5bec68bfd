#include "sweep/pareto.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>

#include "sweep/table.h"

namespace edrnr::sweep {

namespace {

bool dominates(const ParetoPoint& a, const ParetoPoint& b) {
  const bool no_worse = a.fps >= b.fps && a.nJ_per_pixel <= b.nJ_per_pixel && a.sram_bytes <= b.sram_bytes;
  const bool better = a.fps > b.fps || a.nJ_per_pixel < b.nJ_per_pixel || a.sram_bytes < b.sram_bytes;
  return no_worse && better;
}

}  // namespace

std::vector<ParetoPoint> pareto_points(const SweepPlan& plan, const std::map<std::string, Row>& rows) {
  struct Sum {
    size_t jobs = 0, ok = 0;
    double fps = 0, nj = 0;
    uint64_t sram = 0;
    bool failed = false;
  };
  std::vector<Sum> sums(plan.points.size());
  for (const Job& j : plan.jobs) {
    Sum& s = sums[j.point];
    ++s.jobs;
    auto it = rows.find(j.key);
    if (it == rows.end()) continue;
    const Row& r = it->second;
    const Row& m = r["metrics"];
    if (r["status"] != "ok" || !m["fps"].is_number() || !m["nJ_per_pixel"].is_number() ||
        !m["sram_total_bytes"].is_number()) {
      s.failed = true;
      continue;
    }
    ++s.ok;
    s.fps += m["fps"].get<double>();
    s.nj += m["nJ_per_pixel"].get<double>();
    s.sram = std::max(s.sram, m["sram_total_bytes"].get<uint64_t>());
  }
  std::vector<ParetoPoint> out;
  for (size_t p = 0; p < sums.size(); ++p) {
    const Sum& s = sums[p];
    if (s.failed || s.ok == 0 || s.ok != s.jobs) continue;
    ParetoPoint q;
    q.point = p;
    q.fps = s.fps / double(s.ok);
    q.nJ_per_pixel = s.nj / double(s.ok);
    q.sram_bytes = s.sram;
    q.base = plan.base_point && *plan.base_point == p;
    out.push_back(q);
  }
  for (ParetoPoint& a : out)
    a.on_front = std::none_of(out.begin(), out.end(), [&](const ParetoPoint& b) { return dominates(b, a); });
  return out;
}

std::string pareto_csv(const SweepPlan& plan, const std::vector<ParetoPoint>& points) {
  std::string out = "point";
  for (const std::string& k : plan.varied) out.append(",").append(csv_cell(k));
  out += ",config_hash,fps,nJ_per_pixel,sram_total_bytes,on_front,design\n";
  std::vector<ParetoPoint> rows;
  for (const ParetoPoint& p : points)
    if (p.on_front || p.base) rows.push_back(p);
  std::stable_sort(rows.begin(), rows.end(), [](const ParetoPoint& a, const ParetoPoint& b) { return a.fps > b.fps; });
  for (const ParetoPoint& p : rows) {
    const Point& pt = plan.points[p.point];
    out += std::to_string(p.point);
    for (size_t i = 0; i < plan.varied.size(); ++i) out.append(",").append(csv_cell(yaml_to_json(pt.values[i])));
    out += fmt::format(",{},{},{},{},{},{}\n", pt.config_hash, nlohmann::json(p.fps).dump(),
                       nlohmann::json(p.nJ_per_pixel).dump(), p.sram_bytes, p.on_front ? 1 : 0, p.base ? "base" : "");
  }
  return out;
}

}  // namespace edrnr::sweep
