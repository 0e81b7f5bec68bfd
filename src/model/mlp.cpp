#include "model/mlp.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace edrnr {
namespace {

// y = W x + b, with ReLU when `relu`. The sum starts at the bias and adds the
// products in input order.
void dense_forward(const DenseF& layer, const float* x, float* y, bool relu) {
  for (int o = 0; o < layer.out; ++o) {
    const float* w = layer.w.data() + size_t(o) * size_t(layer.in);
    float s = layer.b[size_t(o)];
    for (int i = 0; i < layer.in; ++i) s += w[i] * x[i];
    y[o] = relu ? std::max(s, 0.f) : s;
  }
}

// Runs a stack of layers: hidden ReLU, last linear. `x` is the input; the
// result ends up in the returned buffer (one of a, b).
const float* net_forward(const std::vector<DenseF>& layers, const float* x, float* a, float* b) {
  const float* in = x;
  float* out = a;
  for (size_t l = 0; l < layers.size(); ++l) {
    dense_forward(layers[l], in, out, l + 1 < layers.size());
    in = out;
    out = (out == a) ? b : a;
  }
  return in;
}

void check_widths(const std::vector<DenseF>& layers, const char* net) {
  if (layers.empty()) fail("MLP {} net has no layers", net);
  for (const DenseF& l : layers)
    if (l.in > kMlpEvalMaxWidth || l.out > kMlpEvalMaxWidth || l.in <= 0 || l.out <= 0)
      fail("MLP {} layer {}x{} is outside 1..{} neurons", net, l.out, l.in, kMlpEvalMaxWidth);
}

float sigmoid(float x) { return 1.f / (1.f + std::exp(-x)); }

}  // namespace

void check_mlp_arch(const MlpArch& arch, int feature_channels, int max_width, const char* limit_note) {
  const auto& dw = arch.density_widths;
  const auto& cw = arch.color_widths;
  if (dw.size() < 2 || cw.size() < 2) fail("mlp_arch needs at least one layer in each net");
  if (dw.front() != feature_channels)
    fail("mlp_arch density input {} does not match the {} feature channels", dw.front(), feature_channels);
  if (dw.back() < 1 || cw.front() != dw.back() + arch.dir_dims())
    fail("mlp_arch colour input {} is not the density output {} plus {} direction values", cw.front(), dw.back(),
         arch.dir_dims());
  if (cw.back() != 3) fail("mlp_arch colour net has {} outputs, expected 3", cw.back());
  if (arch.dir_frequencies < 0) fail("mlp_arch direction frequencies {} is negative", arch.dir_frequencies);
  const std::string note = *limit_note ? std::string(" (") + limit_note + ")" : std::string();
  for (const auto* w : {&dw, &cw})
    for (int n : *w)
      if (n < 1 || n > max_width) fail("mlp_arch layer width {} is outside 1..{}{}", n, max_width, note);
}

MlpArch default_mlp_arch(int feature_channels) {
  MlpArch arch;
  arch.dir_frequencies = 2;
  // The chip's MLP (docs/training.md, "MLP size"): 800 INT8 weights, 1216
  // bytes as stored, so six fit the 8.25 KB MLP cache.
  arch.density_widths = {feature_channels, 16, 8};
  arch.color_widths = {8 + arch.dir_dims(), 16, 3};
  return arch;
}

void encode_direction(const Vec3f& dir, int frequencies, float* out) {
  out[0] = dir.x;
  out[1] = dir.y;
  out[2] = dir.z;
  float* o = out + 3;
  float freq = 1.f;
  for (int k = 0; k < frequencies; ++k) {
    for (int a = 0; a < 3; ++a) o[a] = std::sin(freq * dir[a]);
    for (int a = 0; a < 3; ++a) o[3 + a] = std::cos(freq * dir[a]);
    o += 6;
    freq *= 2.f;
  }
}

