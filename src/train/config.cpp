#include "train/config.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <map>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "model/model_io.h"
#include "render/options.h"

namespace edrnr::train {

using limits::kMaxBatchSamples;
using limits::kMaxRaysPerStep;

MlpArch TrainConfig::mlp_arch() const {
  MlpArch a;
  a.dir_frequencies = dir_frequencies;
  a.density_widths.push_back(feature_channels());
  for (int w : density_hidden) a.density_widths.push_back(w);
  a.density_widths.push_back(geo_features);
  a.color_widths.push_back(geo_features + a.dir_dims());
  for (int w : color_hidden) a.color_widths.push_back(w);
  a.color_widths.push_back(3);
  return a;
}

int64_t TrainConfig::freeze_step(int64_t n) const {
  return std::max<int64_t>(1, int64_t(std::llround(double(n) * (1.0 - per_cv_fraction - qat_fraction))));
}

double TrainConfig::planned_seconds(int64_t step, int64_t n, double seconds_per_step) const {
  const int64_t freeze = freeze_step(n);
  const int64_t qat = std::max(freeze, int64_t(std::llround(double(n) * (1.0 - qat_fraction))));
  const auto span = [&](int64_t a, int64_t b) { return double(std::max<int64_t>(0, b - std::max(a, step))); };
  return seconds_per_step * (double(plan_cost_main) * span(step, freeze) +
                             double(plan_cost_per_cv) * span(freeze, qat) + double(plan_cost_qat) * span(qat, n));
}

int64_t TrainConfig::plan_iters(int64_t step, double seconds_per_step, double seconds_left) const {
  const double p = std::max(seconds_per_step, 1e-6);
  const double target = (1.0 - double(plan_reserve)) * std::max(seconds_left, 0.0);
  const double main_share = 1.0 - double(per_cv_fraction) - double(qat_fraction);
  // The model is linear in n but for the phase boundaries' rounding: solve it
  // without them, then step down while the rounded model is over the target.
  const double per_n = double(plan_cost_main) * main_share + double(plan_cost_per_cv) * double(per_cv_fraction) +
                       double(plan_cost_qat) * double(qat_fraction);
  const double guess = (target / p + double(plan_cost_main) * double(step)) / per_n;
  int64_t n = int64_t(std::min(guess, 1e9));
  while (n > step + 1 && planned_seconds(step, n, p) > target) --n;
  n = std::max(n, step + 1);
  // The main phase must not have ended already: a replay with --iters n
  // changes phase at the same step.
  return std::max<int64_t>(n, int64_t(std::ceil(double(step + 1) / main_share)) + 1);
}

uint64_t TrainConfig::main_state_bytes() const {
  const uint64_t R = uint64_t(micro_res);
  uint64_t pyramid = 0;
  for (int r : levels) pyramid += uint64_t(r) * uint64_t(r) * uint64_t(r) * 4 /* channels */ * 12 /* value, m, v */;
  return R * R * R * 4 /* density */ + R * R * R / 8 /* bitmap */ + pyramid;
}

uint64_t TrainConfig::block_state_bytes(uint64_t blocks) const {
  return blocks * uint64_t(kBlockVerts) * uint64_t(feature_channels()) * 16;
}

void TrainConfig::validate() const {
  for (int a = 0; a < 3; ++a)
    if (!(scene_box.hi[a] > scene_box.lo[a])) fail("train config: scene_box must have hi > lo on every axis");
  const float ex = scene_box.hi.x - scene_box.lo.x;
  for (int a = 1; a < 3; ++a)
    if (std::fabs((scene_box.hi[a] - scene_box.lo[a]) - ex) > 1e-6f * ex)
      fail("train config: scene_box must be a cube");
  if (micro_res < 32 || micro_res % 32 || micro_res > 1024)
    fail("train config: micro_res {} must be a multiple of 32 in [32, 1024]", micro_res);
  if (levels.empty()) fail("train config: levels must list at least one resolution");
  for (int r : levels)
    if (r <= 0 || r > micro_res || micro_res % r || !std::has_single_bit(unsigned(micro_res / r)))
      fail("train config: levels entry {} must divide micro_res {} by a power of two", r, micro_res);
  if (geo_features < 1) fail("train config: geo_features must be at least 1");
  if (geo_features > 256) fail("train config: geo_features {} is over the limit of 256", geo_features);
  if (levels.size() * 4 > size_t(kMaxFeatureChannels))
    fail("train config: {} levels make {} feature channels, over the limit of {}", levels.size(), levels.size() * 4,
         kMaxFeatureChannels);
  for (int w : density_hidden)
    if (w < 1 || w > 256) fail("train config: density_hidden widths must be in [1, 256]");
  for (int w : color_hidden)
    if (w < 1 || w > 256) fail("train config: color_hidden widths must be in [1, 256]");
  if (dir_frequencies < 0 || dir_frequencies > 8) fail("train config: dir_frequencies must be in [0, 8]");
  if (mlp_arch().q8_bytes() > kMlpCacheBytes)
    fail("train config: the MLP needs {} bytes in INT8, more than the {}-byte MLP cache", mlp_arch().q8_bytes(),
         kMlpCacheBytes);
  if (!(step_micro > 0.f)) fail("train config: step_micro must be positive");
  check_step_micro(step_micro, micro_res, "train config: step_micro");
  if (!(transmittance_min > 0.f && transmittance_min < 1.f)) fail("train config: transmittance_min must be in (0, 1)");
  if (iters < 1) fail("train config: iters must be at least 1");
  if (freeze_step(iters) >= iters) {
    const double after = double(per_cv_fraction) + double(qat_fraction);
    if (!(after > 0.0))
      fail(
          "train config: per_cv_fraction and qat_fraction are both 0: no step would follow the occupancy freeze, "
          "so no model could be exported");
    // From n >= 1/after + 1 on, at least one step follows the freeze.
    const double bound = std::min(1e15, std::ceil(1.0 / after) + 1.0);
    int64_t least = int64_t(bound);
    for (int64_t n = 2; n < std::min<int64_t>(least, 1000000); ++n)
      if (freeze_step(n) < n) {
        least = n;
        break;
      }
    fail(
        "train config: iters {} (--iters or the preset) is too few: training would end before the occupancy "
        "freezes at step {} (after {:.0f} % of the steps; per_cv_fraction and qat_fraction are the rest), so no "
        "model could be exported; give at least {} steps",
        iters, freeze_step(iters), 100.0 * (1.0 - per_cv_fraction - qat_fraction), least);
  }
  if (minutes < 0) fail("train config: minutes must not be negative");
  if (fit_box_steps < 0 ||
      (fit_box_steps > 0 && (fit_box_steps <= aabb_start || freeze_step(fit_box_steps) >= fit_box_steps)))
    fail(
        "train config: fit_box_steps {} must be 0 (off) or a pilot run's steps: more than aabb_start ({}), when "
        "the object is first found, with steps after the occupancy freezes",
        fit_box_steps, aabb_start);
  if (!(fit_box_margin >= 0.f)) fail("train config: fit_box_margin must not be negative");
  if (fit_box_max_blocks < 0) fail("train config: fit_box_max_blocks must not be negative (0: no limit)");
  if (!(depth_jitter >= 0.f && depth_jitter <= 1.f)) fail("train config: depth_jitter must be in [0, 1]");
  if (!(error_map_share >= 0.f && error_map_share < 1.f)) fail("train config: error_map_share must be in [0, 1)");
  if (error_map_cell < 1 || error_map_cell > 4096) fail("train config: error_map_cell must be in [1, 4096] pixels");
  if (plan_step < 10) fail("train config: plan_step must be at least 10");
  for (float c : {plan_cost_main, plan_cost_per_cv, plan_cost_qat})
    if (!(c > 0.f && c <= 10.f)) fail("train config: plan_cost_main, _per_cv and _qat must be in (0, 10]");
  if (!(plan_reserve >= 0.f && plan_reserve < 1.f)) fail("train config: plan_reserve must be in [0, 1)");
  if (!(per_cv_fraction >= 0.f && qat_fraction >= 0.f && per_cv_fraction + qat_fraction < 1.f))
    fail("train config: per_cv_fraction and qat_fraction must be >= 0 and sum to less than 1");
  if (batch_samples < 1024 || batch_samples > kMaxBatchSamples)
    fail("train config: batch_samples {} must be between 1024 and {} (limit)", batch_samples, kMaxBatchSamples);
  if (min_rays < 1 || max_rays < min_rays) fail("train config: need 1 <= min_rays <= max_rays");
  if (max_rays > kMaxRaysPerStep)
    fail("train config: max_rays {} is over the limit of {} rays per step", max_rays, kMaxRaysPerStep);
  if (!(lr_features > 0.f) || !(lr_mlp > 0.f)) fail("train config: learning rates must be positive");
  if (!(lr_final > 0.f && lr_final <= 1.f)) fail("train config: lr_final must be in (0, 1]");
  if (!(qat_lr_scale > 0.f && qat_lr_scale <= 100.f)) fail("train config: qat_lr_scale must be in (0, 100]");
  if (!(block_lr_scale > 0.f && block_lr_scale <= 100.f)) fail("train config: block_lr_scale must be in (0, 100]");
  if (lr_warmup < 0) fail("train config: lr_warmup must not be negative");
  if (!(adam_beta1 >= 0.f && adam_beta1 < 1.f && adam_beta2 >= 0.f && adam_beta2 < 1.f && adam_eps > 0.f))
    fail("train config: Adam needs 0 <= beta < 1 and eps > 0");
  if (!(tv_weight >= 0.f)) fail("train config: tv_weight must not be negative");
  if (tv_levels < 1 || tv_levels > int(levels.size()))
    fail("train config: tv_levels {} must be between 1 and the number of levels ({})", tv_levels, levels.size());
  static_assert(kMaxFeatureChannels / 4 <= 32, "the trainer's active-level masks have 32 bits");
  if (!level_unlock_steps.empty() && level_unlock_steps.size() != levels.size())
    fail("train config: level_unlock_steps has {} entries for {} levels (give one per level, or none)",
         level_unlock_steps.size(), levels.size());
  for (int s : level_unlock_steps)
    if (s < 0) fail("train config: level_unlock_steps entry {} must not be negative", s);
  if (!(block_tv_weight >= 0.f)) fail("train config: block_tv_weight must not be negative");
  // The largest rate a step applies (per neighbour) times the most neighbours
  // (6 in a grid, 9 for a block vertex with its copies) stays below 1, so a
  // step never overshoots the neighbours' mean. The pyramid is smoothed in
  // the main phase (learning rate at most lr_features), the blocks later.
  const float block_rate = lr_features * block_lr_scale * std::max(1.f, qat_lr_scale);
  if (!(smooth_weight >= 0.f && smooth_weight * lr_features * 6.f < 1.f))
    fail("train config: smooth_weight {} must be >= 0 and below 1 / (6 lr_features) = {}", smooth_weight,
         1.f / (6.f * lr_features));
  if (!(block_smooth_weight >= 0.f && block_smooth_weight * block_rate * 9.f < 1.f))
    fail(
        "train config: block_smooth_weight {} must be >= 0 and below 1 / (9 lr_features block_lr_scale max(1, "
        "qat_lr_scale)) = {}",
        block_smooth_weight, 1.f / (9.f * block_rate));
  if (!(distortion_weight >= 0.f)) fail("train config: distortion_weight must not be negative");
  if (!(mlp_tie_weight >= 0.f)) fail("train config: mlp_tie_weight must not be negative");
  for (float d : {ema_decay_per_cv, ema_decay_qat})
    if (!(d >= 0.f && d < 1.f)) fail("train config: ema_decay_per_cv and ema_decay_qat must be in [0, 1)");
  if (ema_every < 1 || ema_every > 1000) fail("train config: ema_every must be between 1 and 1000");
  if (!(init_features >= 0.f)) fail("train config: init_features must not be negative");
  if (occupancy_every < 1) fail("train config: occupancy_every must be at least 1");
  if (!(occupancy_decay > 0.f && occupancy_decay <= 1.f)) fail("train config: occupancy_decay must be in (0, 1]");
  if (!(occupancy_alpha > 0.f && occupancy_alpha < 1.f)) fail("train config: occupancy_alpha must be in (0, 1)");
  if (aabb_every < 1 || aabb_start < 0) fail("train config: aabb_every must be >= 1 and aabb_start >= 0");
  if (!(aabb_filter_sigma >= 0.f)) fail("train config: aabb_filter_sigma must not be negative");
  if (!(aabb_keep > 0.f && aabb_keep <= 1.f)) fail("train config: aabb_keep must be in (0, 1]");
  if (!(prune_weight >= 0.f && prune_weight < 1.f)) fail("train config: prune_weight must be in [0, 1)");
  if (!(prune_cv_weight >= 0.f && prune_cv_weight < 1.f)) fail("train config: prune_cv_weight must be in [0, 1)");
  if (!(prune_part_fraction >= 0.f && prune_part_fraction <= 1.f))
    fail("train config: prune_part_fraction must be in [0, 1]");
  if (quant_refit_every < 1) fail("train config: quant_refit_every must be at least 1");
  if (qat_activations_every < 1) fail("train config: qat_activations_every must be at least 1");
  if (!(mlp_equalize >= 0.f && mlp_equalize <= 1.f)) fail("train config: mlp_equalize must be in [0, 1]");
  if (mlp_equalize > 0.f && mlp_tie_weight > 0.f)
    fail(
        "train config: mlp_equalize and mlp_tie_weight cannot both be on: equalization rescales each MLP's hidden "
        "units differently, so the MLPs' mean the tie pulls toward is no longer a meaningful MLP (set mlp_equalize: 0 "
        "to use the tie)");
  if (downscale < 1) fail("train config: downscale must be at least 1");
  for (float b : background)
    if (!(b >= 0.f && b <= 1.f)) fail("train config: background values must be in [0, 1]");
  if (!(max_state_gib > 0.0 && max_state_gib <= 1024.0))
    fail("train config: max_state_gib {} must be in (0, 1024]", max_state_gib);
  if (main_state_bytes() > max_state_bytes())
    fail(
        "train config: micro_res {} with levels [{}] needs {:.2f} GiB for the occupancy grid and the feature "
        "pyramid, over the limit max_state_gib = {} GiB",
        micro_res, fmt::join(levels, ", "), double(main_state_bytes()) / double(uint64_t{1} << 30), max_state_gib);
}

namespace {

struct Field {
  std::function<void(TrainConfig&, const YAML::Node&)> read;
  std::function<std::string(const TrainConfig&)> write;
};

template <class T>
Field scalar(T TrainConfig::*member) {
  return {[member](TrainConfig& c, const YAML::Node& n) { c.*member = n.as<T>(); },
          [member](const TrainConfig& c) { return fmt::format("{}", c.*member); }};
}

Field int_list(std::vector<int> TrainConfig::*member) {
  return {[member](TrainConfig& c, const YAML::Node& n) { c.*member = n.as<std::vector<int>>(); },
          [member](const TrainConfig& c) { return fmt::format("[{}]", fmt::join(c.*member, ", ")); }};
}

const std::map<std::string, Field>& fields() {
  static const std::map<std::string, Field> f = {
      {"scene_box",
       {[](TrainConfig& c, const YAML::Node& n) {
          auto v = n.as<std::vector<float>>();
          if (v.size() == 2) {
            c.scene_box = {{v[0], v[0], v[0]}, {v[1], v[1], v[1]}};
          } else if (v.size() == 6) {
            c.scene_box = {{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
          } else {
            throw YAML::Exception(n.Mark(), "expected [lo, hi] or [x0, y0, z0, x1, y1, z1]");
          }
        },
        [](const TrainConfig& c) {
          return fmt::format("[{}, {}, {}, {}, {}, {}]", c.scene_box.lo.x, c.scene_box.lo.y, c.scene_box.lo.z,
                             c.scene_box.hi.x, c.scene_box.hi.y, c.scene_box.hi.z);
        }}},
      {"micro_res", scalar(&TrainConfig::micro_res)},
      {"levels", int_list(&TrainConfig::levels)},
      {"density_hidden", int_list(&TrainConfig::density_hidden)},
      {"geo_features", scalar(&TrainConfig::geo_features)},
      {"color_hidden", int_list(&TrainConfig::color_hidden)},
      {"dir_frequencies", scalar(&TrainConfig::dir_frequencies)},
      {"step_micro", scalar(&TrainConfig::step_micro)},
      {"transmittance_min", scalar(&TrainConfig::transmittance_min)},
      {"background",
       {[](TrainConfig& c, const YAML::Node& n) {
          auto v = n.as<std::vector<float>>();
          if (v.size() != 3) throw YAML::Exception(n.Mark(), "expected [r, g, b]");
          for (int i = 0; i < 3; ++i) c.background[i] = v[size_t(i)];
        },
        [](const TrainConfig& c) {
          return fmt::format("[{}, {}, {}]", c.background[0], c.background[1], c.background[2]);
        }}},
      {"random_background", scalar(&TrainConfig::random_background)},
      {"pixel_jitter", scalar(&TrainConfig::pixel_jitter)},
      {"depth_jitter", scalar(&TrainConfig::depth_jitter)},
      {"error_map_share", scalar(&TrainConfig::error_map_share)},
      {"error_map_cell", scalar(&TrainConfig::error_map_cell)},
      {"error_map_unbiased", scalar(&TrainConfig::error_map_unbiased)},
      {"iters", scalar(&TrainConfig::iters)},
      {"minutes", scalar(&TrainConfig::minutes)},
      {"plan_step", scalar(&TrainConfig::plan_step)},
      {"plan_cost_main", scalar(&TrainConfig::plan_cost_main)},
      {"plan_cost_per_cv", scalar(&TrainConfig::plan_cost_per_cv)},
      {"plan_cost_qat", scalar(&TrainConfig::plan_cost_qat)},
      {"plan_reserve", scalar(&TrainConfig::plan_reserve)},
      {"fit_box_steps", scalar(&TrainConfig::fit_box_steps)},
      {"fit_box_margin", scalar(&TrainConfig::fit_box_margin)},
      {"fit_box_max_blocks", scalar(&TrainConfig::fit_box_max_blocks)},
      {"per_cv_fraction", scalar(&TrainConfig::per_cv_fraction)},
      {"qat_fraction", scalar(&TrainConfig::qat_fraction)},
      {"batch_samples", scalar(&TrainConfig::batch_samples)},
      {"max_rays", scalar(&TrainConfig::max_rays)},
      {"min_rays", scalar(&TrainConfig::min_rays)},
      {"lr_features", scalar(&TrainConfig::lr_features)},
      {"lr_mlp", scalar(&TrainConfig::lr_mlp)},
      {"lr_final", scalar(&TrainConfig::lr_final)},
      {"qat_lr_scale", scalar(&TrainConfig::qat_lr_scale)},
      {"block_lr_scale", scalar(&TrainConfig::block_lr_scale)},
      {"lr_warmup", scalar(&TrainConfig::lr_warmup)},
      {"adam_beta1", scalar(&TrainConfig::adam_beta1)},
      {"adam_beta2", scalar(&TrainConfig::adam_beta2)},
      {"adam_eps", scalar(&TrainConfig::adam_eps)},
      {"tv_weight", scalar(&TrainConfig::tv_weight)},
      {"tv_levels", scalar(&TrainConfig::tv_levels)},
      {"level_unlock_steps", int_list(&TrainConfig::level_unlock_steps)},
      {"block_tv_weight", scalar(&TrainConfig::block_tv_weight)},
      {"smooth_weight", scalar(&TrainConfig::smooth_weight)},
      {"block_smooth_weight", scalar(&TrainConfig::block_smooth_weight)},
      {"distortion_weight", scalar(&TrainConfig::distortion_weight)},
      {"mlp_tie_weight", scalar(&TrainConfig::mlp_tie_weight)},
      {"ema_decay_per_cv", scalar(&TrainConfig::ema_decay_per_cv)},
      {"ema_decay_qat", scalar(&TrainConfig::ema_decay_qat)},
      {"ema_every", scalar(&TrainConfig::ema_every)},
      {"init_features", scalar(&TrainConfig::init_features)},
      {"occupancy_every", scalar(&TrainConfig::occupancy_every)},
      {"occupancy_decay", scalar(&TrainConfig::occupancy_decay)},
      {"occupancy_alpha", scalar(&TrainConfig::occupancy_alpha)},
      {"aabb_start", scalar(&TrainConfig::aabb_start)},
      {"aabb_every", scalar(&TrainConfig::aabb_every)},
      {"aabb_filter_sigma", scalar(&TrainConfig::aabb_filter_sigma)},
      {"aabb_keep", scalar(&TrainConfig::aabb_keep)},
      {"prune_weight", scalar(&TrainConfig::prune_weight)},
      {"prune_cv_weight", scalar(&TrainConfig::prune_cv_weight)},
      {"prune_part_fraction", scalar(&TrainConfig::prune_part_fraction)},
      {"quant_refit_every", scalar(&TrainConfig::quant_refit_every)},
      {"mlp_equalize", scalar(&TrainConfig::mlp_equalize)},
      {"calibrate_activations", scalar(&TrainConfig::calibrate_activations)},
      {"qat_activations", scalar(&TrainConfig::qat_activations)},
      {"qat_activations_every", scalar(&TrainConfig::qat_activations_every)},
      {"max_state_gib", scalar(&TrainConfig::max_state_gib)},
      {"seed", scalar(&TrainConfig::seed)},
      {"downscale", scalar(&TrainConfig::downscale)},
      {"split", scalar(&TrainConfig::split)},
  };
  return f;
}

}  // namespace

TrainConfig parse_train_config(const std::string& yaml_text, const std::string& source, TrainConfig base) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    fail("{}: not valid YAML: {}", source, e.what());
  }
  if (root.IsNull()) return base;
  if (!root.IsMap()) fail("{}: expected a mapping of setting: value", source);
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    auto it = fields().find(key);
    if (it == fields().end()) fail("{}: unknown setting '{}'", source, key);
    try {
      it->second.read(base, kv.second);
    } catch (const YAML::Exception& e) {
      fail("{}: setting '{}' has a bad value (line {}): {}", source, key, e.mark.line + 1, e.msg);
    }
  }
  try {
    base.validate();
  } catch (const Error& e) {
    fail("{}: {}", source, e.what());
  }
  return base;
}

TrainConfig load_train_config(const std::filesystem::path& path, TrainConfig base) {
  return parse_train_config(read_file_text(path), path.string(), std::move(base));
}

std::string to_yaml(const TrainConfig& config) {
  std::string out;
  for (const auto& [key, field] : fields()) out += fmt::format("{}: {}\n", key, field.write(config));
  return out;
}

}  // namespace edrnr::train
