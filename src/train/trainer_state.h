#pragma once
// Internal to the trainer, not part of the public API (that is train/trainer.h):
// the declaration of Trainer::State, which trainer.cpp, trainer_sampling.cpp,
// trainer_phases.cpp and trainer_io.cpp define between them, and the types its
// members share (a step's rays and samples, its work items, the timed stages).
// Include it from those files only.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/vec.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "render/fast_march.h"
#include "render/traversal.h"
#include "train/adam.h"
#include "train/checkpoint_io.h"
#include "train/error_map.h"
#include "train/feature_grid.h"
#include "train/mlp_kernels.h"
#include "train/occupancy.h"
#include "train/trainer.h"

namespace edrnr::train {

namespace trainer_detail {

struct WorkItem {
  int32_t mlp = 0;
  int32_t begin = 0, end = 0;  // range in the grouped id list
  int32_t chunk0 = 0;          // index of its first chunk among all chunks of the list
};

// Rays and samples of one step (reused between steps).
struct Batch {
  int n_rays = 0;
  std::vector<MicroRay> mray;           // each ray in micro-grid units (the renderer's sampling)
  std::vector<float> target;            // 3 per ray
  std::vector<float> background;        // 3 per ray
  std::vector<float> dir_enc;           // dir_dims per ray
  std::vector<int32_t> k_next, k_last;  // each ray's candidate range (k_next: its first)
  std::vector<float> trans;
  std::vector<uint8_t> alive;
  std::vector<int32_t> ray_first, ray_count;  // each ray's active samples in `order`
  std::vector<int32_t> order;                 // active sample ids, ray after ray, each in march order
  std::vector<float> pixel;                   // 3 per ray
  std::vector<double> ray_sq_err;
  std::vector<uint32_t> ray_cell;  // each ray's error-map cell (error_map_share > 0)
  std::vector<float> ray_weight;   // each ray's loss weight (empty: 1)

  size_t n_samples = 0;
  std::vector<float> pos;       // 3 per sample: micro-grid position
  std::vector<int16_t> micro;   // 3 per sample: micro voxel
  std::vector<int32_t> cand;    // candidate index k along the ray
  std::vector<int32_t> ray;     // owning ray
  std::vector<int32_t> mlp;     // MLP index
  std::vector<float> feat;      // F per sample
  std::vector<float> geo;       // G per sample; geo[0] is the raw density
  std::vector<uint8_t> active;  // before termination
  std::vector<float> rgb;       // 3 per sample
  std::vector<float> d_raw;     // 1 per sample
  std::vector<float> weight;    // 1 per sample: T alpha
  std::vector<float> d_z;       // 3 per sample: gradient before the sigmoid
  std::vector<float> d_feat;    // F per sample

  std::vector<int32_t> col_ids;
  std::vector<WorkItem> col_items;
  std::vector<float> col_acts;

  // The march's scratch (Trainer::State::march), kept between steps.
  std::vector<FastMarcher> marchers;  // per ray
  std::vector<MarchSample> found;     // per live ray, the round's samples
  std::vector<uint8_t> ended;         // per live ray: no candidates left

  void reserve_samples(size_t n, int F, int G) {
    if (pos.size() >= 3 * n) return;
    size_t cap = std::max(n, pos.size() / 3 * 2);
    pos.resize(3 * cap);
    micro.resize(3 * cap);
    cand.resize(cap);
    ray.resize(cap);
    mlp.resize(cap);
    feat.resize(cap * size_t(F));
    geo.resize(cap * size_t(G));
    active.resize(cap);
    rgb.resize(3 * cap);
    d_raw.resize(cap);
    weight.resize(cap);
    d_z.resize(3 * cap);
    d_feat.resize(cap * size_t(F));
  }
};

// The stages of a step, timed separately (TrainStats::stage_seconds).
enum Stage { kRays, kMarch, kDensity, kColor, kComposite, kBackward, kScatter, kAdam, kOccupancy, kPhase, kStages };
const char* const kStageNames[kStages] = {"rays",     "march",   "density", "colour",    "composite",
                                          "backward", "scatter", "adam",    "occupancy", "phase change"};

}  // namespace trainer_detail

struct Trainer::State {
  const Dataset& data;
  TrainConfig cfg;
  MlpArch arch;
  MlpLayout layout;
  int F = 0, G = 0, DD = 0;
  SceneModel geometry;  // scene box and micro resolution only: the renderer's sampling helpers take a model
  float delta = 0;      // scene units between candidate samples
  std::vector<uint64_t> pixel_start;  // prefix sums of pixels per frame
  bool rgba = false;                  // images are premultiplied RGBA

  int64_t step = 0;
  int64_t iters = 0;
  bool iters_fixed = false;
  Phase phase = Phase::Main;
  int n_rays = 0;
  double mse_ema = -1;
  double psnr_float = 0, psnr_quantized = 0;
  int64_t occ_updates = 0;
  int64_t feature_adam_t = 0, mlp_adam_t = 0;
  int last_rays = 0;
  int64_t last_samples = 0;

  ErrorMap err_map;  // cfg.error_map_share > 0; else empty

  FeaturePyramid pyramid;
  BlockFeatures blocks;
  OccupancyGrid occ;
  // occ's micro occupancy as the vector march reads it (march_grid()).
  mutable FastSkipGrid march_grid_;
  mutable uint64_t march_grid_generation_ = 0;
  std::vector<Int4Channel> feature_quant;  // quantization-aware phase

