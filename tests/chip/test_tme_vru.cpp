#include <gtest/gtest.h>

#include <cmath>

#include "chip/activation_lut.h"
#include "chip/tme.h"
#include "chip/vru.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

TEST(ActivationLut, DeterministicFunctionsMatchTheirClosedForms) {
  EXPECT_EQ(det_exp(0.0), 1.0);
  EXPECT_NEAR(det_exp(1.0), 2.718281828459045, 1e-15);
  EXPECT_NEAR(det_exp(-20.5), 1.2501528663867426e-09, 1e-24);
  EXPECT_NEAR(det_log(2.718281828459045), 1.0, 1e-15);
  EXPECT_NEAR(det_log(0.1), -2.302585092994046, 1e-15);
  EXPECT_NEAR(det_sin(0.5), 0.479425538604203, 1e-15);
  EXPECT_NEAR(det_cos(2.0), -0.4161468365471424, 1e-15);
  EXPECT_NEAR(det_sin(-3.0), -0.1411200080598672, 1e-15);
  EXPECT_NEAR(det_cos(100.0), 0.8623188722876839, 1e-13);
}

TEST(ActivationLut, InterpolatesLinearlyAndClampsOutsideItsRange) {
  // f(x) = x / 16 + 0.5 on [-8, 8], inputs with 4 fraction bits, 16 entries,
  // 8-bit output Q1.7: a linear function is exact between entries.
  ActivationLut lut([](double x) { return x / 16 + 0.5; }, -8, 8, 4, 4, 8, fx::Rounding::HalfUp);
  EXPECT_EQ(lut.base_code(), -128);
  EXPECT_EQ(lut.shift(), 5);  // 15 intervals of 16 codes fall short of the 256-code range; of 32 they do not
  EXPECT_EQ(lut(0), 64);      // 0.5 in Q1.7
  EXPECT_EQ(lut(-128), 0);
  EXPECT_EQ(lut(-1000), 0);
  EXPECT_EQ(lut(8), 68);  // x = 0.5: 0.53125 * 128, between entries 4 (x = 0) and 5 (x = 2)
  EXPECT_EQ(lut(1000), lut.table().back());
}

TEST(ActivationLut, AlphaAndSigmoidTables) {
  const double delta = 0.1;
  ActivationLut alpha = make_alpha_lut(delta, 8, 10, 16, fx::Rounding::HalfUp);
  // exp(raw) delta = ln 2 gives alpha = 1/2.
  const double raw_half = std::log(std::log(2.0) / delta);
  EXPECT_NEAR(double(alpha(std::lround(raw_half * 256))), 16384.0, 20.0);
  for (double raw : {-6.0, -2.0, 0.0, 1.0, 2.5, 4.0}) {
    const double expect = (1.0 - std::exp(-std::exp(raw) * delta)) * 32768.0;
    EXPECT_NEAR(double(alpha(std::lround(raw * 256))), expect, 1.0) << raw;
  }
  EXPECT_EQ(alpha(-30 * 256), 0);
  EXPECT_EQ(alpha(15 * 256), 32768);
  int64_t last = -1;
  for (int64_t c = -4000; c <= 2000; c += 7) {
    EXPECT_GE(alpha(c), last);
    last = alpha(c);
  }
  ActivationLut sig = make_sigmoid_lut(8, 10, 16, fx::Rounding::HalfUp);
  for (int64_t code : {-2048, -256, 0, 77, 384, 1792})  // x = code / 256
    EXPECT_NEAR(double(sig(code)), 32768.0 / (1.0 + std::exp(-double(code) / 256)), 1.0) << code;
  EXPECT_EQ(sig(0), 16384);
}

