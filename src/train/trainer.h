#pragma once
// The trainer: learns an EDR-NR scene model (scene_model.h) from posed images
// on the CPU.
//
// Phases (fractions of `iters`, train/config.h):
//   1. main: a feature pyramid and one shared MLP; the occupancy grid is
//      refreshed as training goes and the object AABB taken from it.
//   2. per-CV: the occupancy is frozen, the pyramid baked exactly into one
//      5^3 block per occupied fine voxel, the shared MLP copied into every
//      occupied coarse voxel; blocks and per-CV MLPs are fine-tuned in float.
//   3. quantization-aware: features read through INT4, MLP weights through
//      INT8 (straight-through estimator).
// Every step samples rays from all training pixels and renders them exactly as
// render_reference does (render/reference.h), so the exported model renders
// what training measured.
//
// Determinism: random draws are functions of (seed, step, index); parallel
// work is split into fixed items whose results are combined in a fixed order.
// The same dataset, config and seed give the same bits for any thread count,
// and a run resumed from a checkpoint ends in the same bits as one that was
// never interrupted.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/image.h"
#include "data/dataset.h"
#include "model/scene_model.h"
#include "train/config.h"

namespace edrnr::train {

enum class Phase : int { Main = 0, PerCv = 1, Quantize = 2, Done = 3 };
const char* phase_name(Phase p);

struct TrainOptions {
  int threads = 0;                        // 0: all cores
  std::filesystem::path checkpoint_path;  // empty: no checkpoints
  double checkpoint_minutes = 5;          // between periodic checkpoints
  bool progress = false;                  // a live progress line on stderr
  // > 0 (and progress off): a plain progress message through `log` this often,
  // for runs whose output goes to a file.
  double progress_log_seconds = 0;
  int64_t stop_after = -1;                       // >= 0: checkpoint and stop once this many steps are done
  const std::atomic<bool>* interrupt = nullptr;  // set (e.g. by SIGINT): checkpoint and stop
  std::function<void(const std::string&)> log;   // one-line messages (phase changes, checkpoints)
  // Problems the run survives (a periodic checkpoint that could not be
  // written: the run goes on and tries again at the next one). Unset: stderr.
  std::function<void(const std::string&)> warn;
};

struct TrainStats {
  int64_t step = 0;   // steps done
  int64_t iters = 0;  // steps planned
  Phase phase = Phase::Main;
  int rays = 0;                 // rays in the last step
  int64_t samples = 0;          // samples evaluated in the last step
  double loss = 0;              // running mean squared error
  double psnr = 0;              // running training PSNR (dB) from that
  double psnr_float = 0;        // running PSNR at the end of the float phases (0 until then)
  double psnr_quantized = 0;    // running PSNR at the end of training (0 until then)
  size_t blocks = 0, mlps = 0;  // after the freeze
  // Wall-clock seconds spent in each stage of the steps so far in this process.
  std::vector<std::pair<std::string, double>> stage_seconds;
};

class Trainer {
 public:
  // A fresh run. The dataset (images loaded) must outlive the trainer. Its
  // images are RGB composited on config.background, or premultiplied RGBA
  // (train/images.h), all frames alike; with RGBA and random_background each
  // training ray gets its own random background. Throws Error on an empty
  // dataset or frames without images.
  Trainer(const Dataset& data, const TrainConfig& config);
  // Continues from checkpoint bytes written by checkpoint(); the dataset must
  // be the one the checkpoint was made from (Error otherwise).
  Trainer(const Dataset& data, const std::vector<uint8_t>& checkpoint, const std::string& source);
  ~Trainer();
  // The settings stored in checkpoint bytes (to load the dataset as the run did).
  static TrainConfig checkpoint_config(const std::vector<uint8_t>& checkpoint, const std::string& source);
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  // Runs steps until training is done, stop_after is reached or interrupt is
  // set; writes checkpoints as options say (always on stop or interrupt).
  // Returns true when training is done. A periodic checkpoint that cannot be
  // written is reported through options.warn and training goes on; the one
  // written on stop or interrupt throws Error if it cannot be written.
  bool run(const TrainOptions& options);
  // One step (phase changes happen at its start).
  void step();
  bool done() const;

  const TrainConfig& config() const;
  TrainStats stats() const;
  // Fixes the number of steps (before the main phase ends). Used by --minutes.
  void set_iters(int64_t iters);

  // Checkpoint bytes: everything needed to continue to the same bits.
  std::vector<uint8_t> checkpoint() const;

  // The model as of now (the freeze must have happened: phase >= PerCv).
  // quantized: INT4 features and INT8 MLPs (no float forms); otherwise the
  // float model as it was when quantization-aware training began (or now, if
  // it has not begun).
  SceneModel export_model(bool quantized) const;

  // Renders a camera with the training-time forward pass (for checks against
  // render_reference).
  Image render(const Camera& camera) const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace edrnr::train
