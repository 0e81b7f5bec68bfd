// The trainer (train/trainer.h): Trainer::State's set-up and one training
// step, and the public Trainer methods (run, render, stats, ...). The rest of
// Trainer::State is in trainer_sampling.cpp, trainer_phases.cpp and
// trainer_io.cpp (train/trainer_state.h).
#include "train/trainer.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/file_io.h"
#include "render/traversal.h"
#include "train/adam.h"
#include "train/checkpoint_io.h"
#include "train/mlp_kernels.h"
#include "train/trainer_state.h"

namespace edrnr::train {

using trainer_detail::Batch;
using trainer_detail::kStageNames;
using trainer_detail::kStages;
using trainer_detail::Stage;
using enum trainer_detail::Stage;

const char* phase_name(Phase p) {
  switch (p) {
    case Phase::Main:
      return "main";
    case Phase::PerCv:
      return "per-CV";
    case Phase::Quantize:
      return "quantize";
    case Phase::Done:
      return "done";
  }
  return "?";
}

// --- set-up ----------------------------------------------------------------

Trainer::State::State(const Dataset& d, const TrainConfig& c)
    : data(d), cfg(c), arch(c.mlp_arch()), layout(arch), occ(c.micro_res) {
  cfg.validate();
  F = cfg.feature_channels();
  G = cfg.geo_features;
  DD = arch.dir_dims();
  geometry.scene_box = cfg.scene_box;
  geometry.micro_res = cfg.micro_res;
  delta = sample_spacing(geometry, cfg.step_micro);
  if (data.frames.empty()) fail("dataset {}: no frames to train on", data.root.string());
  pixel_start.push_back(0);
  rgba = data.frames[0].image.channels == 4;
  for (const auto& f : data.frames) {
    const int ch = rgba ? 4 : 3;
    if (f.image.width <= 0 || f.image.height <= 0 || f.image.channels != ch ||
        f.image.data.size() != size_t(f.image.width) * f.image.height * size_t(ch))
      fail("dataset {}: frame {} has no RGB image loaded (or not the same channels as the first frame)",
           data.root.string(), f.image_path.string());
    if (f.camera.width != f.image.width || f.camera.height != f.image.height)
      fail("dataset {}: frame {} image is {}x{} but its camera is {}x{}", data.root.string(), f.image_path.string(),
           f.image.width, f.image.height, f.camera.width, f.camera.height);
    pixel_start.push_back(pixel_start.back() + uint64_t(f.image.width) * uint64_t(f.image.height));
  }
  iters = cfg.iters;
  init_error_map();
}

void Trainer::State::fresh_init() {
  pyramid = FeaturePyramid(cfg.micro_res, cfg.levels, cfg.seed, cfg.init_features);
  n_mlps = 1;
  mlp_params.assign(layout.param_count, 0.f);
  init_mlp_params(layout, cfg.seed, mlp_params.data());
  mlp_m.assign(mlp_params.size(), 0.f);
  mlp_v.assign(mlp_params.size(), 0.f);
  n_rays = int(std::clamp<int64_t>(cfg.batch_samples / 256, cfg.min_rays, cfg.max_rays));
}

// --- the step -------------------------------------------------------------

// The pyramid levels read and trained at main-phase step s (bit l: level l).
uint32_t Trainer::State::active_levels(int64_t s) const {
  uint32_t mask = 0;
  for (size_t l = 0; l < cfg.levels.size(); ++l)
    if (cfg.level_unlock_steps.empty() || s >= cfg.level_unlock_steps[l]) mask |= 1u << l;
  return mask;
}

void Trainer::State::do_step() {
  if (phase == Phase::Done) return;
  using clock = std::chrono::steady_clock;
  auto t = clock::now();
  auto lap = [&](Stage st) {
    const auto now = clock::now();
    stage_s[st] += std::chrono::duration<double>(now - t).count();
    t = now;
  };
  if (phase == Phase::Main && step >= freeze_step()) freeze();
  if (phase == Phase::PerCv && step >= qat_step()) start_quantization();
  lap(kPhase);
  if (phase == Phase::Main) {
    pyramid.set_active_levels(active_levels(step));
    if (step % cfg.occupancy_every == 0) refresh_occupancy();
    if (step >= cfg.aabb_start && (step - cfg.aabb_start) % cfg.aabb_every == 0) update_aabb();
  }
  lap(kOccupancy);
  if (phase == Phase::Quantize) {
    if ((step - qat_step()) % cfg.quant_refit_every == 0 && step != qat_step()) {
      feature_quant = blocks.fit_quantization();
      blocks.set_quantization(feature_quant);
    }
    update_fake_quantized_mlps();
    const int64_t since = step - qat_step() - cfg.quant_refit_every;
    if (cfg.qat_activations && since >= 0 && since % cfg.qat_activations_every == 0) refresh_activation_steps();
  }
  lap(kPhase);

  Batch& b = batch;
  sample_training_rays(b, n_rays);
  lap(kRays);
  const double density_before = stage_s[kDensity];
  march(b);
  lap(kMarch);
  stage_s[kMarch] -= stage_s[kDensity] - density_before;
  evaluate_color(b);
  lap(kColor);
  const double se = composite_rays(b, true);
  update_error_map(b);
  if (phase == Phase::PerCv && !max_weight.empty())
    for (int32_t s : b.order) {
      const size_t cell = size_t(
          linear_index(b.micro[3 * size_t(s)], b.micro[3 * size_t(s) + 1], b.micro[3 * size_t(s) + 2], cfg.micro_res));
      max_weight[cell] = std::max(max_weight[cell], b.weight[size_t(s)]);
    }
  lap(kComposite);
  std::vector<float> grad;
  backward_mlps(b, grad, phase == Phase::Quantize);
  if (phase != Phase::Main) add_mlp_tie_gradient(grad);
  lap(kBackward);

  // Feature gradients, slab by slab.
  std::vector<int32_t> active_ids;
  active_ids.reserve(b.order.size());
  for (size_t s = 0; s < b.n_samples; ++s)
    if (b.active[s]) active_ids.push_back(int32_t(s));
  GradientSlabs slabs;
  const float lr = lr_factor(step) * (phase == Phase::Quantize ? cfg.qat_lr_scale : 1.f);
  if (phase == Phase::Main) {
    slabs.build(cfg.micro_res, pyramid.slab_micro(), active_ids, b.micro);
    pyramid.scatter_gradients(slabs, b.pos, b.micro, b.d_feat);
    pyramid.add_tv_gradient(cfg.tv_weight, cfg.tv_levels);
    pyramid.smooth(cfg.smooth_weight * cfg.lr_features * lr, cfg.tv_levels);
    lap(kScatter);
    ++feature_adam_t;
    pyramid.adam_step(AdamStep(adam_settings(), cfg.lr_features * lr, feature_adam_t));
  } else {
    slabs.build(cfg.micro_res, kMicroPerFine, active_ids, b.micro);
    blocks.scatter_gradients(slabs, b.pos, b.micro, b.d_feat);
    blocks.add_tv_gradient(cfg.block_tv_weight);
    blocks.smooth(cfg.block_smooth_weight * cfg.lr_features * cfg.block_lr_scale * lr);
    lap(kScatter);
    ++feature_adam_t;
    blocks.adam_step(AdamStep(adam_settings(), cfg.lr_features * cfg.block_lr_scale * lr, feature_adam_t));
  }
  ++mlp_adam_t;
  const AdamStep mstep(adam_settings(), cfg.lr_mlp * lr, mlp_adam_t);
  const int64_t np = int64_t(mlp_params.size());
#pragma omp parallel for schedule(static)
  for (int64_t k = 0; k < np; ++k)
    mstep.update(mlp_params[size_t(k)], mlp_m[size_t(k)], mlp_v[size_t(k)], grad[size_t(k)]);
  update_ema();
  lap(kAdam);

  // Running error and the next batch size.
  const double mse = se / (3.0 * b.n_rays);
  mse_ema = mse_ema < 0 ? mse : 0.95 * mse_ema + 0.05 * mse;
  last_rays = b.n_rays;
  last_samples = int64_t(b.n_samples);
  const double ratio = double(cfg.batch_samples) / double(std::max<size_t>(1, b.n_samples));
  n_rays = int(std::clamp<double>(std::round(b.n_rays * std::clamp(ratio, 0.5, 2.0)), cfg.min_rays, cfg.max_rays));
  ++step;
  if (step >= iters) {
    psnr_quantized = mse_ema > 0 ? -10.0 * std::log10(mse_ema) : 0;
    if (phase != Phase::Quantize) psnr_float = psnr_quantized;
    take_ema();
    phase = Phase::Done;
    update_fake_quantized_mlps();  // render() then reads the weights export_model(true) writes
  }
}

void Trainer::State::update_ema() {
  const float d = ema_decay();
  if (!(d > 0.f)) return;
  std::vector<float>& values = blocks.values();
  if (ema_blocks.empty()) {
    ema_blocks = values;
    ema_mlps = mlp_params;
    return;
  }
  if (step % cfg.ema_every != 0) return;
  float dk = 1.f;  // d^ema_every by repeated products (the same bits everywhere, unlike pow)
  for (int i = 0; i < cfg.ema_every; ++i) dk *= d;
  const float w = 1.f - dk;
  const int64_t n = int64_t(values.size());
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) ema_blocks[size_t(i)] += w * (values[size_t(i)] - ema_blocks[size_t(i)]);
  for (size_t i = 0; i < mlp_params.size(); ++i) ema_mlps[i] += w * (mlp_params[i] - ema_mlps[i]);
}

