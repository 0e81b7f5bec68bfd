#include "chip/tme.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "chip/tme_kernel.h"
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

// A multiplier and shift the 64-bit kernels take (tme_kernel.h).
bool kernel_requant(const fx::Requant& q) {
  return q.multiplier >= 0 && q.multiplier == int32_t(q.multiplier) && q.shift >= 0 && q.shift <= 62;
}

TmeRequantRow requant_row(const std::vector<fx::Requant>& qs, const ChipNumerics& n) {
  TmeRequantRow row;
  row.vector = n.rounding == fx::Rounding::Floor || n.rounding == fx::Rounding::HalfUp;
  for (const fx::Requant& q : qs) row.vector = row.vector && kernel_requant(q);
  if (!row.vector) return row;
  row.bias.assign(qs.size(), 0);
  for (const fx::Requant& q : qs) {
    row.mult.push_back(uint32_t(q.multiplier));
    row.shift.push_back(uint64_t(q.shift));
    row.half.push_back(n.rounding == fx::Rounding::HalfUp ? (uint64_t(1) << q.shift) >> 1 : 0);
  }
  return row;
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
    const size_t pad = tme_lane_pad();
    t.out_pad = int((size_t(t.out) + pad - 1) / pad * pad);
    t.wt.assign(size_t(t.in) * size_t(t.out_pad), 0);
    for (int j = 0; j < t.out; ++j)
      for (int i = 0; i < t.in; ++i)
        t.wt[size_t(i) * size_t(t.out_pad) + size_t(j)] = t.w[size_t(j) * size_t(t.in) + size_t(i)];
    if (n.activation_bits <= 16)  // every input fits int16
      t.wt_pairs = tme_pair_weights(t.wt.data(), size_t(t.in), size_t(t.out_pad));
    const int A = n.accumulator_bits;
    const int64_t x_max = int64_t(1) << (n.activation_bits - 1);  // |x| <= 2^(activation_bits-1)
    t.bias_sat.resize(size_t(d.out));
    t.sum_exact.resize(size_t(d.out));
    for (int j = 0; j < t.out; ++j) {
      const int64_t b = fx::saturate(t.bias[size_t(j)], A);
      t.bias_sat[size_t(j)] = b;
      t.bias_saturations += b != t.bias[size_t(j)];
      t.sum_exact[size_t(j)] = std::abs(b) + t.abs_weight_sum[size_t(j)] * x_max <= fx::max_signed(A);
    }
    bool kernel = A <= 32 && (n.rounding == fx::Rounding::Floor || n.rounding == fx::Rounding::HalfUp);
    bool exact = true;
    for (int j = 0; j < t.out; ++j) {
      kernel = kernel && kernel_requant(t.requant[size_t(j)]);
      exact = exact && t.sum_exact[size_t(j)];
    }
    t.requant_kernel = kernel;
    t.requant_vector = kernel && exact && hidden;
    t.requant_signed = kernel && exact && !hidden;
    t.needs_bound = !exact;
    if (!exact) {
      t.wt_abs = t.wt;
      for (int32_t& w : t.wt_abs) w = std::abs(w);
    }
    if (kernel) {
      t.zero32.assign(size_t(t.out_pad), 0);
      t.requant_rounding = n.rounding;
      const size_t P = size_t(t.out_pad);
      t.bias32.assign(P, 0);
      t.mult32.assign(P, 0);
      t.shift64.assign(P, 0);
      t.half64.assign(P, 0);
      for (size_t j = 0; j < size_t(t.out); ++j) {
        t.bias32[j] = int32_t(t.bias_sat[j]);
        t.mult32[j] = uint32_t(t.requant[j].multiplier);
        t.shift64[j] = uint64_t(t.requant[j].shift);
        if (n.rounding == fx::Rounding::HalfUp) t.half64[j] = (uint64_t(1) << t.requant[j].shift) >> 1;
      }
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
  m.feature_row = requant_row(m.feature_in, n);
  m.geo_row = requant_row(std::vector<fx::Requant>(size_t(m.density.back().out), m.geo_in), n);
  return m;
}

std::vector<int32_t> Tme::encode_direction(const Vec3d& dir, int frequencies, const ChipNumerics& n) {
  std::vector<int32_t> out;
  encode_direction(dir, frequencies, n, out);
  return out;
}

namespace {
// Tme::encode_direction with the rounding mode fixed at compile time.
template <fx::Rounding M>
void encode_direction_as(const Vec3d& dir, int frequencies, const ChipNumerics& n, int32_t* code) {
  const int frac_bits = n.direction_code_frac_bits, bits = n.direction_code_bits;
  // Values in [-1, 1] (the direction, sines and cosines) with at most 51
  // fraction bits scale exactly below 2^52: no range checks needed.
  const bool small = frac_bits >= 0 && frac_bits <= fx::kSmallScaleFracBitsMax;
  const double unit = small ? fx::pow2(frac_bits) : 0.0;
  auto put = [&](double v) {
    *code++ = int32_t(small && std::fabs(v) <= 1.0 ? fx::saturate(fx::round_scaled_small<M>(v, unit), bits)
                                                   : fx::to_fixed(v, frac_bits, bits, M));
  };
  for (int a = 0; a < 3; ++a) put(dir[a]);
  // The sines and cosines of every frequency at once (det_sin_cos: the bits of
  // det_sin / det_cos), on the stack for up to 16 frequencies.
  const size_t count = 3 * size_t(std::max(frequencies, 0));
  constexpr size_t kOnStack = 48;
  std::array<double, 3 * kOnStack> stack;
  std::vector<double> heap;
  double* arg = stack.data();
  if (count > kOnStack) {
    heap.resize(3 * count);
    arg = heap.data();
  }
  double* sin_v = arg + count;
  double* cos_v = sin_v + count;
  double scale = 1.0;  // 2^k, exact (doubling a power of two)
  for (int k = 0; k < frequencies; ++k, scale *= 2.0)
    for (int a = 0; a < 3; ++a) arg[3 * k + a] = scale * dir[a];
  det_sin_cos(arg, count, sin_v, cos_v);
  for (int k = 0; k < frequencies; ++k) {
    for (int a = 0; a < 3; ++a) put(sin_v[size_t(3 * k + a)]);
    for (int a = 0; a < 3; ++a) put(cos_v[size_t(3 * k + a)]);
  }
}
}  // namespace

void Tme::encode_direction(const Vec3d& dir, int frequencies, const ChipNumerics& n, std::vector<int32_t>& out) {
  out.resize(3 + 6 * size_t(std::max(frequencies, 0)));
  switch (n.rounding) {
    case fx::Rounding::Floor:
      return encode_direction_as<fx::Rounding::Floor>(dir, frequencies, n, out.data());
    case fx::Rounding::HalfUp:
      return encode_direction_as<fx::Rounding::HalfUp>(dir, frequencies, n, out.data());
    case fx::Rounding::HalfEven:
      return encode_direction_as<fx::Rounding::HalfEven>(dir, frequencies, n, out.data());
  }
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

int32_t Tme::mlp_of(uint32_t cv_tag) const {
  const int32_t m = model_.coarse_to_mlp.at(cv_tag);
  if (m < 0) fail("coarse voxel {} is occupied but has no MLP (the model breaks its invariants)", cv_tag);
  return m;
}

void Tme::load(uint32_t cv_tag) {
  const int32_t m = mlp_of(cv_tag);
  if (m == current_) return;
  current_ = m;
  ++counters_.mlp_loads;
  counters_.mlp_load_bytes += mlps_[size_t(m)].stored_bytes;
}

void Tme::select(int32_t index) {
  if (index < 0 || size_t(index) >= mlps_.size()) throw std::logic_error("TME select: no MLP " + std::to_string(index));
  current_ = index;
}

void Tme::direction_input(const std::vector<int32_t>& dir_code, TmeDirection& out) const {
  out.terms_tme = nullptr;  // the terms were those of other inputs
  out.terms_mlp = -1;
  out.x.resize(dir_code.size());
  const int32_t* c = dir_code.data();
  const size_t n = dir_code.size();
  const int bits = n_.activation_bits;
  switch (n_.rounding) {
    case fx::Rounding::Floor:
      out.saturations = fx::requantize_saturate_row<fx::Rounding::Floor>(c, n, dir_code_, bits, out.x.data());
      return;
    case fx::Rounding::HalfUp:
      out.saturations = fx::requantize_saturate_row<fx::Rounding::HalfUp>(c, n, dir_code_, bits, out.x.data());
      return;
    case fx::Rounding::HalfEven:
      out.saturations = fx::requantize_saturate_row<fx::Rounding::HalfEven>(c, n, dir_code_, bits, out.x.data());
      return;
  }
}

TmeOutput Tme::eval(const int32_t* feature, const std::vector<int32_t>& dir_code) {
  direction_input(dir_code, eval_dir_);
  TmeDirection* d = &eval_dir_;
  TmeOutput out;
  eval_batch(1, feature, &d, &out);
  return out;
}

void Tme::eval_batch(size_t samples, const int32_t* features, TmeDirection* const* dirs, TmeOutput* out) {
  if (current_ < 0) throw std::logic_error("TME eval: no MLP loaded");
  if (samples == 0) return;
  const size_t need = samples * size_t(kMaxLayerWidth);
  if (term_of_sample_.size() < samples) term_of_sample_.resize(samples);
  if (act_a_.size() < need) {
    act_a_.resize(need);
    act_b_.resize(need);
    sum_main_.resize(need);
    abs_x_.resize(need);
    abs_sum_.resize(need);
  }
  switch (n_.rounding) {
    case fx::Rounding::Floor:
      return eval_batch_as<fx::Rounding::Floor>(samples, features, dirs, out);
    case fx::Rounding::HalfUp:
      return eval_batch_as<fx::Rounding::HalfUp>(samples, features, dirs, out);
    case fx::Rounding::HalfEven:
      return eval_batch_as<fx::Rounding::HalfEven>(samples, features, dirs, out);
  }
}

// One layer for every sample of a batch: the products through the GEMM kernel
// (exact in int32, see tme_kernel.h), the saturating accumulation, the
// direction partial sum and the requantization per neuron as the TME does them.
template <fx::Rounding M>
void Tme::layer_batch(const TmeLayer& L, size_t samples, const int32_t* x, int32_t* y, bool hidden, int out_bits,
                      int split, const TmeDirTerms* const* dir_terms) {
  const int A = n_.accumulator_bits;
  const size_t W = kMaxLayerWidth;
  const int main_in = split >= 0 ? split : L.in;
  if (!L.wt_pairs.empty())
    tme_dot_columns_pairs(L.wt_pairs.data(), L.wt.data(), size_t(L.out_pad), size_t(main_in), x, W, samples,
                          sum_main_.data(), W);
  else
    tme_dot_columns(L.wt.data(), size_t(L.out_pad), 0, size_t(main_in), x, W, samples, sum_main_.data(), W);
  uint64_t saturations = L.bias_saturations * samples;
  if (hidden && split < 0 && L.requant_vector && L.requant_rounding == M) {
    // Every sum is exact and every requantization fits 64 bits: the same
    // values as the loop below, several neurons at a time.
    saturations += tme_requant_relu(sum_main_.data(), W, samples, L.bias32.data(), L.mult32.data(), L.half64.data(),
                                    L.shift64.data(), size_t(L.out_pad), out_bits, y, W);
    counters_.macs += uint64_t(L.in) * uint64_t(L.out) * samples;
    counters_.saturations += saturations;
    return;
  }
  if (!hidden && split < 0 && L.requant_signed && L.requant_rounding == M) {
    // An output layer with exact sums: bias, requantization and saturation
    // as the loop below does them, several neurons at a time.
    saturations += tme_requant_signed(sum_main_.data(), W, samples, size_t(L.out), L.bias32.data(), L.mult32.data(),
                                      L.half64.data(), L.shift64.data(), out_bits, y, W);
    counters_.macs += uint64_t(L.in) * uint64_t(L.out) * samples;
    counters_.saturations += saturations;
    return;
  }
  // The bound |bias| + sum |w| |x| of every partial sum of each neuron and
  // sample, when the weights alone do not rule saturation out.
  const bool bound = L.needs_bound;
  if (bound) {
    for (size_t s = 0; s < samples; ++s)
      for (int i = 0; i < main_in; ++i) abs_x_[s * W + size_t(i)] = std::abs(x[s * W + size_t(i)]);
    tme_dot_columns(L.wt_abs.data(), size_t(L.out_pad), 0, size_t(main_in), abs_x_.data(), W, samples, abs_sum_.data(),
                    W);
  }
  const int64_t acc_max = fx::max_signed(A);
  // The requantization in the kernels once the accumulators are formed (they
  // go into sum_main_, in place).
  const bool kernel = L.requant_kernel && L.requant_rounding == M;
  // Exact sums plus direction terms, requantized in the kernels: the loop
  // below's sums and saturations, several neurons at a time.
  const bool add_terms = split >= 0 && kernel && !bound && A <= 32;
  if (add_terms) {
    if (term_rows_.size() < samples) term_rows_.resize(samples);
    for (size_t s = 0; s < samples; ++s) {
      saturations += dir_terms[s]->saturations;
      term_rows_[s] = dir_terms[s]->term.data();
    }
    saturations += tme_add_terms(sum_main_.data(), W, samples, size_t(L.out), L.bias_sat.data(), term_rows_.data(), A);
  }
  for (size_t s = 0; s < samples && !add_terms; ++s) {
    const int32_t* xs = x + s * W;
    int32_t* main_sum = &sum_main_[s * W];
    const TmeDirTerms* dir = split >= 0 ? dir_terms[s] : nullptr;
    if (dir) saturations += dir->saturations;
    const int32_t* abs_sum = &abs_sum_[s * W];
    int32_t* ys = y + s * W;
    for (int j = 0; j < L.out; ++j) {
      int64_t acc = L.bias_sat[size_t(j)];
      if (L.sum_exact[size_t(j)] || (bound && std::abs(acc) + abs_sum[j] <= acc_max)) {
        // No partial sum can reach the accumulator's limits: saturating after
        // each addition would change nothing.
        acc += main_sum[j];
      } else {
        const int8_t* w = &L.w[size_t(j) * size_t(L.in)];
        for (int i = 0; i < main_in; ++i) {
          const int64_t sum = acc + int64_t(w[i]) * xs[i];
          acc = fx::saturate(sum, A);
          saturations += acc != sum;
        }
      }
      if (dir) {
        // The direction term (direction_terms()).
        const int64_t sum = acc + dir->term[size_t(j)];
        acc = fx::saturate(sum, A);
        saturations += acc != sum;
      }
      if (kernel) {
        main_sum[j] = int32_t(acc);  // |acc| < 2^31: the accumulator has at most 32 bits
        continue;
      }
      const int64_t v = hidden ? std::max<int64_t>(acc, 0) : acc;
      const int64_t r = fx::requantize<M>(v, L.requant[size_t(j)]);
      const int64_t o = fx::saturate(r, out_bits);
      ys[j] = int32_t(o);
      saturations += o != r;
    }
  }
  if (kernel) {
    // The ReLU (hidden), requantization and saturation the loop above leaves,
    // several neurons at a time.
    if (hidden)
      saturations += tme_requant_relu(sum_main_.data(), W, samples, L.zero32.data(), L.mult32.data(), L.half64.data(),
                                      L.shift64.data(), size_t(L.out_pad), out_bits, y, W);
    else
      saturations += tme_requant_signed(sum_main_.data(), W, samples, size_t(L.out), L.zero32.data(), L.mult32.data(),
                                        L.half64.data(), L.shift64.data(), out_bits, y, W);
  }
  counters_.macs += uint64_t(L.in) * uint64_t(L.out) * samples;
  counters_.saturations += saturations;
}

template <fx::Rounding M>
void Tme::direction_terms(const TmeLayer& L, int split, const fx::Requant& q, const TmeDirection& d, TmeDirTerms& t) {
  const size_t W = kMaxLayerWidth;
  // The kernel reads x[split, L.in) and writes sum[0, L.out_pad); the bound
  // scratch is free here (layer_batch() fills it again).
  int32_t* x = abs_x_.data();
  int32_t* sum = abs_sum_.data();
  std::copy(d.x.begin(), d.x.end(), x + split);
  tme_dot_columns(L.wt.data(), size_t(L.out_pad), size_t(split), size_t(L.in), x, W, 1, sum, W);
  t.term.resize(size_t(L.out));
  t.saturations = fx::saturate_requantize_row<M>(sum, size_t(L.out), n_.accumulator_bits, q, t.term.data());
}

template <fx::Rounding M>
void Tme::eval_batch_as(size_t samples, const int32_t* features, TmeDirection* const* dirs, TmeOutput* out) {
  const TmeMlp& m = mlps_[size_t(current_)];
  const int act = n_.activation_bits, outb = n_.mlp_output_bits;
  const size_t W = kMaxLayerWidth;
  uint64_t saturations = 0;
  auto in_stage = [&](int64_t v, const fx::Requant& q) {
    const int64_t r = fx::requantize<M>(v, q);
    const int64_t s = fx::saturate(r, act);
    saturations += s != r;
    return int32_t(s);
  };
  const int F = model_.feature_channels;
  int32_t* x = act_a_.data();
  int32_t* y = act_b_.data();
  const bool row_kernels = n_.rounding == M;  // the rows were made for the current rounding
  if (row_kernels && m.feature_row.vector) {
    saturations +=
        tme_requant_signed(features, size_t(F), samples, size_t(F), m.feature_row.bias.data(),
                           m.feature_row.mult.data(), m.feature_row.half.data(), m.feature_row.shift.data(), act, x, W);
  } else {
    for (size_t s = 0; s < samples; ++s)
      for (int c = 0; c < F; ++c)
        x[s * W + size_t(c)] = in_stage(features[s * size_t(F) + size_t(c)], m.feature_in[size_t(c)]);
  }
  for (size_t l = 0; l < m.density.size(); ++l) {
    const bool hidden = l + 1 < m.density.size();
    layer_batch<M>(m.density[l], samples, x, y, hidden, hidden ? act : outb, -1, nullptr);
    std::swap(x, y);
  }
  // Colour net input: density outputs, then the direction encoding.
  const int G = m.density.back().out;
  const bool geo_kernel = row_kernels && m.geo_row.vector;
  if (geo_kernel)
    saturations += tme_requant_signed(x, W, samples, size_t(G), m.geo_row.bias.data(), m.geo_row.mult.data(),
                                      m.geo_row.half.data(), m.geo_row.shift.data(), act, y, W);
  for (size_t s = 0; s < samples; ++s) {
    out[s].raw_density = x[s * W];
    out[s].alpha = alpha_lut_(out[s].raw_density);
    if (!geo_kernel)
      for (int g = 0; g < G; ++g) y[s * W + size_t(g)] = in_stage(x[s * W + size_t(g)], m.geo_in);
    TmeDirection* d = dirs[s];
    saturations += d->saturations;
    if (m.color.empty()) continue;
    // The ray's direction terms: kept from its earlier samples in this MLP,
    // or made now.
    if (d->terms_tme != this || d->terms_mlp != current_) {
      direction_terms<M>(m.color.front(), G, m.dir_in, *d, d->terms);
      d->terms_tme = this;
      d->terms_mlp = current_;
    }
    term_of_sample_[s] = &d->terms;
  }
  std::swap(x, y);
  for (size_t l = 0; l < m.color.size(); ++l) {
    const bool hidden = l + 1 < m.color.size();
    layer_batch<M>(m.color[l], samples, x, y, hidden, hidden ? act : outb, l == 0 ? G : -1, term_of_sample_.data());
    std::swap(x, y);
  }
  for (size_t s = 0; s < samples; ++s)
    for (int c = 0; c < 3; ++c) out[s].rgb[size_t(c)] = sigmoid_lut_(x[s * W + size_t(c)]);
  counters_.samples += samples;
  counters_.saturations += saturations;
}

}  // namespace edrnr::chip
