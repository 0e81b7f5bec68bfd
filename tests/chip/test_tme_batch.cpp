// The TME on a batch of samples against a plain per-sample evaluation of the
// integer MLP written from its documented formulas (tme.h), on an MLP whose
// biases and inputs drive the accumulators and outputs into saturation.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "chip/activation_lut.h"
#include "chip/tme.h"

namespace edrnr::chip {
namespace {

// density [4 -> 8 -> 3], colour [3 + 3 -> 8 -> 3], no direction frequencies.
SceneModel saturating_model(uint32_t seed, int mlps = 1) {
  std::mt19937 rng(seed);
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 4;
  m.init_grids();
  m.feature_quant.scale = {0.5f, 0.25f, 1.0f, 0.125f};
  m.feature_quant.zero_point = {8, 7, 8, 9};
  m.mlp_arch.density_widths = {4, 8, 3};
  m.mlp_arch.color_widths = {6, 8, 3};
  m.mlp_arch.dir_frequencies = 0;
  auto dense = [&](int in, int out, float in_scale) {
    DenseQ d;
    d.in = in;
    d.out = out;
    for (int i = 0; i < in * out; ++i) d.w.push_back(int8_t(int(rng() % 256) - 128));
    for (int j = 0; j < out; ++j) {
      d.w_scale.push_back(1 / 64.f);
      // Every third bias is far past the INT20 accumulator (saturated at
      // once); others sit near its limit, so that the products can cross it.
      const float acc_unit = in_scale / 64.f;
      const float b = j % 3 == 0 ? 3e6f : (j % 3 == 1 ? 5.1e5f : float(int(rng() % 2001) - 1000));
      d.b.push_back(b * acc_unit * ((rng() & 1) ? 1.f : -1.f));
    }
    d.in_scale = in_scale;
    return d;
  };
  for (int i = 0; i < mlps; ++i) {
    MlpQ q;
    q.density = {dense(4, 8, 1 / 32.f), dense(8, 3, 1 / 16.f)};
    q.color = {dense(6, 8, 1 / 16.f), dense(8, 3, 1 / 8.f)};
    m.mlps_q8.push_back(q);
    m.mlp_coarse_index.push_back(uint32_t(i));
  }
  m.finalize();
  return m;
}

struct RefCounters {
  uint64_t saturations = 0, macs = 0;
};

// One sample, as tme.h states it: saturating accumulation after each
// product, the direction products apart, one rounding per requantization.
TmeOutput reference_eval(const Tme& tme, const TmeMlp& m, const ChipNumerics& n, const int32_t* feature,
                         const std::vector<int32_t>& dir_code, int F, RefCounters& c) {
  const fx::Requant dir_code_q = fx::requant_from_scale(
      std::ldexp(1.0 / (1.0 / double(fx::max_signed(n.activation_bits))), -n.direction_code_frac_bits),
      n.requant_multiplier_bits);
  auto narrow = [&](int64_t v, int bits) {
    const int64_t s = fx::saturate(v, bits);
    c.saturations += s != v;
    return s;
  };
  auto layer = [&](const TmeLayer& L, const std::vector<int64_t>& x, bool hidden, int out_bits, int split,
                   const fx::Requant* split_q) {
    std::vector<int64_t> y(size_t(L.out));
    for (int j = 0; j < L.out; ++j) {
      int64_t acc = narrow(L.bias[size_t(j)], n.accumulator_bits);
      const int main_in = split >= 0 ? split : L.in;
      for (int i = 0; i < main_in; ++i)
        acc = narrow(acc + int64_t(L.w[size_t(j * L.in + i)]) * x[size_t(i)], n.accumulator_bits);
      if (split >= 0) {
        int64_t part = 0;
        for (int i = split; i < L.in; ++i) part += int64_t(L.w[size_t(j * L.in + i)]) * x[size_t(i)];
        part = narrow(part, n.accumulator_bits);
        acc = narrow(acc + fx::requantize(part, *split_q, n.rounding), n.accumulator_bits);
      }
      c.macs += uint64_t(L.in);
      y[size_t(j)] =
          narrow(fx::requantize(hidden ? std::max<int64_t>(acc, 0) : acc, L.requant[size_t(j)], n.rounding), out_bits);
    }
    return y;
  };
  std::vector<int64_t> x;
  for (int ch = 0; ch < F; ++ch)
    x.push_back(narrow(fx::requantize(feature[ch], m.feature_in[size_t(ch)], n.rounding), n.activation_bits));
  for (size_t l = 0; l < m.density.size(); ++l) {
    const bool hidden = l + 1 < m.density.size();
    x = layer(m.density[l], x, hidden, hidden ? n.activation_bits : n.mlp_output_bits, -1, nullptr);
  }
  TmeOutput out;
  out.raw_density = x[0];
  out.alpha = tme.alpha_lut()(x[0]);
  const int G = int(x.size());
  std::vector<int64_t> in;
  for (int64_t g : x) in.push_back(narrow(fx::requantize(g, m.geo_in, n.rounding), n.activation_bits));
  for (int32_t d : dir_code) in.push_back(narrow(fx::requantize(d, dir_code_q, n.rounding), n.activation_bits));
  x = in;
  for (size_t l = 0; l < m.color.size(); ++l) {
    const bool hidden = l + 1 < m.color.size();
    x = layer(m.color[l], x, hidden, hidden ? n.activation_bits : n.mlp_output_bits, l == 0 ? G : -1, &m.dir_in);
  }
  for (int k = 0; k < 3; ++k) out.rgb[size_t(k)] = tme.sigmoid_lut()(x[size_t(k)]);
  return out;
}

// Random interpolated features over the whole INT16 range (many clip at the
// input), F per sample.
std::vector<int32_t> random_features(std::mt19937& rng, size_t samples, int F) {
  std::vector<int32_t> features(samples * size_t(F));
  for (int32_t& f : features) f = int32_t(int(rng() % 65536) - 32768) >> int(rng() % 8);
  return features;
}

// Rays of the given directions (no frequencies) with their TME inputs, and
// sample s on ray s % dirs.size().
struct BatchRays {
  std::vector<std::vector<int32_t>> codes;
  std::vector<TmeDirection> inputs;
  std::vector<TmeDirection*> of_sample;
};
BatchRays batch_rays(const Tme& tme, const ChipNumerics& n, const std::vector<Vec3d>& dirs, size_t samples) {
  BatchRays b;
  b.inputs.resize(dirs.size());
  for (size_t r = 0; r < dirs.size(); ++r) {
    b.codes.push_back(Tme::encode_direction(dirs[r], 0, n));
    tme.direction_input(b.codes.back(), b.inputs[r]);
  }
  for (size_t s = 0; s < samples; ++s) b.of_sample.push_back(&b.inputs[s % dirs.size()]);
  return b;
}

void check_batch(fx::Rounding rounding, uint32_t seed) {
  const SceneModel model = saturating_model(seed);
  ChipNumerics n;
  n.rounding = rounding;
  Tme tme(model, n, 0.1, 8448);
  tme.load(0);
  std::mt19937 rng(seed + 1);
  const int F = model.feature_channels;
  const size_t samples = 53;
  const std::vector<int32_t> features = random_features(rng, samples, F);
  // Five rays, one of them along an axis (codes of +-1 clip to the INT8 step).
  const std::vector<Vec3d> dirs = {{1, 0, 0}, {0.6, -0.8, 0}, {-0.48, 0.6, 0.64}, {0, 0, -1}, {0.1, 0.2, -0.97}};
  BatchRays rays = batch_rays(tme, n, dirs, samples);
  const std::vector<std::vector<int32_t>>& codes = rays.codes;
  std::vector<TmeOutput> out(samples);
  tme.eval_batch(samples, features.data(), rays.of_sample.data(), out.data());

  RefCounters ref;
  for (size_t s = 0; s < samples; ++s) {
    const TmeOutput e = reference_eval(tme, tme.mlp(0), n, &features[s * size_t(F)], codes[s % dirs.size()], F, ref);
    ASSERT_EQ(out[s].raw_density, e.raw_density) << s;
    ASSERT_EQ(out[s].alpha, e.alpha) << s;
    ASSERT_EQ(out[s].rgb, e.rgb) << s;
  }
  EXPECT_EQ(tme.counters().samples, samples);
  EXPECT_EQ(tme.counters().macs, ref.macs);
  EXPECT_EQ(tme.counters().saturations, ref.saturations);
  EXPECT_GT(ref.saturations, samples);  // the saturating paths were taken

  // One sample at a time through eval() gives the same again.
  Tme single(model, n, 0.1, 8448);
  single.load(0);
  for (size_t s = 0; s < samples; ++s) {
    const TmeOutput e = single.eval(&features[s * size_t(F)], codes[s % dirs.size()]);
    ASSERT_EQ(e.rgb, out[s].rgb) << s;
    ASSERT_EQ(e.raw_density, out[s].raw_density) << s;
  }
  EXPECT_EQ(single.counters().saturations, tme.counters().saturations);
  EXPECT_EQ(single.counters().macs, tme.counters().macs);
}

// A ray's direction terms are kept in its TmeDirection between batches: they
// must be made again for another MLP, and for another TME's MLP of the same
// index (another model), and reused when the MLP comes back.
TEST(TmeBatch, KeptDirectionTermsFollowTheMlpAndTheTme) {
  const SceneModel model = saturating_model(11, 2), other_model = saturating_model(12, 1);
  ChipNumerics n;
  n.rounding = fx::Rounding::HalfUp;
  Tme tme(model, n, 0.1, 8448), other(other_model, n, 0.1, 8448);
  ASSERT_EQ(tme.mlp_count(), 2u);
  std::mt19937 rng(13);
  const int F = model.feature_channels;
  const size_t samples = 20;
  const std::vector<int32_t> features = random_features(rng, samples, F);
  const std::vector<Vec3d> dirs = {{0.6, -0.8, 0}, {-0.48, 0.6, 0.64}, {0.1, 0.2, -0.97}};
  BatchRays rays = batch_rays(tme, n, dirs, samples);
  const std::vector<std::vector<int32_t>>& codes = rays.codes;
  std::vector<TmeDirection*>& of_sample = rays.of_sample;
  std::vector<TmeOutput> out(samples);
  auto expect_reference = [&](const Tme& t, int mlp, const char* what) {
    RefCounters ref;
    for (size_t s = 0; s < samples; ++s) {
      const TmeOutput e =
          reference_eval(t, t.mlp(size_t(mlp)), n, &features[s * size_t(F)], codes[s % dirs.size()], F, ref);
      ASSERT_EQ(out[s].raw_density, e.raw_density) << what << " sample " << s;
      ASSERT_EQ(out[s].rgb, e.rgb) << what << " sample " << s;
    }
  };
  bool rgb_differs = false;
  std::vector<TmeOutput> first;
  for (int mlp : {0, 1, 0}) {
    tme.select(mlp);
    tme.eval_batch(samples, features.data(), of_sample.data(), out.data());
    expect_reference(tme, mlp, mlp == 0 ? "MLP 0" : "MLP 1");
    if (first.empty())
      first = out;
    else
      for (size_t s = 0; s < samples; ++s) rgb_differs |= out[s].rgb != first[s].rgb;
  }
  EXPECT_TRUE(rgb_differs);  // the two MLPs disagree somewhere: a stale term would show
  other.select(0);
  other.eval_batch(samples, features.data(), of_sample.data(), out.data());
  expect_reference(other, 0, "another TME");
}

// The direction codes are the values (the direction, det_sin_cos's sines
// and cosines of 2^k times it) as fx::to_fixed rounds them, in every mode,
// ties included (0.5 + 2^-15 is 8192.5 steps of 2^-14).
TEST(TmeBatch, DirectionCodesAreTheValuesRoundedByToFixed) {
  const std::vector<Vec3d> dirs = {
      {0.5 + 0x1p-15, -0.5 - 0x1p-15, 0.7}, {1, 0, 0}, {-0.48, 0.6, 0.64}, {0.1, 0.2, -0.97}, {-1, 0, 0}};
  for (fx::Rounding mode : {fx::Rounding::Floor, fx::Rounding::HalfUp, fx::Rounding::HalfEven}) {
    ChipNumerics n;
    n.rounding = mode;
    const int L = 3;
    for (const Vec3d& d : dirs) {
      const std::vector<int32_t> code = Tme::encode_direction(d, L, n);
      ASSERT_EQ(code.size(), size_t(3 + 6 * L));
      std::vector<double> arg;
      for (int k = 0; k < L; ++k)
        for (int a = 0; a < 3; ++a) arg.push_back(std::ldexp(d[a], k));
      std::vector<double> sn(arg.size()), cs(arg.size());
      det_sin_cos(arg.data(), arg.size(), sn.data(), cs.data());
      std::vector<double> values = {d.x, d.y, d.z};
      for (int k = 0; k < L; ++k) {
        for (int a = 0; a < 3; ++a) values.push_back(sn[size_t(3 * k + a)]);
        for (int a = 0; a < 3; ++a) values.push_back(cs[size_t(3 * k + a)]);
      }
      for (size_t i = 0; i < values.size(); ++i)
        EXPECT_EQ(code[i], fx::to_fixed(values[i], n.direction_code_frac_bits, n.direction_code_bits, mode))
            << "mode " << int(mode) << " value " << i;
    }
  }
  ChipNumerics floor, half_up;
  floor.rounding = fx::Rounding::Floor;
  half_up.rounding = fx::Rounding::HalfUp;
  const Vec3d tie{0.5 + 0x1p-15, -0.5 - 0x1p-15, 0};
  EXPECT_EQ(Tme::encode_direction(tie, 0, floor), (std::vector<int32_t>{8192, -8193, 0}));
  EXPECT_EQ(Tme::encode_direction(tie, 0, half_up), (std::vector<int32_t>{8193, -8192, 0}));
}

TEST(TmeBatch, MatchesThePerSampleFormulasInEveryRoundingMode) {
  check_batch(fx::Rounding::HalfUp, 5);
  check_batch(fx::Rounding::HalfEven, 6);
  check_batch(fx::Rounding::Floor, 7);
}

}  // namespace
}  // namespace edrnr::chip