// A one-MLP model: density net [2 -> 2], colour net [2 + 3 -> 3], L = 0.
SceneModel tiny_mlp_model() {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 2;
  m.init_grids();
  m.feature_quant.scale = {0.5f, 0.5f};
  m.feature_quant.zero_point = {8, 8};
  m.mlp_arch.density_widths = {2, 2};
  m.mlp_arch.color_widths = {5, 3};
  m.mlp_arch.dir_frequencies = 0;
  MlpQ q;
  DenseQ d;
  d.in = 2;
  d.out = 2;
  d.w = {64, 0, 0, 64};
  d.w_scale = {1 / 64.f, 1 / 64.f};
  d.b = {0, 0};
  d.in_scale = 1 / 32.f;
  q.density.push_back(d);
  DenseQ c;
  c.in = 5;
  c.out = 3;
  // rgb0 = geo0, rgb1 = -dir_x, rgb2 = -geo1 + 1.
  c.w = {64, 0, 0, 0, 0, 0, 0, -64, 0, 0, 0, -64, 0, 0, 0};
  c.w_scale = {1 / 64.f, 1 / 64.f, 1 / 64.f};
  c.b = {0, 0, 1};
  c.in_scale = 1 / 16.f;
  q.color.push_back(c);
  m.mlps_q8 = {q};
  m.mlp_coarse_index = {0};
  m.finalize();
  return m;
}

TEST(Tme, EvaluatesTheIntegerMlpByHand) {
  const SceneModel m = tiny_mlp_model();
  const double delta = 0.1;
  Tme tme(m, ChipNumerics{}, delta, 8448);
  // q8_bytes: 4 + 15 weights + 8 bytes for each of 5 neurons = 59; plus 4
  // bytes for each of the 2 feature and the 2 colour-input multipliers.
  EXPECT_EQ(tme.mlp(0).stored_bytes, 75u);
  tme.load(0);
  tme.load(0);
  EXPECT_EQ(tme.counters().mlp_loads, 1u);
  // Features 2.0 and -1.0 code steps (8 fraction bits) are 1.0 and -0.5:
  // INT8 inputs 32 and -16 (step 1/32); raw outputs acc / 8: 256 and -128.
  const int32_t feature[2] = {512, -256};
  const std::vector<int32_t> dir = Tme::encode_direction({1, 0, 0}, 0, ChipNumerics{});
  EXPECT_EQ(dir, (std::vector<int32_t>{16384, 0, 0}));
  const TmeOutput out = tme.eval(feature, dir);
  EXPECT_EQ(out.raw_density, 256);  // 1.0
  // Colour inputs: geo 16, -8 (step 1/16); direction 127, 0, 0 (its own step
  // 1/127), whose partial sum -64 * 127 becomes -1024 accumulator units
  // (x 16/127). rgb0 = 1.0, rgb1 = -1.0, rgb2 = 0.5 + 1 = 1.5.
  EXPECT_NEAR(double(out.rgb[0]), 32768 / (1 + std::exp(-1.0)), 1.0);
  EXPECT_NEAR(double(out.rgb[1]), 32768 / (1 + std::exp(1.0)), 1.0);
  EXPECT_NEAR(double(out.rgb[2]), 32768 / (1 + std::exp(-1.5)), 1.0);
  EXPECT_NEAR(double(out.alpha), 32768 * (1 - std::exp(-std::exp(1.0) * delta)), 1.0);
  EXPECT_EQ(tme.counters().macs, 2u * 2u + 5u * 3u);
}

// The direction keeps its own input step: with a coarse colour-net input step
// (1/4, as large density outputs give), a direction component of 0.3 still
// reaches the colour to within the INT8 direction step (1/127), where sharing
// the step would have made it 0.25.
TEST(Tme, DirectionKeepsItsOwnInputStep) {
  SceneModel m = tiny_mlp_model();
  m.mlps_q8[0].color[0].in_scale = 0.25f;
  Tme tme(m, ChipNumerics{}, 0.1, 8448);
  tme.load(0);
  const int32_t feature[2] = {512, -256};
  const double dx = 0.3, dz = std::sqrt(1 - dx * dx);
  const TmeOutput out = tme.eval(feature, Tme::encode_direction({dx, 0, dz}, 0, ChipNumerics{}));
  EXPECT_NEAR(double(out.rgb[0]), 32768 / (1 + std::exp(-1.0)), 1.0);
  EXPECT_NEAR(double(out.rgb[1]), 32768 / (1 + std::exp(dx)), 32768 * 0.25 / 127);
  EXPECT_NEAR(double(out.rgb[2]), 32768 / (1 + std::exp(-1.5)), 1.0);
}