void Trainer::State::take_ema() {
  if (ema_blocks.empty()) return;
  blocks.values() = std::move(ema_blocks);
  mlp_params = std::move(ema_mlps);
  ema_blocks.clear();
  ema_mlps.clear();
}

// Pulls every per-CV MLP toward the mean of all of them (mlp_tie_weight):
// an MLP seen by few samples stays near what the others agree on.
void Trainer::State::add_mlp_tie_gradient(std::vector<float>& grad) const {
  if (!(cfg.mlp_tie_weight > 0.f) || n_mlps < 2) return;
  const size_t P = layout.param_count;
  std::vector<double> mean(P, 0.0);
  for (int m = 0; m < n_mlps; ++m)
    for (size_t k = 0; k < P; ++k) mean[k] += mlp_params[size_t(m) * P + k];
  for (size_t k = 0; k < P; ++k) mean[k] /= double(n_mlps);
  for (int m = 0; m < n_mlps; ++m)
    for (size_t k = 0; k < P; ++k)
      grad[size_t(m) * P + k] += 2.f * cfg.mlp_tie_weight * float(double(mlp_params[size_t(m) * P + k]) - mean[k]);
}

// Cross-layer equalization of every MLP (the same functions; less INT8 error).
void Trainer::State::equalize_mlps() {
  const size_t P = layout.param_count;
  for (int m = 0; m < n_mlps; ++m)
    equalize_mlp(layout, cfg.mlp_equalize, &mlp_params[size_t(m) * P], &mlp_m[size_t(m) * P], &mlp_v[size_t(m) * P]);
}

