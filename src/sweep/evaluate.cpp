#include "sweep/evaluate.h"

#include <fmt/format.h>

#include <exception>
#include <stdexcept>

#include "core/error.h"
#include "core/metrics.h"
#include "render/options.h"
#include "render/reference.h"
#include "sim/memory_system.h"
#include "sim/simulator.h"

namespace edrnr::sweep {

namespace {

// The metric names, in column order.
const std::vector<std::string>& metric_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n = {"fps",
                                  "cycles",
                                  "frame_time_ms",
                                  "nJ_per_pixel",
                                  "power_mW",
                                  "sram_micro_grid_bytes",
                                  "sram_feature_bytes",
                                  "sram_mlp_bytes",
                                  "sram_others_bytes",
                                  "sram_total_bytes",
                                  "over_budget",
                                  "dram_read_bytes",
                                  "dram_write_bytes"};
    for (int t = 0; t < sim::kDataTypes; ++t)
      n.push_back(std::string("dram_") + sim::data_type_name(sim::DataType(t)) + "_read_bytes");
    for (const char* x : {"micro_grid_hit_rate", "feature_hit_rate", "mlp_hit_rate", "psnr_dB", "psnr_against"})
      n.push_back(x);
    return n;
  }();
  return names;
}

Row base_row(const SweepPlan& plan, size_t job) {
  const Job& j = plan.jobs[job];
  const Point& p = plan.points[j.point];
  Row r;
  r["key"] = j.key;
  r["point"] = j.point;
  r["model"] = plan.models[j.model].name;
  r["view"] = plan.views[j.model][j.view].name;
  Row values = Row::object();
  for (size_t i = 0; i < plan.varied.size(); ++i) values[plan.varied[i]] = yaml_to_json(p.values[i]);
  r["values"] = values;
  r["config_hash"] = p.config_hash;
  r["status"] = "ok";
  r["error"] = "";
  r["metrics"] = empty_metrics();
  return r;
}

void put_sram(Row& m, const sim::SramBudget& b) {
  for (int k = 0; k < sim::kSramClasses; ++k)
    m[std::string("sram_") + sim::sram_class_name(sim::SramClass(k)) + "_bytes"] = b.class_bytes[k];
  m["sram_total_bytes"] = b.total_bytes();
  m["over_budget"] = b.over_budget();
}

}  // namespace

bool float_form(const SceneModel& model) {
  try {
    resolve_model_form(model, ModelForm::Float);
    return true;
  } catch (const Error&) {
    return false;
  }
}

const Image& ReferenceImages::get(const SweepPlan& plan, size_t model, size_t view) {
  const auto key = std::make_pair(model, view);
  auto it = images_.find(key);
  if (it != images_.end()) return it->second;
  const ChipConfig& chip = plan.base_config.chip;
  RenderSettings s;
  s.step_micro = chip.step_micro;
  s.transmittance_min = chip.transmittance_min;
  for (int c = 0; c < 3; ++c) s.background[c] = chip.background[c];
  s.form = float_form(*plan.models[model].model) ? ModelForm::Float : ModelForm::Auto;
  s.threads = 1;
  Image img = render_reference(*plan.models[model].model, plan.views[model][view].camera, s);
  return images_.emplace(key, std::move(img)).first->second;
}

Row error_row(const SweepPlan& plan, size_t job, const std::string& message) {
  Row r = base_row(plan, job);
  r["status"] = "error";
  r["error"] = message;
  return r;
}

Row empty_metrics() {
  Row m = Row::object();
  for (const std::string& name : metric_names()) m[name] = nullptr;
  return m;
}

void evaluate_config(Row& row, const EvalInput& in) {
  row["status"] = "ok";
  row["error"] = "";
  row["metrics"] = empty_metrics();
  Row& m = row["metrics"];
  try {
    if (!in.config) fail("config: {}", in.config_error);
    const sim::SimConfig& cfg = *in.config;
    check_step_micro(cfg.chip.step_micro, in.model->micro_res, "render.step_micro");
    const sim::SramBudget budget = sim::sram_budget_for(*in.model, cfg);
    put_sram(m, budget);
    if (budget.over_budget() && !in.allow_over_budget) {
      std::string why;
      for (const std::string& v : budget.violations()) why.append(why.empty() ? "" : "; ").append(v);
      fail("over Table I's SRAM budget: {} (allow_over_budget: true simulates it anyway)", why);
    }
    sim::SimOptions options;
    options.threads = 1;
    sim::SimResult res = sim::simulate_chip(*in.model, *in.camera, cfg, options);
    const sim::SimSummary& s = res.summary;
    m["fps"] = s.fps;
    m["cycles"] = s.cycles;
    m["frame_time_ms"] = s.frame_time_s * 1e3;
    if (res.energy) {
      m["nJ_per_pixel"] = res.energy->nJ_per_pixel;
      m["power_mW"] = res.energy->average_power_W * 1e3;
    }
    put_sram(m, res.sram_budget);
    m["dram_read_bytes"] = s.dram_read_bytes;
    m["dram_write_bytes"] = s.dram_write_bytes;
    for (int t = 0; t < sim::kDataTypes; ++t) {
      const std::string type = sim::data_type_name(sim::DataType(t));
      m["dram_" + type + "_read_bytes"] = uint64_t(res.stats->get("mem." + type + ".read_bytes"));
    }
    m["micro_grid_hit_rate"] = s.micro_grid_hit_rate;
    m["feature_hit_rate"] = s.feature_hit_rate;
    m["mlp_hit_rate"] = s.mlp_hit_rate;
    if (in.ground_truth && !in.ground_truth->data.empty()) {
      m["psnr_dB"] = psnr(res.image, *in.ground_truth);
      m["psnr_against"] = "ground_truth";
    } else if (in.reference) {
      m["psnr_dB"] = psnr(res.image, in.reference());
      m["psnr_against"] = float_form(*in.model) ? "reference_float" : "reference_quantized";
    }
    if (in.result) *in.result = std::move(res);
  } catch (const std::exception& e) {
    // Error: bad input for this point; logic_error: an internal fault of the
    // simulator (a deadlock). Both are the point's result, not the sweep's end.
    row["status"] = "error";
    row["error"] = e.what();
  }
}

Row evaluate_job(const SweepPlan& plan, size_t job, ReferenceImages& references) {
  Row r = base_row(plan, job);
  const Job& j = plan.jobs[job];
  const Point& p = plan.points[j.point];
  const SweepView& view = plan.views[j.model][j.view];
  EvalInput in;
  in.config = p.config ? &*p.config : nullptr;
  in.config_error = p.config_error;
  in.model = plan.models[j.model].model.get();
  in.camera = &view.camera;
  in.ground_truth = &view.ground_truth;
  in.allow_over_budget = plan.spec.allow_over_budget;
  in.reference = [&]() -> const Image& { return references.get(plan, j.model, j.view); };
  evaluate_config(r, in);
  return r;
}

std::vector<std::string> table_columns(const SweepPlan& plan) {
  std::vector<std::string> c = {"point", "model", "view"};
  for (const std::string& k : plan.varied) c.push_back(k);
  for (const char* x : {"config_hash", "status"}) c.push_back(x);
  for (const std::string& x : metric_names()) c.push_back(x);
  c.push_back("error");
  c.push_back("key");
  return c;
}

}  // namespace edrnr::sweep
