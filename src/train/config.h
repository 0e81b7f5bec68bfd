#pragma once
// Trainer settings: every field a preset (configs/train/*.yaml) may set, with
// its default; the defaults are configs/train/default.yaml. Durations are in
// training steps unless the name says otherwise.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/limits.h"
#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr::train {

struct TrainConfig {
  // --- model ---
  Box3f scene_box{{-1.5f, -1.5f, -1.5f}, {1.5f, 1.5f, 1.5f}};  // must be a cube
  int micro_res = 256;                                         // Rm, a multiple of 32
  std::vector<int> levels{32, 64, 128, 256};                   // feature pyramid resolutions (4 channels each)
  std::vector<int> density_hidden{16};                         // density net hidden widths
  int geo_features = 8;                                        // density net outputs (G)
  std::vector<int> color_hidden{16};                           // colour net hidden widths
  int dir_frequencies = 2;                                     // L
  float step_micro = kDefaultStepMicro;                        // sample spacing in micro voxels (as the renderer)
  float transmittance_min = 1e-4f;                             // early termination (as the renderer)
  float background[3] = {1.f, 1.f, 1.f};  // the background the model is exported for (and evaluated on)
  bool random_background = true;          // with RGBA images: composite each ray's target on a random colour
  bool pixel_jitter = false;              // training rays through a random point of their pixel, not its centre
  // > 0: each training ray's samples move along it by a random share of the
  // sample step, uniform in +-depth_jitter / 2 of it (1: anywhere between two
  // fixed positions), so the field is fitted between the positions a render
  // samples, not only at them (docs/training.md, "Samples jittered along
  // their rays"); 0: the render's fixed positions
  float depth_jitter = 1.f;
  // > 0: this share of each step's rays go through pixels drawn in proportion
  // to an error map (every training image in cells of error_map_cell^2
  // pixels, each cell the running mean squared error of the rays through it),
  // the others through pixels drawn uniformly. With error_map_unbiased each
  // ray's loss is weighted by its pixel's uniform probability over its actual
  // one (the expected gradient stays that of uniform rays, with less noise
  // where the error is); without, hard pixels simply count more.
  float error_map_share = 0.f;
  int error_map_cell = 16;
  bool error_map_unbiased = true;

  // --- schedule ---
  int64_t iters = 20000;     // total steps
  double minutes = 0;        // > 0: choose iters to fit this budget (measured after a calibration)
  int64_t plan_step = 1000;  // the learning rate holds until this step; --minutes fixes iters here (or
                             // earlier, once a quarter of the budget is spent) from the speed measured
                             // over the last 40 % of the steps, when empty space is already skipped
  // --minutes: the time left at the plan goes to the steps by a model of
  // their cost relative to the steps the plan measured (plan_iters below):
  // a main-phase step after the plan costs plan_cost_main of them, a per-CV
  // step plan_cost_per_cv (one level of 16 channels instead of four of 4), a
  // quantization-aware step plan_cost_qat (rounding on top, and with
  // qat_activations the activations and their refreshes: 1.4; 1.1 without), and
  // plan_reserve of the time left is kept for checkpoints, the export and the
  // machine's drift; the defaults are the slowest of the measured mic runs,
  // rounded up (docs/training.md, "The time budget"; a per-CV step costs
  // more than a main-phase one since the main phase's occupancy refresh is
  // vectorized).
  float plan_cost_main = 1.0f;
  float plan_cost_per_cv = 1.3f;
  float plan_cost_qat = 1.4f;
  float plan_reserve = 0.05f;
  float per_cv_fraction = 0.45f;  // share of steps training per-CV MLPs in float
  float qat_fraction = 0.1f;      // share of steps of quantization-aware training (last)
  int64_t batch_samples = 65536;  // target samples evaluated per step
  int max_rays = 16384;           // rays per step, at most
  int min_rays = 256;             // rays per step, at least

  // --- optimiser ---
  float lr_features = 2e-2f;
  float lr_mlp = 2e-2f;
  float lr_final = 0.2f;       // the learning rate decays exponentially to this factor at the last step
  float qat_lr_scale = 0.33f;  // the learning rate is multiplied by this in the quantization-aware phase
  float block_lr_scale = 1.f;  // the feature blocks' learning rate (per-CV and quantization-aware phases) times this
  int64_t lr_warmup = 100;     // linear warm-up steps
  float adam_beta1 = 0.9f, adam_beta2 = 0.99f, adam_eps = 1e-15f;
  // Per pyramid level (coarsest first), the step from which it is read and
  // trained; before it the level's channels read zero (coarse to fine).
  // Empty: every level from step 0. Steps are absolute, so --minutes and
  // --resume see the same schedule.
  std::vector<int> level_unlock_steps;
  float tv_weight = 0.f;        // total variation on the pyramid's finest levels (main phase)
  int tv_levels = 1;            // how many of the finest levels tv_weight applies to
  float block_tv_weight = 0.f;  // total variation on the feature blocks, copies across faces included (later phases)
  // Decoupled smoothing (outside Adam): each step, every touched vertex of
  // the tv_levels finest pyramid levels (main phase) or of the blocks (later
  // phases) moves toward its neighbours by lr * weight * sum(neighbour -
  // value), lr the step's feature learning rate. Unlike tv_weight, whose
  // gradient Adam normalizes (a rarely seen vertex is then smoothed at the
  // full rate), the pull is proportional to the differences.
  float smooth_weight = 0.f;
  float block_smooth_weight = 0.f;
  float distortion_weight = 0.01f;  // distortion loss per ray (train/volume.h), distances in scene-box edges
  float mlp_tie_weight = 0.f;       // per-CV phases: squared distance of each MLP's weights to the MLPs' mean
  float init_features = 1e-4f;      // initial feature values: uniform in +-this
  // Running averages of the weights (the feature blocks and the MLPs), 0: off.
  // In the per-CV phase with ema_decay_per_cv per step: the quantization-aware
  // phase then starts from the average. In the quantization-aware phase with
  // ema_decay_qat: the exported model is the average. Each average starts
  // from its phase's first step and is updated every ema_every steps (with
  // the decay to that power).
  float ema_decay_per_cv = 0.f;
  float ema_decay_qat = 0.f;
  int ema_every = 4;

