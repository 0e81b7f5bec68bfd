#include "render/reference.h"

#include <omp.h>

#include <cmath>
#include <vector>

#include "core/error.h"
#include "model/mlp.h"
#include "render/traversal.h"

namespace edrnr {
namespace {

void check_net(const std::vector<DenseF>& net, const std::vector<int>& widths, const char* name, size_t index) {
  if (net.size() + 1 != widths.size())
    fail("MLP {} has {} {} layers, mlp_arch says {}", index, net.size(), name, widths.size() - 1);
  for (size_t l = 0; l < net.size(); ++l) {
    const DenseF& d = net[l];
    if (d.in != widths[l] || d.out != widths[l + 1] || d.w.size() != size_t(d.in) * size_t(d.out) ||
        d.b.size() != size_t(d.out))
      fail("MLP {} {} layer {} is {}x{} with {} weights, mlp_arch says {}x{}", index, name, l, d.out, d.in, d.w.size(),
           widths[l + 1], widths[l]);
  }
}

void check_model(const SceneModel& m, const ResolvedForm& form) {
  m.check_structure();
  const size_t F = size_t(m.feature_channels);
  if (F < 1) fail("model has {} feature channels", m.feature_channels);
  check_feature_storage(m, form);
  if (m.mlp_count() > 0) {
    check_mlp_arch(m.mlp_arch, m.feature_channels, kMlpEvalMaxWidth, "");
    const size_t n = form.quantized_mlps ? m.mlps_q8.size() : m.mlps_f32.size();
    if (n != m.mlp_count()) fail("model has {} MLPs of the rendered form for {} coarse voxels", n, m.mlp_count());
    for (size_t i = 0; i < n; ++i) {
      if (form.quantized_mlps) {
        const MlpQ& q = m.mlps_q8[i];
        for (const auto* net : {&q.density, &q.color})
          for (const DenseQ& d : *net)
            if (d.w_scale.size() != size_t(d.out) || d.w.size() != size_t(d.in) * size_t(d.out) ||
                d.b.size() != size_t(d.out))
              fail("INT8 MLP {} has a layer whose sizes do not match {}x{}", i, d.out, d.in);
        const MlpF f = dequantize_mlp(q);
        check_net(f.density, m.mlp_arch.density_widths, "density", i);
        check_net(f.color, m.mlp_arch.color_widths, "colour", i);
      } else {
        check_net(m.mlps_f32[i].density, m.mlp_arch.density_widths, "density", i);
        check_net(m.mlps_f32[i].color, m.mlp_arch.color_widths, "colour", i);
      }
    }
  }
}

}  // namespace

void check_feature_storage(const SceneModel& m, const ResolvedForm& form) {
  const size_t F = size_t(m.feature_channels);
  const size_t values = m.block_count() * kBlockVerts * F;
  if (m.block_count() == 0) return;
  if (form.quantized_features) {
    if (m.features_q4.size() != (values + 1) / 2 || m.feature_quant.scale.size() != F ||
        m.feature_quant.zero_point.size() != F)
      fail("model INT4 features hold {} bytes, expected {} for {} blocks", m.features_q4.size(), (values + 1) / 2,
           m.block_count());
  } else if (m.features_f32.size() != values) {
    fail("model float features hold {} values, expected {} for {} blocks", m.features_f32.size(), values,
         m.block_count());
  }
}

void check_render_inputs(const Camera& camera, const RenderSettings& s) {
  if (camera.width <= 0 || camera.height <= 0) fail("camera image size {}x{} is empty", camera.width, camera.height);
  if (!(std::isfinite(camera.fx) && std::isfinite(camera.fy) && camera.fx != 0 && camera.fy != 0))
    fail("camera focal lengths {}, {} are not finite and non-zero", camera.fx, camera.fy);
  const Ray corner = camera.pixel_ray(0, 0);
  if (!(std::isfinite(corner.origin.x) && std::isfinite(corner.origin.y) && std::isfinite(corner.origin.z) &&
        std::isfinite(corner.dir.x) && std::isfinite(corner.dir.y) && std::isfinite(corner.dir.z)))
    fail("camera transform gives no valid rays (a degenerate or non-finite transform_matrix)");
  if (!(s.step_micro > 0.f && std::isfinite(s.step_micro))) fail("render step {} must be positive", s.step_micro);
  if (!(s.transmittance_min >= 0.f && s.transmittance_min <= 1.f))
    fail("transmittance threshold {} is outside [0, 1]", s.transmittance_min);
  if (!(s.fast_transmittance_min >= 0.f && s.fast_transmittance_min <= 1.f))
    fail("fast renderer's transmittance threshold {} is outside [0, 1]", s.fast_transmittance_min);
  if (!(s.fast_int8_transmittance_min >= 0.f && s.fast_int8_transmittance_min <= 1.f))
    fail("fast renderer's INT8 transmittance threshold {} is outside [0, 1]", s.fast_int8_transmittance_min);
  if (s.threads < 0) fail("thread count {} is negative", s.threads);
}

ResolvedForm resolve_model_form(const SceneModel& model, ModelForm requested) {
  const bool need_features = model.block_count() > 0, need_mlps = model.mlp_count() > 0;
  const bool has_f32 = !model.features_f32.empty(), has_q4 = !model.features_q4.empty();
  const bool has_mlp_f32 = !model.mlps_f32.empty(), has_mlp_q8 = !model.mlps_q8.empty();
  ResolvedForm r;
  switch (requested) {
    case ModelForm::Float:
      if (need_features && !has_f32) fail("the model has no float features (only its quantized form can be rendered)");
      if (need_mlps && !has_mlp_f32) fail("the model has no float MLPs (only its quantized form can be rendered)");
      break;
    case ModelForm::Quantized:
      if (need_features && !has_q4) fail("the model has no INT4 features (only its float form can be rendered)");
      if (need_mlps && !has_mlp_q8) fail("the model has no INT8 MLPs (only its float form can be rendered)");
      r.quantized_features = true;
      r.quantized_mlps = true;
      break;
    case ModelForm::Auto:
      r.quantized_features = has_q4 || !has_f32;
      r.quantized_mlps = has_mlp_q8 || !has_mlp_f32;
      if (need_features && !has_q4 && !has_f32) fail("the model has occupied fine voxels but no features");
      if (need_mlps && !has_mlp_q8 && !has_mlp_f32) fail("the model has occupied coarse voxels but no MLPs");
      break;
  }
  return r;
}

Image render_reference(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                       RenderStats* stats) {
  check_render_inputs(camera, settings);
  const ResolvedForm form = resolve_model_form(model, settings.form);
  check_model(model, form);

  // The MLPs this render reads, dequantized once.
  std::vector<MlpF> dequantized;
  if (form.quantized_mlps)
    for (const MlpQ& q : model.mlps_q8) dequantized.push_back(dequantize_mlp(q));
  const std::vector<MlpF>& mlps = form.quantized_mlps ? dequantized : model.mlps_f32;
  const FeatureSource source = form.quantized_features ? FeatureSource::Quantized : FeatureSource::Float;

  const int W = camera.width, H = camera.height;
  const int F = model.feature_channels;
  const int L = model.mlp_arch.dir_frequencies;
  const int cr = model.coarse_res();
  const int cv_micro = kMicroPerFine * kFinePerCoarse;
  const float delta = sample_spacing(model, settings.step_micro);
  const Box3d aabb{model.object_aabb.lo.cast<double>(), model.object_aabb.hi.cast<double>()};
  const int threads = settings.threads > 0 ? settings.threads : omp_get_max_threads();

  Image image(W, H, 3);
  RenderStats total;
  uint64_t missing = 0;  // samples in an occupied micro voxel without block or MLP
#pragma omp parallel num_threads(threads)
  {
    RenderStats local;
    uint64_t local_missing = 0;
    std::vector<float> feature(static_cast<size_t>(F));
    std::vector<float> dir_enc(static_cast<size_t>(3 + 6 * L));
#pragma omp for schedule(dynamic, 1)
    for (int y = 0; y < H; ++y) {
      for (int x = 0; x < W; ++x) {
        const Ray ray = camera.pixel_ray(x, y);
        ++local.rays;
        double t_near, t_far;
        if (intersect_box(ray.origin, ray.dir, aabb, t_near, t_far) && t_far >= 0) ++local.rays_hit_aabb;
        encode_direction(ray.dir.cast<float>(), L, dir_enc.data());
        SampleMarcher march(model, ray, make_micro_ray(model, ray, delta), settings.use_occupancy_tiers);
        float T = 1.f;
        float rgb[3] = {0.f, 0.f, 0.f};
        MarchSample s;
        while (T >= settings.transmittance_min && march.next(s)) {
          const int32_t mlp =
              model.coarse_to_mlp[linear_index(s.voxel.x / cv_micro, s.voxel.y / cv_micro, s.voxel.z / cv_micro, cr)];
          if (mlp < 0 || !interpolate_feature(model, s.p_micro, source, feature.data())) {
            ++local_missing;
            continue;
          }
          const MlpOutput out = eval_mlp(model.mlp_arch, mlps[size_t(mlp)], feature.data(), dir_enc.data());
          ++local.samples;
          const float tau = out.sigma * delta;
          const float weight = T * -std::expm1(-tau);  // T_i * alpha_i
          for (int c = 0; c < 3; ++c) rgb[c] += weight * out.rgb[c];
          T *= std::exp(-tau);
        }
        local.occupancy_checks += march.occupancy_checks();
        float* px = image.at(x, y);
        for (int c = 0; c < 3; ++c) px[c] = rgb[c] + T * settings.background[c];
      }
    }
#pragma omp critical
    {
      total.rays += local.rays;
      total.rays_hit_aabb += local.rays_hit_aabb;
      total.samples += local.samples;
      total.occupancy_checks += local.occupancy_checks;
      missing += local_missing;
    }
  }
  if (missing)
    fail("{} samples lie in occupied micro voxels without a feature block or MLP (the model breaks its invariants)",
         missing);
  if (stats) *stats = total;
  return image;
}

}  // namespace edrnr