TEST(Tme, RefusesMlpsTheChipCannotHold) {
  const SceneModel m = tiny_mlp_model();
  EXPECT_THROW(Tme(m, ChipNumerics{}, 0.1, 74), Error);  // 75 bytes do not fit
  SceneModel bad = m;
  bad.mlps_q8[0].density[0].w_scale[1] = -1.f;
  EXPECT_THROW(Tme(bad, ChipNumerics{}, 0.1, 8448), Error);
  bad = m;
  bad.mlps_q8[0].color[0].in_scale = 0.f;
  EXPECT_THROW(Tme(bad, ChipNumerics{}, 0.1, 8448), Error);
}

TEST(Tme, DirectionEncodingByHand) {
  // d = (0, 0.6, -0.8), L = 1: [d, sin d, cos d] in Q1.14.
  const auto code = Tme::encode_direction({0, 0.6, -0.8}, 1, ChipNumerics{});
  ASSERT_EQ(code.size(), 9u);
  EXPECT_EQ(code[1], std::lround(0.6 * 16384));
  EXPECT_EQ(code[2], std::lround(-0.8 * 16384));
  EXPECT_EQ(code[4], std::lround(std::sin(0.6) * 16384));
  EXPECT_EQ(code[6], 16384);  // cos 0
  EXPECT_EQ(code[8], std::lround(std::cos(-0.8) * 16384));
}

TEST(Vru, CompositesByHandAndStopsAtTheThreshold) {
  const float bg[3] = {1.f, 0.5f, 0.f};
  Vru vru(ChipNumerics{}, 1e-4, bg);
  EXPECT_EQ(vru.threshold_code(), 4);  // ceil(3.2768)
  RayState ray;
  ray.valid = true;
  vru.start(ray);
  EXPECT_EQ(ray.transmittance, 32768);
  vru.composite(ray, 16384, {32768, 0, 16384});  // alpha 1/2: weight 1/2
  EXPECT_EQ(ray.color, (std::array<int64_t, 3>{16384, 0, 8192}));
  EXPECT_EQ(ray.transmittance, 16384);
  // Pixel now: C + T bg = (0.5 + 0.5, 0 + 0.25, 0.25 + 0).
  auto px = vru.pixel(ray);
  EXPECT_EQ(px[0], 1.f);
  EXPECT_EQ(px[1], 0.25f);
  EXPECT_EQ(px[2], 0.25f);
  vru.composite(ray, 24576, {0, 32768, 0});  // alpha 3/4: weight 3/8
  EXPECT_EQ(ray.color[1], 12288);
  EXPECT_EQ(ray.transmittance, 4096);
  EXPECT_FALSE(ray.terminated);
  vru.composite(ray, 32767, {0, 0, 0});  // T = round(4096 / 32768) = 0 < 4
  EXPECT_TRUE(ray.terminated);
  vru.composite(ray, 32768, {32768, 32768, 32768});  // ignored
  EXPECT_EQ(ray.color[0], 16384);
  EXPECT_EQ(vru.counters().samples, 3u);
  EXPECT_EQ(vru.counters().samples_skipped, 1u);
  EXPECT_EQ(vru.counters().rays_terminated, 1u);
  EXPECT_THROW(Vru(ChipNumerics{}, 2.0, bg), Error);
}

}  // namespace
}  // namespace edrnr::chip