  int n_mlps = 1;
  std::vector<uint32_t> mlp_cv;    // CV of each MLP (after the freeze)
  std::vector<int32_t> cv_to_mlp;  // dense coarse grid -> MLP
  std::vector<float> mlp_params, mlp_m, mlp_v;
  std::vector<float> mlp_eff;       // fake-quantized weights in the quantization-aware phase
  std::vector<float> layer_in_max;  // per MLP x layer: largest |input| seen in the quantization-aware phase
  // Per MLP x layer (density then colour): the INT8 input step the
  // quantization-aware phase rounds that layer's inputs to (qat_activations);
  // empty until the phase's first refresh_activation_steps().
  std::vector<float> act_steps;

  // Largest sample weight seen per micro voxel in the per-CV phase (for pruning).
  std::vector<float> max_weight;

  // Float snapshot when quantization-aware training begins.
  std::vector<float> float_blocks, float_mlps;
  // The running averages of the block values and MLP parameters in the
  // current phase (cfg.ema_decay_per_cv, ema_decay_qat); empty when off or
  // before the phase's first step.
  std::vector<float> ema_blocks, ema_mlps;

  mutable trainer_detail::Batch batch;
  mutable double stage_s[trainer_detail::kStages] = {};

  // --- set-up (trainer.cpp) --------------------------------------------------

  State(const Dataset& d, const TrainConfig& c);
  void fresh_init();

  // The averages' decay per step in the current phase (0: none).
  float ema_decay() const {
    return phase == Phase::PerCv ? cfg.ema_decay_per_cv : phase == Phase::Quantize ? cfg.ema_decay_qat : 0.f;
  }
  // After a step's updates: starts or updates the current phase's averages.
  void update_ema();
  // Replaces the block values and MLP parameters by their averages (if any)
  // and drops the averages.
  void take_ema();

  int64_t freeze_step() const { return cfg.freeze_step(iters); }
  int64_t qat_step() const {
    return std::max(freeze_step(), int64_t(std::llround(double(iters) * (1.0 - cfg.qat_fraction))));
  }

  // Warm-up, then constant until cfg.plan_step, then exponential decay to
  // lr_final at the last step: steps before plan_step do not depend on iters,
  // so a --minutes run (whose step count is fixed by then) is replayed exactly
  // by --iters with the count it chose.
  float lr_factor(int64_t t) const {
    const int64_t hold = cfg.plan_step;
    const double e = double(std::max<int64_t>(0, t - hold)) / double(std::max<int64_t>(1, iters - hold));
    double f = std::pow(double(cfg.lr_final), std::min(1.0, e));
    if (cfg.lr_warmup > 0 && t < cfg.lr_warmup) f *= double(t + 1) / double(cfg.lr_warmup + 1);
    return float(f);
  }

  Vec3f micro_scale() const { return cfg.scene_box.size() / float(cfg.micro_res); }

  // --- rays (trainer_sampling.cpp) -------------------------------------------

  void set_ray(trainer_detail::Batch& b, int i, const Ray& r);
  void resize_rays(trainer_detail::Batch& b, int n);
  void sample_training_rays(trainer_detail::Batch& b, int n);
  void init_error_map();
  // Folds each ray's squared error into its error-map cell, ray by ray.
  void update_error_map(const trainer_detail::Batch& b);

  // --- sampling (trainer_sampling.cpp) ---------------------------------------

  int32_t mlp_of_micro(int x, int y, int z) const;
  const float* mlp_weights(int m) const;
  // MLP m's act_steps (density layers, then colour layers), or null when the
  // activations are not rounded.
  const float* act_steps_of(int m) const;
  const float* color_steps(int m) const;  // the colour layers' part of it
  void interpolate(const Vec3f& p, const Vec3i& m, float* out) const;
  void prefetch_features(const Vec3i& m) const;
  // The march grid of the occupancy as it is now (rebuilt when occ changed).
  const FastSkipGrid& march_grid() const;
  void march(trainer_detail::Batch& b) const;
  void evaluate_density(trainer_detail::Batch& b, size_t s0, size_t s1) const;
  // The colour net's input of samples ids[c0, c0 + nl), rounded to the chip's
  // INT8 steps when steps (the colour net's act_steps) is not null.
  void gather_color_input(const trainer_detail::Batch& b, const std::vector<int32_t>& ids, int32_t c0, int nl,
                          float* x0, const float* steps) const;
  void evaluate_color(trainer_detail::Batch& b) const;
  double composite_rays(trainer_detail::Batch& b, bool with_grad) const;
  void backward_mlps(trainer_detail::Batch& b, std::vector<float>& grad, bool calibrate);
  double forward(trainer_detail::Batch& b) const;

  // --- occupancy (trainer_phases.cpp) ----------------------------------------

  float occupancy_threshold() const;
  static constexpr int kOccupancyMargin = 8;  // see refresh_bounds
  void refresh_bounds(Vec3i& lo, Vec3i& hi) const;
  void refresh_occupancy_part(int part, float decay);
  void refresh_occupancy();
  void update_aabb();

  // --- phase changes (trainer_phases.cpp) ------------------------------------

  void freeze();
  void prune();
  void start_quantization();

  // --- the step (trainer.cpp) ------------------------------------------------

  uint32_t active_levels(int64_t s) const;
  void do_step();
  void add_mlp_tie_gradient(std::vector<float>& grad) const;
  void equalize_mlps();
  void update_fake_quantized_mlps();
  void refresh_activation_steps();
  AdamSettings adam_settings() const;

  // --- export and checkpoints (trainer_io.cpp) -------------------------------

  // trained_steps: with act_steps set, the quantized MLPs take them as their
  // input steps; else the steps are calibrated (calibrate_activations) or
  // the largest inputs seen / 127.
  SceneModel make_model(bool quantized, bool trained_steps = true) const;
  std::vector<uint8_t> save() const;
  void load(const CheckpointReader& r);
};

}  // namespace edrnr::train
