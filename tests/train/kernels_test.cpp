// The MLP and volume-rendering kernels of the trainer: every backward kernel
// against central finite differences, the forward kernels against closed forms.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "test_random.h"
#include "train/feature_grid.h"
#include "train/mlp_kernels.h"
#include "train/rng.h"
#include "train/volume.h"

namespace edrnr::train {
namespace {

MlpArch small_arch() {
  MlpArch a;
  a.density_widths = {8, 12, 5};
  a.dir_frequencies = 1;
  a.color_widths = {5 + 9, 10, 7, 3};
  return a;
}

// Loss = sum over lanes < n and outputs of r * out (r random): its gradient
// with respect to the outputs is r.
struct NetCase {
  const std::vector<MlpLayout::Layer>* layers;
  std::vector<float> params, x0, r;
  int n;
  int out_rows() const { return layers->back().out; }
  size_t act_floats() const {
    size_t s = 0;
    for (const auto& l : *layers) s += size_t(l.out);
    return s * kLanes;
  }
  double loss() const {
    std::vector<float> acts(act_floats());
    net_forward(*layers, params.data(), x0.data(), acts.data());
    const float* out = acts.data() + acts.size() - size_t(out_rows()) * kLanes;
    double L = 0;
    for (int o = 0; o < out_rows(); ++o)
      for (int l = 0; l < n; ++l) L += double(r[size_t(o) * kLanes + l]) * out[size_t(o) * kLanes + l];
    return L;
  }
};

// A ReLU switching inside [x - h, x + h] makes the two one-sided slopes differ;
// the central difference is then no reference for the derivative.
bool crosses_kink(double up, double down, float h) {
  return std::fabs(up - down) / h > 1e-3 * (1.0 + std::fabs(up / h));
}

void check_net(const MlpLayout& layout, const std::vector<MlpLayout::Layer>& layers, uint64_t seed) {
  NetCase c;
  c.layers = &layers;
  c.n = 21;  // leaves padding lanes
  c.params.resize(layout.param_count);
  init_mlp_params(layout, seed, c.params.data());
  for (size_t i = 0; i < c.params.size(); ++i) c.params[i] += rnd(seed, 1000 + i, -0.1f, 0.1f);  // non-zero biases
  c.x0.assign(size_t(layers[0].in) * kLanes, 0.f);
  for (int i = 0; i < layers[0].in; ++i)
    for (int l = 0; l < c.n; ++l) c.x0[size_t(i) * kLanes + l] = rnd(seed, 5000 + i * 64 + l, -1.f, 1.f);
  c.r.assign(size_t(c.out_rows()) * kLanes, 0.f);
  for (int o = 0; o < c.out_rows(); ++o)
    for (int l = 0; l < c.n; ++l) c.r[size_t(o) * kLanes + l] = rnd(seed, 9000 + o * 64 + l, -1.f, 1.f);

  std::vector<float> acts(c.act_floats()), grad(layout.param_count, 0.f), dx(size_t(layers[0].in) * kLanes);
  std::vector<float> scratch(net_backward_scratch_floats(layout));
  net_forward(layers, c.params.data(), c.x0.data(), acts.data());
  net_backward(layers, c.params.data(), c.x0.data(), acts.data(), c.r.data(), grad.data(), dx.data(), scratch.data());

  const float h = 4e-3f;
  int checked = 0, kinks = 0;
  for (const auto& l : layers)
    for (size_t k = l.w; k < l.b + size_t(l.out); ++k) {
      NetCase p = c, m = c;
      p.params[k] += h;
      m.params[k] -= h;
      const double l0 = c.loss(), lp = p.loss(), lm = m.loss();
      if (crosses_kink(lp - l0, l0 - lm, h)) {
        ++kinks;
        continue;
      }
      const double fd = (lp - lm) / (2.0 * h);
      EXPECT_NEAR(grad[k], fd, 2e-3 * (1.0 + std::fabs(fd))) << "parameter " << k;
      ++checked;
    }
  EXPECT_GT(checked, 100);
  for (int i = 0; i < layers[0].in; ++i)
    for (int l = 0; l < kLanes; ++l) {
      const size_t k = size_t(i) * kLanes + l;
      if (l >= c.n) {
        continue;  // padding lanes carry no gradient to parameters; their input gradient is unused
      }
      NetCase p = c, m = c;
      p.x0[k] += h;
      m.x0[k] -= h;
      const double l0 = c.loss(), lp = p.loss(), lm = m.loss();
      if (crosses_kink(lp - l0, l0 - lm, h)) {
        ++kinks;
        continue;
      }
      const double fd = (lp - lm) / (2.0 * h);
      EXPECT_NEAR(dx[k], fd, 2e-3 * (1.0 + std::fabs(fd))) << "input " << i << " lane " << l;
      ++checked;
    }
  EXPECT_LT(kinks, checked / 10);  // only a few differences straddle a ReLU kink
}

TEST(MlpKernels, DensityNetGradientMatchesFiniteDifferences) {
  MlpLayout layout(small_arch());
  check_net(layout, layout.density, 1);
}

TEST(MlpKernels, ColorNetGradientMatchesFiniteDifferences) {
  MlpLayout layout(small_arch());
  check_net(layout, layout.color, 2);
}

TEST(MlpKernels, PaddingLanesAddNothingToParameterGradients) {
  MlpLayout layout(small_arch());
  std::vector<float> params(layout.param_count);
  init_mlp_params(layout, 3, params.data());
  const auto& layers = layout.density;
  std::vector<float> x0(size_t(layers[0].in) * kLanes, 0.5f), d(size_t(layers.back().out) * kLanes, 0.f);
  for (int o = 0; o < layers.back().out; ++o) d[size_t(o) * kLanes + 0] = 1.f;  // only lane 0
  std::vector<float> acts(size_t(layout.density_act_floats) * kLanes), g1(layout.param_count, 0.f),
      g2(layout.param_count, 0.f), scratch(net_backward_scratch_floats(layout));
  net_forward(layers, params.data(), x0.data(), acts.data());
  net_backward(layers, params.data(), x0.data(), acts.data(), d.data(), g1.data(), nullptr, scratch.data());
  // Garbage inputs on lanes 1.. change nothing when their output gradient is zero.
  for (int i = 0; i < layers[0].in; ++i)
    for (int l = 1; l < kLanes; ++l) x0[size_t(i) * kLanes + l] = float(l) * 7.f - 50.f;
  net_forward(layers, params.data(), x0.data(), acts.data());
  net_backward(layers, params.data(), x0.data(), acts.data(), d.data(), g2.data(), nullptr, scratch.data());
  EXPECT_EQ(g1, g2);
}

// A net small enough to check by hand: the given density widths (one geo
// output), no direction encoding, a one-layer colour net.
MlpLayout hand_layout(std::vector<int> density_widths) {
  MlpArch a;
  a.density_widths = std::move(density_widths);
  a.dir_frequencies = 0;
  a.color_widths = {1 + 3, 3};
  return MlpLayout(a);
}

// A density net [2, 2, 1] by hand, h = relu(W0 x + b0), out = W1 h + b1, on
// two lanes: x = (1, 1.5) and (-2, 4). Returns the activations of net_forward
// with `in_steps`.
std::vector<float> hand_net_forward(const float* in_steps) {
  const MlpLayout layout = hand_layout({2, 2, 1});
  std::vector<float> p(layout.param_count, 0.f);
  const auto& L0 = layout.density[0];
  const auto& L1 = layout.density[1];
  p[L0.w + 0] = 1.f, p[L0.w + 1] = 2.f, p[L0.w + 2] = -1.f, p[L0.w + 3] = 0.5f;
  p[L0.b + 0] = 0.25f, p[L0.b + 1] = -3.f;
  p[L1.w + 0] = 2.f, p[L1.w + 1] = -1.f, p[L1.b] = 0.5f;
  std::vector<float> x(2 * kLanes, 0.f), acts(3 * kLanes);
  x[0] = 1.f, x[kLanes] = 1.5f;      // lane 0
  x[1] = -2.f, x[kLanes + 1] = 4.f;  // lane 1
  net_forward(layout.density, p.data(), x.data(), acts.data(), -1, in_steps);
  return acts;
}

TEST(MlpKernels, LayerForwardIsAffineThenRelu) {
  const std::vector<float> acts = hand_net_forward(nullptr);
  // lane 0: h = relu(1 + 3 + 0.25, -1 + 0.75 - 3) = (4.25, 0); out = 8.5 + 0.5 = 9
  EXPECT_FLOAT_EQ(acts[0], 4.25f);
  EXPECT_FLOAT_EQ(acts[kLanes], 0.f);
  EXPECT_FLOAT_EQ(acts[2 * kLanes], 9.f);
  // lane 1: h = relu(-2 + 8 + 0.25, 2 + 2 - 3) = (6.25, 1); out = 12.5 - 1 + 0.5 = 12
  EXPECT_FLOAT_EQ(acts[1], 6.25f);
  EXPECT_FLOAT_EQ(acts[kLanes + 1], 1.f);
  EXPECT_FLOAT_EQ(acts[2 * kLanes + 1], 12.f);
}

TEST(MlpKernels, ActivationRoundingIsHalfUpToTheStepAndClamped) {
  // Step 0.5, codes in [-128, 127]: what the chip's INT8 inputs hold.
  std::vector<float> x(2 * kLanes, 0.f);
  const float in[8] = {0.24f, 0.26f, 0.75f, -0.75f, -0.8f, 100.f, -100.f, 63.5f};
  const float want[8] = {0.f, 0.5f, 1.f, -0.5f, -1.f, 63.5f, -64.f, 63.5f};  // ties (1.5, -1.5 steps) go up
  for (int i = 0; i < 8; ++i) x[size_t(i)] = in[i];
  x[size_t(kLanes)] = 1.3f;  // the second row too
  quantize_block(x.data(), 2, 0.5f, -128.f, 127.f);
  for (int i = 0; i < 8; ++i) EXPECT_FLOAT_EQ(x[size_t(i)], want[i]) << in[i];
  EXPECT_FLOAT_EQ(x[size_t(kLanes)], 1.5f);
  EXPECT_EQ(x[size_t(kLanes) + 1], 0.f);  // zero stays zero
}

TEST(MlpKernels, ForwardWithStepsRoundsTheHiddenActivations) {
  // The hand net with input steps (-, 2): the hidden units (4.25, 0) and
  // (6.25, 1) become (4, 0) and (6, 2) (half a step ties up), so the outputs
  // are 8.5 and 10.5.
  const float steps[2] = {1.f, 2.f};
  const std::vector<float> acts = hand_net_forward(steps);
  EXPECT_FLOAT_EQ(acts[0], 4.f);
  EXPECT_FLOAT_EQ(acts[kLanes], 0.f);
  EXPECT_FLOAT_EQ(acts[2 * kLanes], 8.5f);
  EXPECT_FLOAT_EQ(acts[1], 6.f);
  EXPECT_FLOAT_EQ(acts[kLanes + 1], 2.f);
  EXPECT_FLOAT_EQ(acts[2 * kLanes + 1], 10.5f);
}

TEST(MlpKernels, Int8QuantizationRoundsPerRow) {
  const float row[4] = {0.5f, -1.27f, 0.01f, 0.f};
  const float s = int8_row_scale(row, 4);
  EXPECT_FLOAT_EQ(s, 0.01f);
  EXPECT_EQ(int8_quantize(row[0], s), 50);
  EXPECT_EQ(int8_quantize(row[1], s), -127);
  EXPECT_EQ(int8_quantize(row[2], s), 1);
  EXPECT_EQ(int8_quantize(10.f, s), 127);  // saturates
  const float zeros[3] = {0, 0, 0};
  EXPECT_EQ(int8_row_scale(zeros, 3), 1.f);
}

// Equalization by hand: density net [1, 2, 1], hidden unit 0 feeding the
// output with weight 8, unit 1 with weight 2: the geometric mean of the
// column maxima is 4, so unit 0 is scaled by 1/2 and unit 1 by 2.
TEST(MlpKernels, EqualizationMovesColumnRangesToTheirGeometricMean) {
  const MlpLayout layout = hand_layout({1, 2, 1});
  std::vector<float> p(layout.param_count, 0.f), m(layout.param_count, 1.f), v(layout.param_count, 1.f);
  const auto& L0 = layout.density[0];
  const auto& L1 = layout.density[1];
  p[L0.w + 0] = 3.f, p[L0.w + 1] = 5.f, p[L0.b + 0] = 1.f, p[L0.b + 1] = -1.f;
  p[L1.w + 0] = 8.f, p[L1.w + 1] = -2.f;
  equalize_mlp(layout, 1.f, p.data(), m.data(), v.data());
  EXPECT_FLOAT_EQ(p[L1.w + 0], 4.f);
  EXPECT_FLOAT_EQ(p[L1.w + 1], -4.f);
  EXPECT_FLOAT_EQ(p[L0.w + 0], 6.f);  // row 0 times 2 (its column was halved)
  EXPECT_FLOAT_EQ(p[L0.b + 0], 2.f);
  EXPECT_FLOAT_EQ(p[L0.w + 1], 2.5f);  // row 1 halved (its column doubled)
  EXPECT_FLOAT_EQ(p[L0.b + 1], -0.5f);
  // Moments follow the gradients: a parameter times s has m / s and v / s^2.
  EXPECT_FLOAT_EQ(m[L1.w + 0], 2.f);
  EXPECT_FLOAT_EQ(v[L1.w + 0], 4.f);
  EXPECT_FLOAT_EQ(m[L0.w + 1], 2.f);
  EXPECT_FLOAT_EQ(v[L0.w + 1], 4.f);
  EXPECT_FLOAT_EQ(m[L1.b], 1.f);  // output biases are not touched
}

// On a random MLP whose last layer has one dominant column, equalization
// keeps every output (ReLU is positively homogeneous) and lowers the error
// of the INT8 weights.
TEST(MlpKernels, EqualizationKeepsTheFunctionAndLowersInt8Error) {
  const MlpLayout layout(small_arch());
  std::vector<float> p(layout.param_count);
  init_mlp_params(layout, 7, p.data());
  for (size_t i = 0; i < p.size(); ++i) p[i] += rnd(7, 1000 + i, -0.1f, 0.1f);
  for (const auto* net : {&layout.density, &layout.color}) {
    const auto& last = net->back();
    const auto& prev = (*net)[net->size() - 2];
    for (int o = 0; o < last.out; ++o) p[last.w + size_t(o) * last.in] *= 30.f;  // column 0 dominates
    for (int i = 0; i < prev.in; ++i) p[prev.w + size_t(i)] /= 30.f;             // hidden unit 0 small
    p[prev.b] /= 30.f;
  }
  std::vector<float> x(size_t(layout.density[0].in) * kLanes), xc(size_t(layout.color[0].in) * kLanes);
  for (size_t i = 0; i < x.size(); ++i) x[i] = rnd(7, 50000 + i, -1.f, 1.f);
  for (size_t i = 0; i < xc.size(); ++i) xc[i] = rnd(7, 90000 + i, -1.f, 1.f);
  auto outputs = [&](const std::vector<float>& params) {
    std::vector<float> out;
    for (const auto* net : {&layout.density, &layout.color}) {
      size_t floats = 0;
      for (const auto& l : *net) floats += size_t(l.out) * kLanes;
      std::vector<float> acts(floats);
      net_forward(*net, params.data(), net == &layout.density ? x.data() : xc.data(), acts.data());
      out.insert(out.end(), acts.end() - ptrdiff_t(size_t(net->back().out) * kLanes), acts.end());
    }
    return out;
  };
  auto int8_error = [&](const std::vector<float>& params) {
    std::vector<float> q(params.size());
    fake_quantize_mlp(layout, params.data(), q.data());
    const auto a = outputs(params), b = outputs(q);
    double e = 0;
    for (size_t i = 0; i < a.size(); ++i) e += double(a[i] - b[i]) * double(a[i] - b[i]);
    return e;
  };
  const auto before = outputs(p);
  const double error_before = int8_error(p);
  std::vector<float> eq = p;
  equalize_mlp(layout, 1.f, eq.data(), nullptr, nullptr);
  const auto after = outputs(eq);
  for (size_t i = 0; i < before.size(); ++i) EXPECT_NEAR(after[i], before[i], 1e-5f * (1.f + std::fabs(before[i])));
  EXPECT_LT(int8_error(eq), 0.5 * error_before);
  std::vector<float> same = p;
  equalize_mlp(layout, 0.f, same.data(), nullptr, nullptr);
  EXPECT_EQ(same, p);
}

// --- volume rendering ---

TEST(Volume, CompositeMatchesClosedForm) {
  // Two samples with sigma = 2 and 0.5, delta = 0.1, on a grey background.
  const float raw[2] = {std::log(2.f), std::log(0.5f)};
  const float rgb[6] = {1, 0, 0, 0, 1, 0.5f};
  const float bg[3] = {0.5f, 0.5f, 0.5f};
  const CompositeResult r = composite(raw, rgb, 2, 0.1f, bg);
  const double a0 = 1 - std::exp(-0.2), a1 = 1 - std::exp(-0.05);
  const double T1 = 1 - a0, T2 = T1 * (1 - a1);
  EXPECT_NEAR(r.rgb[0], a0 * 1 + T2 * 0.5, 1e-6);
  EXPECT_NEAR(r.rgb[1], T1 * a1 * 1 + T2 * 0.5, 1e-6);
  EXPECT_NEAR(r.rgb[2], T1 * a1 * 0.5 + T2 * 0.5, 1e-6);
  EXPECT_NEAR(r.t_final, T2, 1e-6);
}

TEST(Volume, MarchStopsAfterTheSampleThatCrossesTheThreshold) {
  // alpha = 1 - exp(-sigma delta) with sigma delta = ln 10: each sample divides T by 10.
  const float delta = 0.5f;
  const float raw[6] = {std::log(std::log(10.f) / delta), std::log(std::log(10.f) / delta),
                        std::log(std::log(10.f) / delta), std::log(std::log(10.f) / delta),
                        std::log(std::log(10.f) / delta), std::log(std::log(10.f) / delta)};
  float T;
  // T: 0.1, 0.01, 1e-3, 1e-4 (not below 1e-4 exactly? rounding) ... so use threshold 2e-3.
  const int used = march_transmittance(raw, 6, delta, 2e-3f, 1.f, &T);
  EXPECT_EQ(used, 3);  // after the third sample T = 1e-3 < 2e-3
  EXPECT_NEAR(T, 1e-3, 1e-7);
  EXPECT_EQ(march_transmittance(raw, 2, delta, 2e-3f, 1.f, &T), 2);  // never crosses
}

TEST(Volume, CompositeBackwardMatchesFiniteDifferences) {
  const int n = 7;
  std::vector<float> raw(n), rgb(3 * n);
  for (int i = 0; i < n; ++i) {
    raw[size_t(i)] = rnd(4, uint64_t(i), -1.f, 3.f);
    for (int c = 0; c < 3; ++c) rgb[size_t(3 * i + c)] = rnd(5, uint64_t(3 * i + c), 0.f, 1.f);
  }
  raw[2] = 20.f;  // beyond the clamp: no gradient
  const float bg[3] = {1.f, 0.8f, 0.2f};
  const float g[3] = {0.3f, -0.7f, 1.1f};
  const float delta = 0.05f;
  auto loss = [&](const std::vector<float>& r, const std::vector<float>& c) {
    const CompositeResult res = composite(r.data(), c.data(), n, delta, bg);
    return double(g[0]) * res.rgb[0] + double(g[1]) * res.rgb[1] + double(g[2]) * res.rgb[2];
  };
  std::vector<float> d_raw(n), d_rgb(3 * n);
  composite_backward(raw.data(), rgb.data(), n, delta, bg, g, d_raw.data(), d_rgb.data());
  const float h = 1e-3f;
  for (int i = 0; i < n; ++i) {
    auto p = raw, m = raw;
    p[size_t(i)] += h;
    m[size_t(i)] -= h;
    const double fd = (loss(p, rgb) - loss(m, rgb)) / (2.0 * h);
    EXPECT_NEAR(d_raw[size_t(i)], fd, 1e-3 * (1 + std::fabs(fd))) << "raw " << i;
  }
  EXPECT_EQ(d_raw[2], 0.f);
  for (int k = 0; k < 3 * n; ++k) {
    auto p = rgb, m = rgb;
    p[size_t(k)] += h;
    m[size_t(k)] -= h;
    const double fd = (loss(raw, p) - loss(raw, m)) / (2.0 * h);
    EXPECT_NEAR(d_rgb[size_t(k)], fd, 1e-3 * (1 + std::fabs(fd))) << "rgb " << k;
  }
}

TEST(Volume, DistortionLossKnownValues) {
  // One sample holding all the weight: only the self term w^2 s / 3 remains.
  const float delta = 0.1f;
  const float opaque[1] = {std::log(200.f / delta)};  // tau = 200: w = 1 - exp(-200) = 1
  const float t1[1] = {0.5f};
  EXPECT_NEAR(distortion_loss(opaque, t1, 1, delta, 0.3f), 0.1, 1e-6);
  // Two samples of weight 1/2 each, 2 apart: 2 * (1/2)(1/2) * 2 + 2 * (1/4) s / 3.
  // w_0 = 1/2 needs tau_0 = ln 2; w_1 = 1/2 needs alpha_1 = 1 (an opaque second sample).
  const float raw[2] = {std::log(std::log(2.f) / delta), std::log(200.f / delta)};
  const float t2[2] = {1.f, 3.f};
  EXPECT_NEAR(distortion_loss(raw, t2, 2, delta, 0.6f), 1.0 + 0.1, 1e-5);
}

TEST(Volume, DistortionBackwardMatchesFiniteDifferences) {
  const int n = 9;
  std::vector<float> raw(n), t(n);
  for (int i = 0; i < n; ++i) {
    raw[size_t(i)] = rnd(6, uint64_t(i), -1.f, 4.f);
    t[size_t(i)] = 0.3f * float(i) + (i > 4 ? 1.f : 0.f);  // increasing, with a gap
  }
  raw[3] = 20.f;  // beyond the clamp: no gradient
  const float delta = 0.05f, s = 0.3f, scale = 0.7f;
  std::vector<float> d_raw(n, 0.25f);  // the loss gradient is added to what is there
  distortion_backward(raw.data(), t.data(), n, delta, s, scale, d_raw.data());
  const float h = 1e-3f;
  for (int i = 0; i < n; ++i) {
    auto p = raw, m = raw;
    p[size_t(i)] += h;
    m[size_t(i)] -= h;
    const double fd =
        scale * (distortion_loss(p.data(), t.data(), n, delta, s) - distortion_loss(m.data(), t.data(), n, delta, s)) /
        (2.0 * h);
    EXPECT_NEAR(d_raw[size_t(i)] - 0.25f, fd, 1e-3 * (1 + std::fabs(fd))) << "raw " << i;
  }
  EXPECT_EQ(d_raw[3], 0.25f);
}

}  // namespace
}  // namespace edrnr::train
