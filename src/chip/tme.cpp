#include "chip/tme.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/error.h"

namespace edrnr::chip {

namespace {

// The step of the INT8 direction inputs: +-1 maps to the largest code.
double direction_step(const ChipNumerics& n) { return 1.0 / double(fx::max_signed(n.activation_bits)); }

fx::Requant requant_or_fail(double scale, int bits, size_t mlp, const char* what) {
  if (!std::isfinite(scale) || scale < 0.0)
    fail("INT8 MLP {}: {} scale {} is not a finite non-negative number", mlp, what, scale);
  if (scale == 0.0) return {0, 0};
  try {
    return fx::requant_from_scale(scale, bits);
  } catch (const Error& e) {
    fail("INT8 MLP {}: {} scale {} cannot be a {}-bit requantization multiplier: {}", mlp, what, scale, bits, e.what());
  }
}

std::vector<TmeLayer> compile_net(const std::vector<DenseQ>& net, const std::vector<int>& widths, size_t mlp,
                                  const char* name, const ChipNumerics& n) {
  if (net.size() + 1 != widths.size())
    fail("INT8 MLP {} has {} {} layers, mlp_arch says {}", mlp, net.size(), name, widths.size() - 1);
  std::vector<TmeLayer> out;
  for (size_t l = 0; l < net.size(); ++l) {
    const DenseQ& d = net[l];
    if (d.in != widths[l] || d.out != widths[l + 1] || d.w.size() != size_t(d.in) * size_t(d.out) ||
        d.w_scale.size() != size_t(d.out) || d.b.size() != size_t(d.out))
      fail("INT8 MLP {} {} layer {} does not have the {}x{} shape of mlp_arch", mlp, name, l, widths[l + 1], widths[l]);
    if (d.in > kMaxLayerWidth || d.out > kMaxLayerWidth)
      fail("INT8 MLP {} {} layer {} is {}x{}, wider than the TME's {}", mlp, name, l, d.out, d.in, kMaxLayerWidth);
    if (!(d.in_scale > 0.f) || !std::isfinite(d.in_scale))
      fail("INT8 MLP {} {} layer {}: input scale {} is not positive", mlp, name, l, d.in_scale);
    const bool hidden = l + 1 < net.size();
    TmeLayer t;
    t.in = d.in;
    t.out = d.out;
    t.w = d.w;
    t.bias.resize(size_t(d.out));
    t.requant.resize(size_t(d.out));
    t.abs_weight_sum.resize(size_t(d.out));
    for (int j = 0; j < d.out; ++j) {
      const double ws = d.w_scale[size_t(j)];
      if (!std::isfinite(ws) || ws < 0.0)
        fail("INT8 MLP {} {} layer {} neuron {}: weight scale {} is not finite and >= 0", mlp, name, l, j, ws);
      double acc_unit = ws * double(d.in_scale);
      if (ws == 0.0) {  // the row's weights stand for zero
        std::fill(t.w.begin() + size_t(j) * size_t(d.in), t.w.begin() + size_t(j + 1) * size_t(d.in), int8_t(0));
        acc_unit = double(d.in_scale);
      }
      t.bias[size_t(j)] = fx::to_fixed(double(d.b[size_t(j)]) / acc_unit, 0, 32, n.rounding);
      const double scale =
          hidden ? acc_unit / double(net[l + 1].in_scale) : std::ldexp(acc_unit, n.mlp_output_frac_bits);
      t.requant[size_t(j)] = requant_or_fail(scale, n.requant_multiplier_bits, mlp, name);
      for (int i = 0; i < d.in; ++i)
        t.abs_weight_sum[size_t(j)] += std::abs(int64_t(t.w[size_t(j) * size_t(d.in) + size_t(i)]));
    }
    out.push_back(std::move(t));
  }
  return out;
}

}  // namespace

TmeMlp compile_tme_mlp(const SceneModel& model, size_t index, const ChipNumerics& n) {
  const MlpArch& arch = model.mlp_arch;
  const MlpQ& q = model.mlps_q8.at(index);
  TmeMlp m;
  m.density = compile_net(q.density, arch.density_widths, index, "density", n);
  m.color = compile_net(q.color, arch.color_widths, index, "colour", n);
  if (arch.color_widths.front() != arch.geo_width() + arch.dir_dims())
    fail("mlp_arch colour input {} is not the density output {} plus {} direction values", arch.color_widths.front(),
         arch.geo_width(), arch.dir_dims());
  const double d_in = q.density.front().in_scale, c_in = q.color.front().in_scale;
  for (int c = 0; c < model.feature_channels; ++c) {
    const double s = model.feature_quant.scale.at(size_t(c));
    m.feature_in.push_back(requant_or_fail(std::ldexp(s / d_in, -n.interp_feature_frac_bits), n.requant_multiplier_bits,
                                           index, "feature input"));
  }
  m.geo_in = requant_or_fail(std::ldexp(1.0 / c_in, -n.mlp_output_frac_bits), n.requant_multiplier_bits, index,
                             "density-to-colour input");
  m.dir_in = requant_or_fail(direction_step(n) / c_in, n.requant_multiplier_bits, index, "direction partial sum");
  m.stored_bytes = arch.q8_bytes();
  return m;
}

std::vector<int32_t> Tme::encode_direction(const Vec3d& dir, int frequencies, const ChipNumerics& n) {
  std::vector<int32_t> out;
  auto put = [&](double v) {
    out.push_back(int32_t(fx::to_fixed(v, n.direction_code_frac_bits, n.direction_code_bits, n.rounding)));
  };
  for (int a = 0; a < 3; ++a) put(dir[a]);
  for (int k = 0; k < frequencies; ++k) {
    const double f = std::ldexp(1.0, k);
    for (int a = 0; a < 3; ++a) put(det_sin(f * dir[a]));
    for (int a = 0; a < 3; ++a) put(det_cos(f * dir[a]));
  }
  return out;
}

Tme::Tme(const SceneModel& model, const ChipNumerics& numerics, double delta, size_t mlp_cache_bytes)
    : model_(model),
      n_(numerics),
      alpha_lut_(make_alpha_lut(delta, numerics.mlp_output_frac_bits, numerics.lut_address_bits, numerics.alpha_bits,
                                numerics.rounding)),
      sigmoid_lut_(make_sigmoid_lut(numerics.mlp_output_frac_bits, numerics.lut_address_bits, numerics.color_bits,
                                    numerics.rounding)),
      dir_code_(fx::requant_from_scale(std::ldexp(1.0 / direction_step(numerics), -numerics.direction_code_frac_bits),
                                       numerics.requant_multiplier_bits)) {
  if (model.mlp_count() > 0 && model.mlps_q8.size() != model.mlp_count())
    fail("model has no INT8 MLPs for its {} coarse voxels (the chip runs only the quantized form)", model.mlp_count());
  for (size_t i = 0; i < model.mlps_q8.size(); ++i) {
    mlps_.push_back(compile_tme_mlp(model, i, numerics));
    if (mlps_.back().stored_bytes > mlp_cache_bytes)
      fail("INT8 MLP {} takes {} bytes on chip, more than the {}-byte MLP cache", i, mlps_.back().stored_bytes,
           mlp_cache_bytes);
  }
}

void Tme::load(uint32_t cv_tag) {
  const int32_t m = model_.coarse_to_mlp.at(cv_tag);
  if (m < 0) fail("coarse voxel {} is occupied but has no MLP (the model breaks its invariants)", cv_tag);
  if (m == current_) return;
  current_ = m;
  ++counters_.mlp_loads;
  counters_.mlp_load_bytes += mlps_[size_t(m)].stored_bytes;
}

void Tme::layer(const TmeLayer& L, const int32_t* x, int32_t* y, bool hidden, int out_bits, int split,
                const fx::Requant* split_q) {
  const int A = n_.accumulator_bits;
  const int main_in = split >= 0 ? split : L.in;
  const int64_t acc_max = fx::max_signed(A);
  const int64_t x_max = int64_t(1) << (n_.activation_bits - 1);  // |x| <= 2^(activation_bits-1)
  for (int j = 0; j < L.out; ++j) {
    int64_t acc = fx::saturate(L.bias[size_t(j)], A);
    counters_.saturations += acc != L.bias[size_t(j)];
    const int8_t* w = &L.w[size_t(j) * size_t(L.in)];
    if (std::abs(acc) + L.abs_weight_sum[size_t(j)] * x_max <= acc_max) {
      // No partial sum can reach the accumulator's limits: saturating after
      // each addition would change nothing.
      int64_t sum = 0;
      for (int i = 0; i < main_in; ++i) sum += int32_t(w[i]) * x[i];
      acc += sum;
    } else {
      for (int i = 0; i < main_in; ++i) {
        const int64_t sum = acc + int64_t(w[i]) * x[i];
        acc = fx::saturate(sum, A);
        counters_.saturations += acc != sum;
      }
    }
    if (split >= 0) {
      // The direction products in an accumulator of their own (at most
      // in * 2^14 in magnitude), then to accumulator units.
      int64_t part = 0;
      for (int i = split; i < L.in; ++i) part += int32_t(w[i]) * x[i];
      const int64_t p = fx::saturate(part, A);
      counters_.saturations += p != part;
      const int64_t sum = acc + fx::requantize(p, *split_q, n_.rounding);
      acc = fx::saturate(sum, A);
      counters_.saturations += acc != sum;
    }
    counters_.macs += uint64_t(L.in);
    const int64_t v = hidden ? std::max<int64_t>(acc, 0) : acc;
    const int64_t r = fx::requantize(v, L.requant[size_t(j)], n_.rounding);
    y[j] = int32_t(fx::saturate(r, out_bits));
    counters_.saturations += y[j] != r;
  }
}

TmeOutput Tme::eval(const int32_t* feature, const std::vector<int32_t>& dir_code) {
  if (current_ < 0) throw std::logic_error("TME eval: no MLP loaded");
  const TmeMlp& m = mlps_[size_t(current_)];
  const int act = n_.activation_bits, outb = n_.mlp_output_bits;
  int32_t a[kMaxLayerWidth], b[kMaxLayerWidth];
  auto in_stage = [&](int64_t v, const fx::Requant& q) {
    const int64_t r = fx::requantize(v, q, n_.rounding);
    const int64_t s = fx::saturate(r, act);
    counters_.saturations += s != r;
    return int32_t(s);
  };
  const int F = model_.feature_channels;
  for (int c = 0; c < F; ++c) a[c] = in_stage(feature[c], m.feature_in[size_t(c)]);
  int32_t* x = a;
  int32_t* y = b;
  for (size_t l = 0; l < m.density.size(); ++l) {
    const bool hidden = l + 1 < m.density.size();
    layer(m.density[l], x, y, hidden, hidden ? act : outb);
    std::swap(x, y);
  }
  TmeOutput out;
  out.raw_density = x[0];
  out.alpha = alpha_lut_(out.raw_density);
  // Colour net input: density outputs, then the direction encoding.
  const int G = m.density.back().out;
  for (int g = 0; g < G; ++g) y[g] = in_stage(x[g], m.geo_in);
  for (size_t i = 0; i < dir_code.size(); ++i) y[size_t(G) + i] = in_stage(dir_code[i], dir_code_);
  std::swap(x, y);
  for (size_t l = 0; l < m.color.size(); ++l) {
    const bool hidden = l + 1 < m.color.size();
    layer(m.color[l], x, y, hidden, hidden ? act : outb, l == 0 ? G : -1, &m.dir_in);
    std::swap(x, y);
  }
  for (int c = 0; c < 3; ++c) out.rgb[size_t(c)] = sigmoid_lut_(x[c]);
  ++counters_.samples;
  return out;
}

}  // namespace edrnr::chip
