// edrnr calibrate: chooses a quantized model's INT8 activation steps from the
// samples its training cameras' rays evaluate (train/calibrate.h), as
// `edrnr train` does when it exports (calibrate_activations in the preset).
#include <fmt/format.h>

#include <memory>
#include <string>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "train/calibrate.h"
#include "train/config.h"

namespace edrnr::cli {
namespace {

struct CalibrateOptions {
  std::string model, dataset, output, split = "train";
  int downscale = 1, threads = 0;
};

void run_calibrate(const CalibrateOptions& o) {
  check_output_path(o.output, "-o");
  if (o.downscale < 1) fail("--downscale {}: must be at least 1", o.downscale);
  if (o.threads < 0) fail("--threads {}: must be 0 (all cores) or more", o.threads);
  SceneModel m = load_model(o.model);
  if (m.mlp_count() > 0 && m.mlps_q8.empty()) fail("{}: the model has no INT8 MLPs to calibrate", o.model);
  DatasetOptions d;
  d.split = o.split;
  d.downscale = o.downscale;
  d.load_images = false;
  const Dataset ds = load_dataset(o.dataset, d);
  std::vector<Camera> cameras;
  for (const auto& f : ds.frames) cameras.push_back(f.camera);
  // The trainer's render settings: the defaults of TrainConfig.
  const train::TrainConfig defaults;
  train::CalibrationSettings s;
  s.step_micro = defaults.step_micro;
  s.transmittance_min = defaults.transmittance_min;
  s.threads = o.threads;
  const train::CalibrationReport r = train::calibrate_activation_scales(m, cameras, s);
  write_file_atomic(o.output, serialize_model(m));
  fmt::print("{}: {} rays from {} {} cameras, {} samples; {} of {} layer input steps changed (mean {:+.2f} in log2)\n",
             o.output, r.rays, cameras.size(), o.split, r.samples, r.layers_changed, r.layers, r.mean_step_log2);
}

void register_calibrate_cmd(CLI::App& app) {
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate", "Choose a quantized model's INT8 activation steps from the samples of its training rays");
  cmd->add_option("model", o->model, "the quantized .edrnr model")->required();
  cmd->add_option("dataset", o->dataset, "its NeRF dataset folder (the cameras of --split; images not read)")
      ->required();
  cmd->add_option("-o,--output", o->output, "the calibrated model to write")->required();
  cmd->add_option("--split", o->split, "the cameras to use")->capture_default_str();
  cmd->add_option("--downscale", o->downscale, "integer image downscale factor")->capture_default_str();
  cmd->add_option("--threads", o->threads, "threads (0: all cores)")->capture_default_str();
  cmd->callback([o] { run_calibrate(*o); });
}

Registrar reg{62, register_calibrate_cmd};

}  // namespace
}  // namespace edrnr::cli