MlpOutput eval_mlp(const MlpArch& arch, const MlpF& mlp, const float* feature, const float* dir_enc) {
  check_widths(mlp.density, "density");
  check_widths(mlp.color, "colour");
  float a[kMlpEvalMaxWidth], b[kMlpEvalMaxWidth];
  const float* geo = net_forward(mlp.density, feature, a, b);

  MlpOutput r;
  r.raw_sigma = geo[0];
  r.sigma = std::exp(std::clamp(geo[0], kRawSigmaMin, kRawSigmaMax));

  // Colour net input: the G density-net outputs, then the direction encoding.
  const int G = mlp.density.back().out;
  const int D = arch.dir_dims();
  if (G + D > kMlpEvalMaxWidth) fail("MLP colour input {} is wider than {}", G + D, kMlpEvalMaxWidth);
  float cin[kMlpEvalMaxWidth];
  std::copy(geo, geo + G, cin);
  std::copy(dir_enc, dir_enc + D, cin + G);
  const float* rgb = net_forward(mlp.color, cin, a, b);
  for (int c = 0; c < 3; ++c) r.rgb[c] = sigmoid(rgb[c]);
  return r;
}

MlpF dequantize_mlp(const MlpQ& q) {
  auto layer = [](const DenseQ& lq) {
    DenseF f;
    f.in = lq.in;
    f.out = lq.out;
    f.b = lq.b;
    f.w.resize(lq.w.size());
    for (int o = 0; o < lq.out; ++o)
      for (int i = 0; i < lq.in; ++i) {
        size_t k = size_t(o) * size_t(lq.in) + size_t(i);
        f.w[k] = float(lq.w[k]) * lq.w_scale[size_t(o)];
      }
    return f;
  };
  MlpF f;
  for (const DenseQ& l : q.density) f.density.push_back(layer(l));
  for (const DenseQ& l : q.color) f.color.push_back(layer(l));
  return f;
}

bool interpolate_feature(const SceneModel& model, const Vec3f& p_micro, float* out) {
  return interpolate_feature(model, p_micro, FeatureSource::Auto, out);
}

bool interpolate_feature(const SceneModel& model, const Vec3f& p_micro, FeatureSource source, float* out) {
  Vec3i m;
  if (!micro_voxel_of(p_micro, model.micro_res, m)) return false;
  const int fr = model.fine_res();
  const Vec3i fine{m.x / kMicroPerFine, m.y / kMicroPerFine, m.z / kMicroPerFine};
  const int32_t block = model.fine_to_block[linear_index(fine.x, fine.y, fine.z, fr)];
  if (block < 0) return false;

  if (source == FeatureSource::Auto)
    source = model.features_f32.empty() ? FeatureSource::Quantized : FeatureSource::Float;
  if (source == FeatureSource::Float && model.features_f32.empty()) fail("model has no float features");
  if (source == FeatureSource::Quantized && model.features_q4.empty()) fail("model has no INT4 features");
  const int F = model.feature_channels;
  // Corner (0,0,0) of the micro voxel inside the block, and the weights.
  const Vec3i local{m.x - kMicroPerFine * fine.x, m.y - kMicroPerFine * fine.y, m.z - kMicroPerFine * fine.z};
  const float fx = p_micro.x - float(m.x), fy = p_micro.y - float(m.y), fz = p_micro.z - float(m.z);
  const float wx[2] = {1.f - fx, fx}, wy[2] = {1.f - fy, fy}, wz[2] = {1.f - fz, fz};

  for (int c = 0; c < F; ++c) out[c] = 0.f;
  const size_t block_base = size_t(block) * kBlockVerts;
  for (int corner = 0; corner < 8; ++corner) {
    const int i = corner & 1, j = (corner >> 1) & 1, k = corner >> 2;
    const float w = wx[i] * wy[j] * wz[k];
    const int vertex = (local.x + i) + kBlockVertsPerAxis * ((local.y + j) + kBlockVertsPerAxis * (local.z + k));
    const size_t base = (block_base + size_t(vertex)) * size_t(F);
    if (source == FeatureSource::Float) {
      const float* v = model.features_f32.data() + base;
      for (int c = 0; c < F; ++c) out[c] += w * v[c];
    } else {
      for (int c = 0; c < F; ++c) {
        const size_t idx = base + size_t(c);
        const uint8_t byte = model.features_q4[idx >> 1];
        const int q = (idx & 1) ? (byte >> 4) : (byte & 15);
        const float v =
            float(q - int(model.feature_quant.zero_point[size_t(c)])) * model.feature_quant.scale[size_t(c)];
        out[c] += w * v;
      }
    }
  }
  return true;
}

}  // namespace edrnr
