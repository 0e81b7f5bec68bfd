#pragma once
// Fitting the scene box to the object (TrainConfig::fit_box_steps): a short
// pilot run finds where the object is, and the run proper trains in the
// smallest cube around it, so that its micro voxels (micro_res across the
// box, fixed by the chip) are as fine as the object allows.
#include "core/vec.h"
#include "data/dataset.h"
#include "train/config.h"
#include "train/trainer.h"

namespace edrnr::train {

// The smallest cube of side at least min_side holding `object` widened by
// `margin` on every side, centred on it and moved (not shrunk) to lie
// inside `within`; `within` itself when the cube would be as large.
// `within` must be a cube.
Box3f cube_around(const Box3f& object, float margin, const Box3f& within, float min_side = 0.f);

// The least side of a box in which `blocks` feature blocks, counted in a box
// of side `side`, would become at most max_blocks: a block covers a fine
// voxel, and the occupied fine voxels of a surface grow as the voxels shrink,
// with exponent 2.5 (measured on the validation splits: lego 1.69 times the
// blocks and mic 2.34 times for voxels 1.23 and 1.40 times finer; a plain
// area would give 2). 0 when max_blocks is 0 (no limit) or blocks is 0.
float least_side_for_blocks(size_t blocks, float side, size_t max_blocks);

struct BoxFit {
  TrainConfig config;  // the run proper: scene_box fitted, fit_box_steps 0, minutes less the pilot's time
  Box3f object;        // the pilot's object AABB
  size_t pilot_blocks = 0;
  double seconds = 0;  // the pilot's wall time
};

// Runs the pilot: cfg with cfg.fit_box_steps steps, all phases (the pruning
// removes floaters), with options' threads and interrupt, no checkpoints;
// the object is its model's AABB, and the box is no smaller than
// least_side_for_blocks allows for cfg.fit_box_max_blocks. Deterministic as the trainer is: the same
// dataset, config and seed give the same box for any thread count. Throws
// Error if interrupted. Precondition: cfg.fit_box_steps > 0 and cfg valid.
BoxFit fit_scene_box(const Dataset& data, const TrainConfig& cfg, const TrainOptions& options);

// Whether cfg's pilot is run: cfg.fit_box_steps > 0, and the run is a time
// budget (cfg.minutes > 0) or has at least kPilotShare times the pilot's
// steps. A shorter run (a quick try, a test) keeps scene_box as given: the
// pilot would cost more than the finer voxels give back. A --minutes run
// always pilots, so --iters with its planned count repeats it only when that
// count is at least kPilotShare times the pilot's steps; the run's resolved
// config (fitted box, fit_box_steps 0) with --iters repeats it in any case.
constexpr int64_t kPilotShare = 4;
bool pilot_pays(const TrainConfig& cfg);

}  // namespace edrnr::train
