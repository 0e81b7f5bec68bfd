#pragma once
// The Pareto front of a sweep over three objectives: frame rate (FPS, higher
// is better), energy per pixel (nJ/pixel, lower) and on-chip SRAM (bytes,
// lower). A point's figures are the means over its models and views (SRAM is
// the largest); a point with any failed job is left out. A point is on the
// front when no other point is at least as good in all three and better in
// one.
#include <optional>
#include <string>
#include <vector>

#include "sweep/evaluate.h"
#include "sweep/plan.h"

namespace edrnr::sweep {

struct ParetoPoint {
  size_t point = 0;
  double fps = 0, nJ_per_pixel = 0;
  uint64_t sram_bytes = 0;
  bool on_front = false;
  bool base = false;  // the base design (plan.base_point)
};

// The points with results for every job, in point order, with on_front set.
std::vector<ParetoPoint> pareto_points(const SweepPlan& plan, const std::map<std::string, Row>& rows);

// CSV of the front (and the base design, marked, whether on it or not):
// point, the varied values, config_hash, fps, nJ_per_pixel, sram_total_bytes,
// on_front, design ("base" or ""); sorted by FPS, highest first.
std::string pareto_csv(const SweepPlan& plan, const std::vector<ParetoPoint>& points);

}  // namespace edrnr::sweep