  // --- occupancy ---
  int occupancy_every = 16;       // steps between partial refreshes (one of 8 parts each)
  float occupancy_decay = 0.95f;  // decay per refresh of the running density maximum
  float occupancy_alpha = 0.01f;  // a voxel is occupied if its alpha at one step exceeds this
  int64_t aabb_start = 512;       // first AABB update
  int64_t aabb_every = 256;
  float aabb_filter_sigma = 0.6f;  // Gaussian filter of the occupancy, in micro voxels
  float aabb_keep = 0.35f;         // filtered occupancy kept in the AABB

  // --- scene box fitting (train/fit_box.h) ---
  // > 0: a pilot run of this many steps (all three phases and the pruning)
  // finds the object first (its model's AABB), and the run then trains from
  // the start in the smallest cube around it, fit_box_margin wider on each
  // side, inside scene_box (finer micro voxels for a small object). The
  // pilot's time counts against --minutes; a run of fewer than
  // kPilotShare (4) times its steps skips it (train/fit_box.h). 0: scene_box
  // as given.
  int64_t fit_box_steps = 1500;
  float fit_box_margin = 0.02f;  // scene units
  // 0: no limit; else the box is no smaller than one in which the pilot's
  // feature blocks, scaled to the box (train/fit_box.h), number at most this
  // many. A short pilot keeps more blocks than the finished model (lego: 1500
  // steps 15763, the 38134-step model 0.73 times that in the same box), so
  // this bounds the model's size (about 1 KB a block) with that margin.
  int64_t fit_box_max_blocks = 21000;

  // --- pruning ---
  float prune_weight = 1e-3f;         // at the start of quantization-aware training, micro voxels whose samples never
                                      // weighed (T alpha) this much in the per-CV phase are emptied; 0: keep all
  float prune_cv_weight = 0.2f;       // then also every coarse voxel none of whose samples weighed this much
                                      // (floaters: each occupied coarse voxel is an MLP the chip loads); 0: off
  float prune_part_fraction = 0.01f;  // then also every connected part of the occupied micro voxels smaller than
                                      // this fraction of the largest and apart from the box around the larger
                                      // ones (floaters that widen the AABB; train/occupancy.h); 0: off

  // --- quantization ---
  int quant_refit_every = 16;         // steps between refits of the INT4 feature ranges
  float mlp_equalize = 0.5f;          // at the start of quantization, cross-layer equalization of every MLP's hidden
                                      // units (equalize_mlp in mlp_kernels.h): 0 off, 1 full; the same function,
                                      // less INT8 error; not with mlp_tie_weight
  bool calibrate_activations = true;  // the exported INT8 MLPs' input steps chosen from the training rays'
                                      // samples (train/calibrate.h) instead of the largest input seen
  bool qat_activations = true;        // the quantization-aware phase also rounds every MLP layer's input to the
                                      // chip's INT8 steps (the steps the export would write, refreshed below)
  int qat_activations_every = 512;    // steps between refreshes of those steps (the first after
                                      // quant_refit_every steps of the phase, once the inputs' ranges are seen)

  // --- memory ---
  // The trainer's state (feature pyramid, occupancy, feature blocks with their
  // Adam moments) may not exceed this; checked when the run starts and at the freeze.
  double max_state_gib = limits::kDefaultTrainStateGiB;

  // --- run ---
  uint64_t seed = 0;
  int downscale = 1;  // image downscale factor when loading a dataset
  std::string split = "train";

  MlpArch mlp_arch() const;
  int feature_channels() const { return 4 * int(levels.size()); }
  float delta() const { return step_micro * (scene_box.hi.x - scene_box.lo.x) / float(micro_res); }
  // The step at which the occupancy freezes (the main phase ends) for `n` steps.
  int64_t freeze_step(int64_t n) const;
  // --minutes: the step count that fits `seconds_left` after `step` steps
  // that took `seconds_per_step` each (the plan_cost_* model above), at
  // least one more step and enough that the main phase is not over yet.
  int64_t plan_iters(int64_t step, double seconds_per_step, double seconds_left) const;
  // The model's seconds for steps `step`..`n` of a run of `n` steps.
  double planned_seconds(int64_t step, int64_t n, double seconds_per_step) const;
  // Bytes of the main phase's state: the occupancy grid and the feature
  // pyramid with its two Adam moments.
  uint64_t main_state_bytes() const;
  // Bytes of the per-CV and quantization phases' state for `blocks` feature
  // blocks: values, two Adam moments and the float snapshot.
  uint64_t block_state_bytes(uint64_t blocks) const;
  uint64_t max_state_bytes() const { return uint64_t(max_state_gib * double(uint64_t{1} << 30)); }
  // Throws Error naming the first invalid field.
  void validate() const;
};

// Applies a YAML preset on top of `base`. Unknown keys and bad values throw
// Error naming the file and the key.
TrainConfig load_train_config(const std::filesystem::path& path, TrainConfig base = {});
TrainConfig parse_train_config(const std::string& yaml_text, const std::string& source, TrainConfig base = {});
// The config as YAML (every field), for checkpoints and model metadata.
std::string to_yaml(const TrainConfig& config);

}  // namespace edrnr::train