void Trainer::State::update_fake_quantized_mlps() {
  mlp_eff.resize(mlp_params.size());
  for (int m = 0; m < n_mlps; ++m)
    fake_quantize_mlp(layout, &mlp_params[size_t(m) * layout.param_count], &mlp_eff[size_t(m) * layout.param_count]);
}

// The INT8 input step of every MLP layer as the export would write it now
// (calibrated on the training rays with calibrate_activations, else the
// largest input seen / 127): the later steps of the quantization-aware phase
// round the activations to these, so the MLPs learn the chip's arithmetic.
void Trainer::State::refresh_activation_steps() {
  SceneModel m = make_model(true, false);
  const size_t n_layers = layout.density.size() + layout.color.size();
  act_steps.assign(size_t(n_mlps) * n_layers, 1.f);
  for (size_t mi = 0; mi < m.mlps_q8.size(); ++mi)
    for (size_t k = 0; k < n_layers; ++k) act_steps[mi * n_layers + k] = mlp_layer(m.mlps_q8[mi], k).in_scale;
}

AdamSettings Trainer::State::adam_settings() const { return {cfg.adam_beta1, cfg.adam_beta2, cfg.adam_eps}; }

// ---------------------------------------------------------------------------

Trainer::Trainer(const Dataset& data, const TrainConfig& config) : s_(std::make_unique<State>(data, config)) {
  s_->fresh_init();
}

Trainer::Trainer(const Dataset& data, const std::vector<uint8_t>& checkpoint, const std::string& source) {
  CheckpointReader r(checkpoint, source);
  TrainConfig cfg = parse_train_config(r.get_string("config"), source + " (config)");
  s_ = std::make_unique<State>(data, cfg);
  s_->load(r);
}

Trainer::~Trainer() = default;

TrainConfig Trainer::checkpoint_config(const std::vector<uint8_t>& checkpoint, const std::string& source) {
  CheckpointReader r(checkpoint, source);
  return parse_train_config(r.get_string("config"), source + " (config)");
}

const TrainConfig& Trainer::config() const { return s_->cfg; }
bool Trainer::done() const { return s_->phase == Phase::Done; }
void Trainer::step() { s_->do_step(); }
std::vector<uint8_t> Trainer::checkpoint() const { return s_->save(); }
SceneModel Trainer::export_model(bool quantized) const { return s_->make_model(quantized); }

