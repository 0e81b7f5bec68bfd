// Trainer::State, export and checkpoints (train/trainer_state.h): the scene
// model (float or INT4/INT8) as of now, and checkpoint bytes written and read
// back (every value a later step relies on checked).
#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "train/calibrate.h"
#include "train/checkpoint_io.h"
#include "train/mlp_kernels.h"
#include "train/rng.h"
#include "train/trainer_state.h"

namespace edrnr::train {

namespace {

uint64_t dataset_fingerprint(const Dataset& d) {
  uint64_t h = mix64(d.frames.size());
  for (const auto& f : d.frames) {
    h = hash_combine(h, uint64_t(f.image.width) * 65536 + uint64_t(f.image.height));
    for (double v : f.camera.c2w) {
      uint64_t bits;
      std::memcpy(&bits, &v, 8);
      h = hash_combine(h, bits);
    }
    for (size_t i = 0; i < f.image.data.size(); i += 997) {
      uint32_t bits;
      std::memcpy(&bits, &f.image.data[i], 4);
      h = hash_combine(h, bits);
    }
  }
  return h;
}

}  // namespace

// --- export ---------------------------------------------------------------

SceneModel Trainer::State::make_model(bool quantized, bool trained_steps) const {
  if (phase == Phase::Main || cv_to_mlp.empty()) fail("the model cannot be exported before the occupancy is frozen");
  SceneModel m;
  m.scene_box = cfg.scene_box;
  m.micro_res = cfg.micro_res;
  m.init_grids();
  m.occupancy[int(Tier::Micro)] = occ.micro;
  m.rebuild_upper_tiers();
  const Vec3f vs = m.micro_voxel_size();
  m.object_aabb.lo = m.scene_box.lo + vs * Vec3f{float(occ.aabb_lo.x), float(occ.aabb_lo.y), float(occ.aabb_lo.z)};
  m.object_aabb.hi =
      m.scene_box.lo + vs * Vec3f{float(occ.aabb_hi.x + 1), float(occ.aabb_hi.y + 1), float(occ.aabb_hi.z + 1)};
  m.feature_channels = F;
  m.block_fine_index = blocks.fine_index();
  m.mlp_arch = arch;
  m.mlp_coarse_index = mlp_cv;
  const bool have_snapshot = phase >= Phase::Quantize && !float_blocks.empty();
  if (quantized) {
    // Without a quantization-aware phase (qat_fraction 0) the ranges are fitted now.
    const auto q = phase >= Phase::Quantize && !feature_quant.empty() ? feature_quant : blocks.fit_quantization();
    const auto& v = blocks.values();
    const size_t n = v.size();
    m.features_q4.assign((n + 1) / 2, 0);
    m.feature_quant.scale.resize(size_t(F));
    m.feature_quant.zero_point.resize(size_t(F));
    for (int c = 0; c < F; ++c) {
      m.feature_quant.scale[size_t(c)] = q[size_t(c)].scale;
      m.feature_quant.zero_point[size_t(c)] = uint8_t(q[size_t(c)].zero_point);
    }
    for (size_t i = 0; i < n; ++i) {
      const int code = q[i % size_t(F)].quantize(v[i]);
      m.features_q4[i >> 1] |= uint8_t((i & 1) ? code << 4 : code);
    }
    const size_t n_layers = layout.density.size() + layout.color.size();
    std::vector<float> fallback(n_layers, 0.f);
    for (size_t k = 0; k < layer_in_max.size(); ++k)
      fallback[k % n_layers] = std::max(fallback[k % n_layers], layer_in_max[k]);
    // Without a quantization-aware phase the MLPs are equalized now (a copy).
    std::vector<float> equalized;
    const float* params = mlp_params.data();
    if (phase < Phase::Quantize && cfg.mlp_equalize > 0.f) {
      equalized = mlp_params;
      for (size_t mi = 0; mi < mlp_cv.size(); ++mi)
        equalize_mlp(layout, cfg.mlp_equalize, &equalized[mi * layout.param_count], nullptr, nullptr);
      params = equalized.data();
    }
    for (size_t mi = 0; mi < mlp_cv.size(); ++mi) {
      std::vector<float> mx(n_layers, 0.f);
      for (size_t k = 0; k < n_layers; ++k) {
        const size_t j = mi * n_layers + k;
        mx[k] = j < layer_in_max.size() && layer_in_max[j] > 0.f ? layer_in_max[j] : fallback[k];
      }
      m.mlps_q8.push_back(quantize_mlp(layout, &params[mi * layout.param_count], mx));
    }
  } else {
    m.features_f32 = have_snapshot ? float_blocks : blocks.values();
    const auto& p = have_snapshot ? float_mlps : mlp_params;
    for (size_t mi = 0; mi < mlp_cv.size(); ++mi)
      m.mlps_f32.push_back(unflatten_mlp(layout, &p[mi * layout.param_count]));
  }
  nlohmann::json meta;
  meta["producer"] = "edrnr train";
  meta["dataset"] = data.root.string();
  meta["split"] = data.split;
  meta["frames"] = data.frames.size();
  meta["form"] = quantized ? "quantized" : "float";
  meta["iters"] = iters;
  meta["seed"] = cfg.seed;
  meta["levels"] = cfg.levels;
  meta["step_micro"] = cfg.step_micro;  // the sample spacing it was trained at (micro voxels)
  meta["train_psnr_float_db"] = std::round(psnr_float * 100) / 100;
  if (quantized) meta["train_psnr_quantized_db"] = std::round(psnr_quantized * 100) / 100;
  m.metadata_json = meta.dump();
  m.finalize();
  if (quantized && trained_steps && !act_steps.empty()) {
    // The activation steps the quantization-aware phase trained with.
    const size_t n_layers = layout.density.size() + layout.color.size();
    for (size_t mi = 0; mi < m.mlps_q8.size(); ++mi)
      for (size_t k = 0; k < n_layers; ++k) mlp_layer(m.mlps_q8[mi], k).in_scale = act_steps[mi * n_layers + k];
    meta["activation_steps"] = "trained (qat_activations)";
    m.metadata_json = meta.dump();
  } else if (quantized && cfg.calibrate_activations) {
    std::vector<Camera> cameras;
    for (const auto& f : data.frames) cameras.push_back(f.camera);
    CalibrationSettings cs;
    cs.step_micro = cfg.step_micro;
    cs.transmittance_min = cfg.transmittance_min;
    calibrate_activation_scales(m, cameras, cs);
  }
  return m;
}

// --- checkpoints ------------------------------------------------------------

std::vector<uint8_t> Trainer::State::save() const {
  // The sections, once counted (to reserve the whole file) and once written.
  std::vector<float> q;
  for (const auto& c : feature_quant) q.insert(q.end(), {c.scale, float(c.zero_point)});
  const auto put_all = [&](CheckpointWriter& w) {
    w.put_string("config", to_yaml(cfg));
    w.put_value("dataset_fingerprint", dataset_fingerprint(data));
    w.put_value("step", step);
    w.put_value("iters", iters);
    w.put_value("iters_fixed", uint8_t(iters_fixed));
    w.put_value("phase", int32_t(phase));
    w.put_value("n_rays", int32_t(n_rays));
    w.put_value("mse_ema", mse_ema);
    w.put_value("psnr_float", psnr_float);
    w.put_value("psnr_quantized", psnr_quantized);
    w.put_value("occ_updates", occ_updates);
    w.put_value("feature_adam_t", feature_adam_t);
    w.put_value("mlp_adam_t", mlp_adam_t);
    w.put("occ_density", occ.density);
    w.put("occ_micro", occ.micro.words());
    w.put_value("occ_aabb_known", uint8_t(occ.aabb_known));
    const int32_t aabb[6] = {occ.aabb_lo.x, occ.aabb_lo.y, occ.aabb_lo.z, occ.aabb_hi.x, occ.aabb_hi.y, occ.aabb_hi.z};
    w.put_bytes("occ_aabb", aabb, sizeof aabb);
    if (phase == Phase::Main) {
      for (size_t li = 0; li < pyramid.levels().size(); ++li) {
        const auto& L = pyramid.levels()[li];
        w.put(fmt::format("level{}_value", li), L.value);
        w.put(fmt::format("level{}_m", li), L.adam.m);
        w.put(fmt::format("level{}_v", li), L.adam.v);
      }
    } else {
      w.put("block_fine_index", blocks.fine_index());
      w.put("block_value", blocks.values());
      w.put("block_m", const_cast<BlockFeatures&>(blocks).adam().m);
      w.put("block_v", const_cast<BlockFeatures&>(blocks).adam().v);
      w.put("mlp_cv", mlp_cv);
    }
    w.put("feature_quant", q);
    w.put("mlp_params", mlp_params);
    w.put("mlp_m", mlp_m);
    w.put("mlp_v", mlp_v);
    w.put("layer_in_max", layer_in_max);
    if (!act_steps.empty()) w.put("act_steps", act_steps);
    w.put("max_weight", max_weight);
    w.put("float_blocks", float_blocks);
    w.put("float_mlps", float_mlps);
    if (!ema_blocks.empty()) {
      w.put("ema_blocks", ema_blocks);
      w.put("ema_mlps", ema_mlps);
    }
    if (!err_map.empty()) w.put("error_map", err_map.values());
  };
  CheckpointWriter sizes(true);
  put_all(sizes);
  CheckpointWriter w;
  w.reserve(sizes.body_bytes());
  put_all(w);
  return w.finish();
}

void Trainer::State::load(const CheckpointReader& r) {
  if (r.get_value<uint64_t>("dataset_fingerprint") != dataset_fingerprint(data))
    fail("{}: the checkpoint was made from a different dataset (or split, or downscale) than {}", r.source(),
         data.root.string());
  step = r.get_value<int64_t>("step");
  iters = r.get_value<int64_t>("iters");
  iters_fixed = r.get_value<uint8_t>("iters_fixed") != 0;
  phase = Phase(r.get_value<int32_t>("phase"));
  if (int(phase) < 0 || int(phase) > int(Phase::Done)) fail("{}: bad phase", r.source());
  n_rays = r.get_value<int32_t>("n_rays");
  mse_ema = r.get_value<double>("mse_ema");
  psnr_float = r.get_value<double>("psnr_float");
  psnr_quantized = r.get_value<double>("psnr_quantized");
  occ_updates = r.get_value<int64_t>("occ_updates");
  feature_adam_t = r.get_value<int64_t>("feature_adam_t");
  mlp_adam_t = r.get_value<int64_t>("mlp_adam_t");
  // Every value a later step indexes or sizes with is checked (a checkpoint
  // that passed its CRC may still have been made by another build, or edited).
  auto bad = [&](const char* what, auto value) {
    fail("{}: the checkpoint's {} ({}) is out of range (corrupt or from another edrnr)", r.source(), what, value);
  };
  if (iters < 1 || iters > (int64_t{1} << 40)) bad("step count", iters);
  if (step < 0 || step > iters) bad("step", step);
  if ((phase == Phase::Done) != (step == iters)) bad("phase", phase_name(phase));
  if (phase == Phase::Main && step > freeze_step()) bad("main-phase step", step);
  if (n_rays < cfg.min_rays || n_rays > cfg.max_rays) bad("ray count", n_rays);
  if (occ_updates < 0 || feature_adam_t < 0 || mlp_adam_t < 0) bad("update counters", occ_updates);
  if (!std::isfinite(mse_ema)) bad("running loss", mse_ema);
  auto expect_size = [&](const char* name, size_t got, size_t want) {
    if (got != want) fail("{}: section '{}' has {} items, expected {}", r.source(), name, got, want);
  };
  // Parameters, their Adam moments and snapshots: finite numbers only.
  auto floats = [&](const std::string& name) {
    std::vector<float> v = r.get<float>(name);
    for (size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i]))
        fail("{}: section '{}' item {} is not a finite number (corrupt checkpoint)", r.source(), name, i);
    return v;
  };
  occ.density = r.get<float>("occ_density");
  expect_size("occ_density", occ.density.size(), size_t(cfg.micro_res) * cfg.micro_res * cfg.micro_res);
  auto words = r.get<uint64_t>("occ_micro");
  expect_size("occ_micro", words.size(), occ.micro.words().size());
  occ.micro.words() = std::move(words);
  occ.aabb_known = r.get_value<uint8_t>("occ_aabb_known") != 0;
  auto aabb = r.get<int32_t>("occ_aabb");
  expect_size("occ_aabb", aabb.size(), 6);
  occ.aabb_lo = {aabb[0], aabb[1], aabb[2]};
  occ.aabb_hi = {aabb[3], aabb[4], aabb[5]};
  for (int a = 0; a < 3; ++a)
    if (occ.aabb_known && (aabb[a] < 0 || aabb[a] > aabb[3 + a] || aabb[3 + a] >= cfg.micro_res))
      bad("object AABB", fmt::format("[{}, {}]", aabb[a], aabb[3 + a]));
  occ.rebuild_macro();
  if (phase == Phase::Main) {
    pyramid = FeaturePyramid(cfg.micro_res, cfg.levels, cfg.seed, 0.f);
    for (size_t li = 0; li < pyramid.levels().size(); ++li) {
      auto& L = pyramid.levels()[li];
      const size_t n = L.value.size();
      L.value = floats(fmt::format("level{}_value", li));
      L.adam.m = floats(fmt::format("level{}_m", li));
      L.adam.v = floats(fmt::format("level{}_v", li));
      expect_size("level values", L.value.size(), n);
      expect_size("level Adam m", L.adam.m.size(), n);
      expect_size("level Adam v", L.adam.v.size(), n);
    }
    n_mlps = 1;
  } else {
    auto fine_index = r.get<uint32_t>("block_fine_index");
    blocks = BlockFeatures(cfg.micro_res, F, std::move(fine_index), floats("block_value"));
    blocks.adam().m = floats("block_m");
    blocks.adam().v = floats("block_v");
    expect_size("block_m", blocks.adam().m.size(), blocks.values().size());
    expect_size("block_v", blocks.adam().v.size(), blocks.values().size());
    mlp_cv = r.get<uint32_t>("mlp_cv");
    const int cr = cfg.micro_res / 32;
    cv_to_mlp.assign(size_t(cr) * cr * cr, -1);
    for (size_t i = 0; i < mlp_cv.size(); ++i) {
      if (mlp_cv[i] >= cv_to_mlp.size()) fail("{}: MLP coarse index out of range", r.source());
      cv_to_mlp[mlp_cv[i]] = int32_t(i);
    }
    n_mlps = std::max<int>(1, int(mlp_cv.size()));
    // Every occupied micro voxel must have its feature block and its MLP
    // (training looks both up for each sample).
    const int R = cfg.micro_res, fr = R / kMicroPerFine;
    const auto& words = occ.micro.words();
    for (size_t w = 0; w < words.size(); ++w)
      for (uint64_t bits = words[w]; bits; bits &= bits - 1) {
        const size_t i = w * 64 + size_t(std::countr_zero(bits));
        const int x = int(i % size_t(R)), y = int(i / size_t(R) % size_t(R)), z = int(i / (size_t(R) * size_t(R)));
        const uint32_t fine = linear_index(x / kMicroPerFine, y / kMicroPerFine, z / kMicroPerFine, fr);
        if (blocks.block_of_fine(fine) < 0 || cv_to_mlp[size_t(linear_index(x >> 5, y >> 5, z >> 5, cr))] < 0)
          bad("occupied micro voxel without a feature block or MLP", fmt::format("{}, {}, {}", x, y, z));
      }
  }
  auto q = r.get<float>("feature_quant");
  if (!q.empty() && q.size() != 2 * size_t(F)) expect_size("feature_quant", q.size(), 2 * size_t(F));
  if (q.empty() && phase == Phase::Quantize) expect_size("feature_quant", q.size(), 2 * size_t(F));
  for (size_t i = 0; i + 1 < q.size(); i += 2)
    if (!(q[i] > 0.f) || !std::isfinite(q[i]) || !std::isfinite(1.f / q[i]) || !(q[i + 1] >= 0.f && q[i + 1] <= 15.f) ||
        q[i + 1] != std::floor(q[i + 1]))
      bad("INT4 channel", fmt::format("scale {}, zero point {}", q[i], q[i + 1]));
  feature_quant.clear();
  for (size_t i = 0; i + 1 < q.size(); i += 2) {
    Int4Channel c = int4_channel_for_range(0.f, 0.f);
    c.scale = q[i];
    c.inv_scale = 1.f / c.scale;
    c.zero_point = int(q[i + 1]);
    feature_quant.push_back(c);
  }
  if (phase == Phase::Quantize || phase == Phase::Done) blocks.set_quantization(feature_quant);
  mlp_params = floats("mlp_params");
  mlp_m = floats("mlp_m");
  mlp_v = floats("mlp_v");
  expect_size("mlp_params", mlp_params.size(), size_t(n_mlps) * layout.param_count);
  expect_size("mlp_m", mlp_m.size(), mlp_params.size());
  expect_size("mlp_v", mlp_v.size(), mlp_params.size());
  layer_in_max = floats("layer_in_max");
  const size_t n_layers = layout.density.size() + layout.color.size();
  if (phase == Phase::Quantize) expect_size("layer_in_max", layer_in_max.size(), size_t(n_mlps) * n_layers);
  if (!layer_in_max.empty()) expect_size("layer_in_max", layer_in_max.size(), size_t(n_mlps) * n_layers);
  act_steps = r.has("act_steps") ? floats("act_steps") : std::vector<float>{};
  if (!act_steps.empty()) expect_size("act_steps", act_steps.size(), size_t(n_mlps) * n_layers);
  for (float a : act_steps)
    if (!(a > 0.f)) bad("activation step", a);
  if (phase >= Phase::Quantize) update_fake_quantized_mlps();
  max_weight = r.get<float>("max_weight");
  if (!max_weight.empty()) expect_size("max_weight", max_weight.size(), occ.density.size());
  float_blocks = floats("float_blocks");
  float_mlps = floats("float_mlps");
  if (!float_blocks.empty() || !float_mlps.empty()) {
    expect_size("float_blocks", float_blocks.size(), phase == Phase::Main ? 0 : blocks.values().size());
    expect_size("float_mlps", float_mlps.size(), mlp_params.size());
  }
  ema_blocks = r.has("ema_blocks") ? floats("ema_blocks") : std::vector<float>{};
  ema_mlps = r.has("ema_mlps") ? floats("ema_mlps") : std::vector<float>{};
  if (!ema_blocks.empty() || !ema_mlps.empty()) {
    if (!(ema_decay() > 0.f)) fail("{}: the checkpoint holds running averages its phase does not keep", r.source());
    expect_size("ema_blocks", ema_blocks.size(), blocks.values().size());
    expect_size("ema_mlps", ema_mlps.size(), mlp_params.size());
  }
  if (!err_map.empty()) {  // sized by init_error_map for this config and dataset
    std::vector<float> e = r.get<float>("error_map");
    expect_size("error_map", e.size(), err_map.cells());
    for (size_t i = 0; i < e.size(); ++i)
      if (!(e[i] >= 0.f && std::isfinite(e[i]))) bad("error map value", e[i]);
    err_map.values() = std::move(e);
  }
}

}  // namespace edrnr::train
