#include "train/fit_box.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/error.h"

namespace edrnr::train {

Box3f cube_around(const Box3f& object, float margin, const Box3f& within, float min_side) {
  const float limit = within.hi.x - within.lo.x;
  float side = min_side;
  for (int a = 0; a < 3; ++a) side = std::max(side, object.hi[a] - object.lo[a] + 2.f * margin);
  if (!(side < limit)) return within;
  Box3f b;
  for (int a = 0; a < 3; ++a) {
    const float centre = 0.5f * (object.lo[a] + object.hi[a]);
    b.lo[a] = std::clamp(centre - 0.5f * side, within.lo[a], within.hi[a] - side);
    b.hi[a] = b.lo[a] + side;
  }
  return b;
}

float least_side_for_blocks(size_t blocks, float side, size_t max_blocks) {
  if (max_blocks == 0 || blocks == 0) return 0.f;
  return float(double(side) * std::pow(double(blocks) / double(max_blocks), 1.0 / 2.5));
}

bool pilot_pays(const TrainConfig& cfg) {
  return cfg.fit_box_steps > 0 && (cfg.minutes > 0 || cfg.iters >= kPilotShare * cfg.fit_box_steps);
}

BoxFit fit_scene_box(const Dataset& data, const TrainConfig& cfg, const TrainOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  TrainConfig pilot = cfg;
  pilot.fit_box_steps = 0;
  pilot.minutes = 0;
  pilot.iters = cfg.fit_box_steps;
  Trainer trainer(data, pilot);
  TrainOptions o;
  o.threads = options.threads;
  o.interrupt = options.interrupt;
  if (!trainer.run(o))
    fail("interrupted during the pilot run that fits the scene box (step {} of {}); nothing to resume: run again",
         trainer.stats().step, cfg.fit_box_steps);
  BoxFit fit;
  const SceneModel pilot_model = trainer.export_model(false);
  fit.object = pilot_model.object_aabb;
  fit.pilot_blocks = pilot_model.block_count();
  fit.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fit.config = cfg;
  fit.config.fit_box_steps = 0;
  const float side = cfg.scene_box.hi.x - cfg.scene_box.lo.x;
  fit.config.scene_box = cube_around(fit.object, cfg.fit_box_margin, cfg.scene_box,
                                     least_side_for_blocks(fit.pilot_blocks, side, size_t(cfg.fit_box_max_blocks)));
  if (cfg.minutes > 0) fit.config.minutes = std::max(cfg.minutes - fit.seconds / 60.0, 1.0 / 60.0);
  if (options.log) {
    const Box3f& b = fit.config.scene_box;
    options.log(
        fmt::format("scene box fitted in {:.1f} s ({} pilot steps, {} blocks): object [{:.3f}, {:.3f}, {:.3f}] .. "
                    "[{:.3f}, {:.3f}, {:.3f}], "
                    "box [{:.3f}, {:.3f}, {:.3f}] .. [{:.3f}, {:.3f}, {:.3f}] (side {:.3f}, was {:.3f})",
                    fit.seconds, cfg.fit_box_steps, fit.pilot_blocks, fit.object.lo.x, fit.object.lo.y, fit.object.lo.z,
                    fit.object.hi.x, fit.object.hi.y, fit.object.hi.z, b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z,
                    b.hi.x - b.lo.x, side));
  }
  return fit;
}

}  // namespace edrnr::train