void Trainer::set_iters(int64_t iters) {
  if (s_->phase != Phase::Main || iters <= s_->step) fail("set_iters: too late to change the number of steps");
  s_->iters = iters;
  s_->iters_fixed = true;
}

TrainStats Trainer::stats() const {
  TrainStats t;
  t.step = s_->step;
  t.iters = s_->iters;
  t.phase = s_->phase;
  t.rays = s_->last_rays;
  t.samples = s_->last_samples;
  t.loss = std::max(0.0, s_->mse_ema);
  t.psnr = s_->mse_ema > 0 ? -10.0 * std::log10(s_->mse_ema) : 0.0;
  t.psnr_float = s_->psnr_float;
  t.psnr_quantized = s_->psnr_quantized;
  t.blocks = s_->phase == Phase::Main ? 0 : s_->blocks.block_count();
  t.mlps = s_->phase == Phase::Main ? 0 : s_->mlp_cv.size();
  for (int i = 0; i < kStages; ++i) t.stage_seconds.emplace_back(kStageNames[i], s_->stage_s[i]);
  return t;
}

Image Trainer::render(const Camera& camera) const {
  State& s = *s_;
  Image img(camera.width, camera.height, 3);
  const int64_t n = int64_t(camera.width) * camera.height;
  constexpr int kRaysPerBatch = 4096;
  Batch b;
  for (int64_t first = 0; first < n; first += kRaysPerBatch) {
    const int cnt = int(std::min<int64_t>(kRaysPerBatch, n - first));
    s.resize_rays(b, cnt);
    for (int i = 0; i < cnt; ++i) {
      const int64_t p = first + i;
      s.set_ray(b, i, camera.pixel_ray(int(p % camera.width), int(p / camera.width)));
      for (int c = 0; c < 3; ++c) {
        b.target[3 * size_t(i) + size_t(c)] = 0.f;
        b.background[3 * size_t(i) + size_t(c)] = s.cfg.background[c];
      }
    }
    s.forward(b);
    for (int i = 0; i < cnt; ++i) {
      const int64_t p = first + i;
      float* px = img.at(int(p % camera.width), int(p / camera.width));
      for (int c = 0; c < 3; ++c) px[c] = b.pixel[3 * size_t(i) + size_t(c)];
    }
  }
  return img;
}

