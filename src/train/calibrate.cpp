#include "train/calibrate.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "model/mlp.h"
#include "render/traversal.h"
#include "train/mlp_kernels.h"

namespace edrnr::train {
namespace {

constexpr int kStepMin = -4, kStepMax = 24;  // candidate steps in_scale * 2^(-k/4)
constexpr int kSteps = kStepMax - kStepMin + 1;

// One MLP's layers, dequantized, with each input's weight for the error: the
// squared norm of its column.
struct CalLayer {
  int in = 0, out = 0;
  std::vector<float> w, b;     // out x in, out
  std::vector<double> col_sq;  // in
  double steps[kSteps] = {};   // candidate input steps
};
struct CalMlp {
  std::vector<CalLayer> density, color;
};

CalLayer make_layer(const DenseQ& q) {
  CalLayer l;
  l.in = q.in;
  l.out = q.out;
  l.b = q.b;
  l.w.resize(q.w.size());
  l.col_sq.assign(size_t(q.in), 0.0);
  for (int o = 0; o < q.out; ++o)
    for (int i = 0; i < q.in; ++i) {
      const float w = float(q.w[size_t(o) * size_t(q.in) + size_t(i)]) * q.w_scale[size_t(o)];
      l.w[size_t(o) * size_t(q.in) + size_t(i)] = w;
      l.col_sq[size_t(i)] += double(w) * double(w);
    }
  for (int k = 0; k < kSteps; ++k) l.steps[k] = double(q.in_scale) * std::exp2(-double(k + kStepMin) / 4.0);
  return l;
}

// Adds the weighted squared quantization error of input x for every candidate step.
void add_errors(const CalLayer& l, const float* x, double lo, double hi, double weight, double* err) {
  if (!(weight > 0)) return;
  for (int k = 0; k < kSteps; ++k) {
    const double s = l.steps[k];
    double e = 0;
    for (int i = 0; i < l.in; ++i) {
      const double q = std::clamp(std::floor(double(x[i]) / s + 0.5), lo, hi) * s;
      const double d = double(x[i]) - q;
      e += l.col_sq[size_t(i)] * d * d;
    }
    err[k] += weight * e;
  }
}

// y = W x + b, ReLU if hidden.
void dense(const CalLayer& l, const float* x, float* y, bool relu) {
  for (int o = 0; o < l.out; ++o) {
    float a = l.b[size_t(o)];
    const float* w = &l.w[size_t(o) * size_t(l.in)];
    for (int i = 0; i < l.in; ++i) a += w[i] * x[i];
    y[o] = relu ? std::max(a, 0.f) : a;
  }
}

}  // namespace

CalibrationReport calibrate_activation_scales(SceneModel& model, const std::vector<Camera>& cameras,
                                              const CalibrationSettings& settings) {
  if (model.mlp_count() > 0 && model.mlps_q8.empty()) fail("activation calibration: the model has no INT8 MLPs");
  if (model.block_count() > 0 && model.features_q4.empty())
    fail("activation calibration: the model has no INT4 features");
  CalibrationReport report;
  const size_t n_mlps = model.mlps_q8.size();
  if (n_mlps == 0 || cameras.empty()) return report;

  std::vector<CalMlp> mlps(n_mlps);
  for (size_t m = 0; m < n_mlps; ++m) {
    for (const DenseQ& q : model.mlps_q8[m].density) mlps[m].density.push_back(make_layer(q));
    for (const DenseQ& q : model.mlps_q8[m].color) mlps[m].color.push_back(make_layer(q));
  }
  const size_t nd = mlps[0].density.size(), nl = nd + mlps[0].color.size();
  const double lo = -std::ldexp(1.0, settings.activation_bits - 1), hi = -lo - 1.0;

  int64_t pixels = 0;
  for (const Camera& c : cameras) pixels += int64_t(c.width) * c.height;
  const int stride =
      std::max<int>(1, int(std::ceil(std::sqrt(double(pixels) / double(std::max<int64_t>(1, settings.target_rays))))));

  const int F = model.feature_channels;
  const int L = model.mlp_arch.dir_frequencies;
  const int cr = model.coarse_res();
  const int cv_micro = kMicroPerFine * kFinePerCoarse;
  const float delta = sample_spacing(model, settings.step_micro);
  const int threads = settings.threads > 0 ? settings.threads : omp_get_max_threads();

  // Per camera, the errors of every MLP x layer x step, summed in a fixed
  // order (pixels in row order), then over the cameras in order.
  const size_t per_cam = n_mlps * nl * kSteps;
  std::vector<double> errors(cameras.size() * per_cam, 0.0);
  std::vector<int64_t> rays(cameras.size(), 0), samples(cameras.size(), 0);
#pragma omp parallel num_threads(threads)
  {
    std::vector<float> feature(static_cast<size_t>(F)), dir_enc(static_cast<size_t>(3 + 6 * L));
    std::vector<float> layer_in((nl + 1) * kMlpEvalMaxWidth);
#pragma omp for schedule(dynamic, 1)
    for (int64_t ci = 0; ci < int64_t(cameras.size()); ++ci) {
      const Camera& cam = cameras[size_t(ci)];
      double* err = &errors[size_t(ci) * per_cam];
      for (int y = stride / 2; y < cam.height; y += stride)
        for (int x = stride / 2; x < cam.width; x += stride) {
          const Ray ray = cam.pixel_ray(x, y);
          ++rays[size_t(ci)];
          encode_direction(ray.dir.cast<float>(), L, dir_enc.data());
          SampleMarcher march(model, ray, make_micro_ray(model, ray, delta), true);
          float T = 1.f;
          MarchSample s;
          while (T >= settings.transmittance_min && march.next(s)) {
            const int32_t m =
                model.coarse_to_mlp[linear_index(s.voxel.x / cv_micro, s.voxel.y / cv_micro, s.voxel.z / cv_micro, cr)];
            if (m < 0 || !interpolate_feature(model, s.p_micro, FeatureSource::Quantized, feature.data())) continue;
            ++samples[size_t(ci)];
            const CalMlp& net = mlps[size_t(m)];
            double* e = err + size_t(m) * nl * kSteps;
            // The forward pass, each layer's input kept (layer l's input at x + l * kMlpEvalMaxWidth).
            float* xs = layer_in.data();
            std::copy(feature.begin(), feature.end(), xs);
            for (size_t l = 0; l < nd; ++l) {
              float* out = xs + (l + 1) * kMlpEvalMaxWidth;
              dense(net.density[l], xs + l * kMlpEvalMaxWidth, out, l + 1 < nd);
            }
            // The colour net's input: the density output (raw density first), then the direction encoding.
            float* cin = xs + nd * kMlpEvalMaxWidth;
            const float raw_sigma = cin[0];
            std::copy(dir_enc.begin(), dir_enc.end(), cin + net.density.back().out);
            for (size_t l = 0; l < net.color.size(); ++l) {
              float* out = xs + (nd + l + 1) * kMlpEvalMaxWidth;
              dense(net.color[l], xs + (nd + l) * kMlpEvalMaxWidth, out, l + 1 < net.color.size());
            }
            const float* logit = xs + nl * kMlpEvalMaxWidth;
            // What an error costs the image: a colour error is scaled by the
            // sample's weight T alpha and the sigmoid's slope; a density error
            // by T times d(alpha)/d(raw density) = tau exp(-tau).
            const float sigma = std::exp(std::clamp(raw_sigma, kRawSigmaMin, kRawSigmaMax));
            const double tau = double(sigma) * double(delta), alpha = -std::expm1(-tau);
            double slope = 0;
            for (int c = 0; c < 3; ++c) {
              const double y = 1.0 / (1.0 + std::exp(-double(logit[c])));
              slope += y * (1.0 - y) * y * (1.0 - y) / 3.0;
            }
            const double w_color = double(T) * alpha * double(T) * alpha * slope;
            const double w_density = double(T) * tau * std::exp(-tau) * double(T) * tau * std::exp(-tau);
            for (size_t l = 0; l < nl; ++l) {
              const CalLayer& layer = l < nd ? net.density[l] : net.color[l - nd];
              add_errors(layer, xs + l * kMlpEvalMaxWidth, lo, hi, l < nd ? w_density : w_color, e + l * kSteps);
            }
            T *= std::exp(-sigma * delta);
          }
        }
    }
  }

  std::vector<double> total(per_cam, 0.0);
  for (size_t ci = 0; ci < cameras.size(); ++ci) {
    for (size_t k = 0; k < per_cam; ++k) total[k] += errors[ci * per_cam + k];
    report.rays += rays[ci];
    report.samples += samples[ci];
  }
  double log_sum = 0;
  for (size_t m = 0; m < n_mlps; ++m)
    for (size_t l = 0; l < nl; ++l) {
      const double* e = &total[(m * nl + l) * kSteps];
      int best = -kStepMin;  // k = 0: the step as it was
      for (int k = 0; k < kSteps; ++k)
        if (e[k] < e[best]) best = k;
      DenseQ& q = mlp_layer(model.mlps_q8[m], l);
      const CalLayer& c = l < nd ? mlps[m].density[l] : mlps[m].color[l - nd];
      ++report.layers;
      if (best != -kStepMin) {
        ++report.layers_changed;
        q.in_scale = float(c.steps[best]);
      }
      log_sum += -double(best + kStepMin) / 4.0;
    }
  report.mean_step_log2 = report.layers ? log_sum / report.layers : 0.0;
  // The model says how its steps were chosen.
  nlohmann::json meta = model.metadata_json.empty() ? nlohmann::json::object()
                                                    : nlohmann::json::parse(model.metadata_json, nullptr, false);
  if (meta.is_object()) {
    meta["activation_calibration"] = {{"rays", report.rays},
                                      {"samples", report.samples},
                                      {"layers_changed", report.layers_changed},
                                      {"layers", report.layers}};
    model.metadata_json = meta.dump();
  }
  return report;
}

}  // namespace edrnr::train
