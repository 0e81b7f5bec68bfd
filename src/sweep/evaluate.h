#pragma once
// One job of a sweep (a point, a model, a view) through the cycle simulator,
// as one row of the results table.
//
// A row (JSON, keys in this order):
//   key, point, model, view, values {varied key: value}, config_hash,
//   status ("ok" or "error"), error (the message; "" when ok),
//   metrics {fps, cycles, nJ_per_pixel, power_mW, sram_*_bytes,
//            over_budget, dram_read_bytes, dram_write_bytes,
//            dram_<data type>_read_bytes, micro_grid_hit_rate,
//            feature_hit_rate, mlp_hit_rate, psnr_dB, psnr_against: "ground_truth",
//            "reference_float" or "reference_quantized"}
// Every field follows from the plan alone (no wall times), so any process
// that evaluates a job writes the same row.
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>

#include "core/image.h"
#include "sim/simulator.h"
#include "sweep/plan.h"

namespace edrnr::sweep {

using Row = nlohmann::ordered_json;

// Whether the model has float features and MLPs (the reference then renders
// the float form; else the quantized one).
bool float_form(const SceneModel& model);

// The reference renderer's image of each (model, view), made once per process
// (the PSNR of a view without ground truth is taken against it).
class ReferenceImages {
 public:
  // The float reference image of views[model][view], rendered with the base
  // config's render settings on one thread. Throws Error if the model has no
  // float form.
  const Image& get(const SweepPlan& plan, size_t model, size_t view);

 private:
  std::map<std::pair<size_t, size_t>, Image> images_;
};

// What evaluate_config simulates. Pointers must stay valid during the call.
struct EvalInput {
  const sim::SimConfig* config = nullptr;  // null: invalid, config_error says why
  std::string config_error;
  const SceneModel* model = nullptr;
  const Camera* camera = nullptr;
  const Image* ground_truth = nullptr;  // null or empty: PSNR against reference()
  bool allow_over_budget = false;
  std::function<const Image&()> reference;  // the reference image (called only if needed); empty: no PSNR
  sim::SimResult* result = nullptr;         // if set, receives the simulator's result of a successful run
};

// An empty metrics object: every metric, null.
Row empty_metrics();

// Simulates in.config and sets row's status, error and metrics (see the top
// of this file). Never throws for a bad config or a failed simulation.
void evaluate_config(Row& row, const EvalInput& in);

// Simulates one job and returns its row. Never throws for a bad point: a
// config that does not resolve, a preset over Table I's SRAM (unless SPEC
// allows it), a step too fine for the model, or a simulation that fails
// becomes a row with status "error" and the message.
Row evaluate_job(const SweepPlan& plan, size_t job, ReferenceImages& references);

// A row for a job that could not be evaluated at all (its worker died).
Row error_row(const SweepPlan& plan, size_t job, const std::string& message);

// The columns of the CSV table, in order (values.<key> for each varied key,
// then the rest of the row flattened).
std::vector<std::string> table_columns(const SweepPlan& plan);

}  // namespace edrnr::sweep