bool Trainer::run(const TrainOptions& options) {
  State& s = *s_;
  if (options.threads > 0) omp_set_num_threads(options.threads);
  using clock = std::chrono::steady_clock;
  const auto t_start = clock::now();
  auto t_checkpoint = t_start;
  auto t_print = t_start;
  double steps_per_s = 0;
  int64_t rate_step = s.step;
  auto rate_time = t_start;
  // --minutes: the time at each step of this run, to fix the step count at
  // plan_step (or once a quarter of the budget is spent) from the speed over
  // the last 40 % of the steps since the run started.
  std::vector<double> step_seconds;
  auto log = [&](const std::string& m) {
    if (options.log) options.log(m);
  };
  auto write_checkpoint = [&]() {
    if (options.checkpoint_path.empty()) return;
    const auto t0 = clock::now();
    const std::vector<uint8_t> bytes = s.save();
    write_file_atomic(options.checkpoint_path, bytes);
    log(fmt::format("checkpoint at step {} written to {} ({:.2f} GB in {:.1f} s)", s.step,
                    options.checkpoint_path.string(), double(bytes.size()) * 1e-9,
                    std::chrono::duration<double>(clock::now() - t0).count()));
  };
  // A periodic checkpoint is a safety net: failing to write one (a full disk)
  // must not end the run it protects. The previous checkpoint stays intact.
  auto try_periodic_checkpoint = [&]() {
    try {
      write_checkpoint();
    } catch (const Error& e) {
      const std::string m = fmt::format("checkpoint at step {} not written ({}); training goes on", s.step, e.what());
      if (options.warn)
        options.warn(m);
      else
        std::fprintf(stderr, "edrnr: warning: %s\n", m.c_str());
    }
  };
  Phase last_phase = s.phase;
  bool line_open = false;
  // Each phase's speed in this run, logged when it ends (a check of the
  // plan_cost_* model), and the plan's expected end.
  double planned_end = -1;
  int64_t phase_step = s.step;
  auto phase_time = t_start;
  auto log_phase_time = [&](clock::time_point now) {
    const double sec = std::chrono::duration<double>(now - phase_time).count();
    const int64_t n = s.step - phase_step;
    if (n > 0)
      log(fmt::format("{} phase: {} steps in {:.1f} s ({:.4f} s per step)", phase_name(last_phase), n, sec,
                      sec / double(n)));
    phase_step = s.step;
    phase_time = now;
  };
  while (s.phase != Phase::Done) {
    if (options.stop_after >= 0 && s.step >= options.stop_after) break;
    if (options.interrupt && options.interrupt->load()) break;
    // --minutes: fix the number of steps from the measured speed.
    if (s.cfg.minutes > 0 && !s.iters_fixed && s.phase == Phase::Main) {
      const double elapsed = std::chrono::duration<double>(clock::now() - t_start).count();
      step_seconds.push_back(elapsed);
      const int64_t done = int64_t(step_seconds.size()) - 1;  // steps timed in this run
      if (done >= 10 && (s.step >= s.cfg.plan_step || elapsed >= 0.25 * s.cfg.minutes * 60.0)) {
        const int64_t from = done * 6 / 10;
        const double per_step = (elapsed - step_seconds[size_t(from)]) / double(done - from);
        const double left = s.cfg.minutes * 60.0 - elapsed;
        set_iters(s.cfg.plan_iters(s.step, per_step, left));
        planned_end = elapsed + s.cfg.planned_seconds(s.step, s.iters, per_step);
        log(
            fmt::format("{:.3f} s per step over steps {}..{} ({:.1f} s in): training for {} steps, to end after "
                        "about {:.1f} of {:.1f} minutes",
                        per_step, s.step - (done - from), s.step, elapsed, s.iters, planned_end / 60.0, s.cfg.minutes));
      }
    }
    s.do_step();
    if (s.phase != last_phase) {
      if (line_open) std::fputc('\n', stderr), line_open = false;
      log_phase_time(clock::now());
      log(fmt::format("step {}: {} phase ({} blocks, {} MLPs)", s.step, phase_name(s.phase),
                      s.phase == Phase::Main ? 0 : s.blocks.block_count(), s.mlp_cv.size()));
      last_phase = s.phase;
    }
    const auto now = clock::now();
    if (std::chrono::duration<double>(now - rate_time).count() >= 2.0) {
      steps_per_s = double(s.step - rate_step) / std::chrono::duration<double>(now - rate_time).count();
      rate_step = s.step;
      rate_time = now;
    }
    if (!options.progress && options.progress_log_seconds > 0 &&
        std::chrono::duration<double>(now - t_print).count() >= options.progress_log_seconds) {
      t_print = now;
      const TrainStats st = stats();
      const double eta = steps_per_s > 0 ? double(st.iters - st.step) / steps_per_s : 0;
      log(fmt::format("step {}/{}  {:.2f} steps/s  ETA {}:{:02d}  loss {:.5f}  PSNR {:.2f} dB  {}", st.step, st.iters,
                      steps_per_s, int(eta) / 60, int(eta) % 60, st.loss, st.psnr, phase_name(st.phase)));
    }
    if (options.progress && std::chrono::duration<double>(now - t_print).count() >= 0.5) {
      t_print = now;
      const TrainStats st = stats();
      const double eta = steps_per_s > 0 ? double(st.iters - st.step) / steps_per_s : 0;
      std::fprintf(stderr, "\r  step %lld/%lld  %.2f steps/s  ETA %d:%02d  loss %.5f  PSNR %.2f dB  %s  %d rays  ",
                   (long long)st.step, (long long)st.iters, steps_per_s, int(eta) / 60, int(eta) % 60, st.loss, st.psnr,
                   phase_name(st.phase), st.rays);
      std::fflush(stderr);
      line_open = true;
    }
    if (std::chrono::duration<double>(now - t_checkpoint).count() >= options.checkpoint_minutes * 60.0 &&
        s.phase != Phase::Done) {
      if (line_open) std::fputc('\n', stderr), line_open = false;
      try_periodic_checkpoint();
      t_checkpoint = clock::now();
    }
  }
  if (line_open) std::fputc('\n', stderr);
  if (s.phase == Phase::Done && planned_end >= 0)
    log(fmt::format("trained in {:.1f} minutes; the plan expected {:.1f} of the {:.1f}-minute budget",
                    std::chrono::duration<double>(clock::now() - t_start).count() / 60.0, planned_end / 60.0,
                    s.cfg.minutes));
  if (s.phase != Phase::Done) {
    write_checkpoint();
    return false;
  }
  return true;
}

}  // namespace edrnr::train
