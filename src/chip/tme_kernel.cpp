// Highway kernels of the TME, compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "chip/tme_kernel.h"

#include <cstring>
#include <stdexcept>
#include <utility>

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "chip/tme_kernel.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::chip {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

void DotColumns(const int32_t* HWY_RESTRICT wt, size_t out_pad, size_t i_begin, size_t i_end,
                const int32_t* HWY_RESTRICT x, size_t x_stride, size_t samples, int32_t* HWY_RESTRICT y,
                size_t y_stride) {
  const hn::ScalableTag<int32_t> d;
  const size_t n = hn::Lanes(d);
  for (size_t s = 0; s < samples; ++s) {
    const int32_t* xs = x + s * x_stride;
    int32_t* ys = y + s * y_stride;
    for (size_t j = 0; j < out_pad; j += n) {
      auto acc0 = hn::Zero(d);
      auto acc1 = hn::Zero(d);
      size_t i = i_begin;
      for (; i + 2 <= i_end; i += 2) {
        acc0 = hn::Add(acc0, hn::Mul(hn::LoadU(d, wt + i * out_pad + j), hn::Set(d, xs[i])));
        acc1 = hn::Add(acc1, hn::Mul(hn::LoadU(d, wt + (i + 1) * out_pad + j), hn::Set(d, xs[i + 1])));
      }
      if (i < i_end) acc0 = hn::Add(acc0, hn::Mul(hn::LoadU(d, wt + i * out_pad + j), hn::Set(d, xs[i])));
      hn::StoreU(hn::Add(acc0, acc1), d, ys + j);
    }
  }
}

// tme_dot_columns_pairs (tme_kernel.h): two inputs per 32-bit lane, their
// products summed in pairs (ReorderWidenMulAccumulate: one multiply-add of
// 16-bit pairs per lane on x86).
void DotColumnsPairs(const int16_t* HWY_RESTRICT wp, const int32_t* HWY_RESTRICT wt, size_t out_pad, size_t i_end,
                     const int32_t* HWY_RESTRICT x, size_t x_stride, size_t samples, int32_t* HWY_RESTRICT y,
                     size_t y_stride) {
#if HWY_TARGET == HWY_SCALAR
  (void)wp;
  DotColumns(wt, out_pad, 0, i_end, x, x_stride, samples, y, y_stride);
#else
  const hn::ScalableTag<int32_t> d;
  const hn::Repartition<int16_t, decltype(d)> d16;
  const size_t n = hn::Lanes(d);
  const hn::Rebind<int16_t, decltype(d)> dh;
  const size_t pairs = i_end / 2;
  // Two samples at a time, sharing the weight loads. Their inputs 2p and
  // 2p + 1 side by side, each pair read as one 32-bit word.
  HWY_ALIGN int16_t packed[2][2 * kTmeMaxPairs];
  auto pack = [&](const int32_t* xs, int16_t* to) {
    size_t i = 0;
    for (; i + n <= 2 * pairs; i += n) hn::StoreU(hn::DemoteTo(dh, hn::LoadU(d, xs + i)), dh, to + i);
    for (; i < 2 * pairs; ++i) to[i] = int16_t(xs[i]);
  };
  auto pair = [&](int which, size_t p) {
    int32_t v;
    std::memcpy(&v, packed[which] + 2 * p, sizeof v);
    return hn::BitCast(d16, hn::Set(d, v));
  };
  for (size_t s = 0; s < samples; s += 2) {
    const size_t s1 = s + 1 < samples ? s + 1 : s;  // an odd last sample is computed twice
    const int32_t* xa = x + s * x_stride;
    const int32_t* xb = x + s1 * x_stride;
    pack(xa, packed[0]);
    pack(xb, packed[1]);
    for (size_t j = 0; j < out_pad; j += n) {
      auto a0 = hn::Zero(d), a1 = hn::Zero(d), b0 = hn::Zero(d), b1 = hn::Zero(d);
      for (size_t p = 0; p < pairs; ++p) {
        const auto w = hn::LoadU(d16, wp + 2 * (p * out_pad + j));
        a0 = hn::ReorderWidenMulAccumulate(d, w, pair(0, p), a0, a1);
        b0 = hn::ReorderWidenMulAccumulate(d, w, pair(1, p), b0, b1);
      }
      auto sa = hn::RearrangeToOddPlusEven(a0, a1), sb = hn::RearrangeToOddPlusEven(b0, b1);
      if (i_end % 2) {
        const auto w = hn::LoadU(d, wt + (i_end - 1) * out_pad + j);
        sa = hn::Add(sa, hn::Mul(w, hn::Set(d, xa[i_end - 1])));
        sb = hn::Add(sb, hn::Mul(w, hn::Set(d, xb[i_end - 1])));
      }
      hn::StoreU(sb, d, y + s1 * y_stride + j);
      hn::StoreU(sa, d, y + s * y_stride + j);
    }
  }
#endif
}

#if HWY_TARGET != HWY_SCALAR
// The int64 lanes of v, each within the int32 range, as int32 lanes (one
// truncating conversion).
template <class V>
HWY_INLINE auto Int32Of(V v) {
  const hn::DFromV<V> d64;
  const hn::Rebind<int32_t, decltype(d64)> d32h;
  return hn::BitCast(d32h, hn::TruncateTo(hn::Rebind<uint32_t, decltype(d64)>(),
                                          hn::BitCast(hn::RebindToUnsigned<decltype(d64)>(), v)));
}
#endif

// tme_requant_relu (tme_kernel.h); the scalar target computes it lane by lane.
uint64_t RequantRelu(const int32_t* HWY_RESTRICT sum, size_t sum_stride, size_t samples,
                     const int32_t* HWY_RESTRICT bias, const uint32_t* HWY_RESTRICT mult,
                     const uint64_t* HWY_RESTRICT half, const uint64_t* HWY_RESTRICT shift, size_t out_pad,
                     int out_bits, int32_t* HWY_RESTRICT y, size_t y_stride) {
#if HWY_TARGET == HWY_SCALAR
  const uint64_t max_value = (uint64_t(1) << (out_bits - 1)) - 1;
  uint64_t saturations = 0;
  for (size_t s = 0; s < samples; ++s)
    for (size_t j = 0; j < out_pad; ++j) {
      const int64_t v = int64_t(sum[s * sum_stride + j]) + bias[j];
      const uint64_t r = (uint64_t(v > 0 ? v : 0) * mult[j] + half[j]) >> shift[j];
      saturations += r > max_value;
      y[s * y_stride + j] = int32_t(r > max_value ? max_value : r);
    }
  return saturations;
#else
  const hn::ScalableTag<uint64_t> d64;
  const hn::Rebind<int32_t, decltype(d64)> d32h;
  const hn::Rebind<uint32_t, decltype(d64)> du32h;
  const hn::Repartition<uint32_t, decltype(d64)> du32;
  const size_t n = hn::Lanes(d64);
  const auto max_out = hn::Set(d64, (uint64_t(1) << (out_bits - 1)) - 1);
  uint64_t saturations = 0;
  for (size_t s = 0; s < samples; ++s) {
    const int32_t* ss = sum + s * sum_stride;
    int32_t* ys = y + s * y_stride;
    for (size_t j = 0; j < out_pad; j += n) {
      const auto v32 = hn::Max(hn::Add(hn::LoadU(d32h, ss + j), hn::LoadU(d32h, bias + j)), hn::Zero(d32h));
      const auto v64 = hn::PromoteTo(d64, hn::BitCast(du32h, v32));
      const auto m64 = hn::PromoteTo(d64, hn::LoadU(du32h, mult + j));
      const auto p = hn::MulEven(hn::BitCast(du32, v64), hn::BitCast(du32, m64));
      const auto r = hn::Add(p, hn::LoadU(d64, half + j)) >> hn::LoadU(d64, shift + j);
      const auto fits = hn::Eq(hn::ShiftRightSame(r, out_bits - 1), hn::Zero(d64));
      saturations += n - hn::CountTrue(d64, fits);
      hn::StoreU(Int32Of(hn::IfThenElse(fits, r, max_out)), d32h, ys + j);
    }
  }
  return saturations;
#endif
}
// tme_requant_signed (tme_kernel.h). The arithmetic shift is a logical one
// between two complements by the sign (exact for negative values too).
uint64_t RequantSigned(const int32_t* HWY_RESTRICT x, size_t x_stride, size_t samples, size_t count,
                       const int32_t* HWY_RESTRICT bias, const uint32_t* HWY_RESTRICT mult,
                       const uint64_t* HWY_RESTRICT half, const uint64_t* HWY_RESTRICT shift, int out_bits,
                       int32_t* HWY_RESTRICT y, size_t y_stride) {
  const int64_t hi = (int64_t(1) << (out_bits - 1)) - 1, lo = -hi - 1;
  uint64_t saturations = 0;
  size_t vector_end = 0;
#if HWY_TARGET != HWY_SCALAR
  const hn::ScalableTag<int64_t> d64;
  const hn::RebindToUnsigned<decltype(d64)> du64;
  const hn::Rebind<int32_t, decltype(d64)> d32h;
  const hn::Rebind<uint32_t, decltype(d64)> du32h;
  const hn::Repartition<int32_t, decltype(d64)> d32;
  const size_t n = hn::Lanes(d64);
  // A last partial vector runs masked: its other lanes load zeros (and
  // compute zeros), are not stored and not counted.
  vector_end = count;
  const size_t whole = count / n * n;
  const auto hi_v = hn::Set(d64, hi), lo_v = hn::Set(d64, lo);
  // round((v * mult + half) / 2^shift) clamped, from the lanes' operands.
  auto requant = [&](auto v32, auto bias32, auto mult32, auto half64, auto shift64) {
    const auto v = hn::Add(hn::PromoteTo(d64, v32), hn::PromoteTo(d64, bias32));
    const auto m = hn::BitCast(d64, hn::PromoteTo(du64, mult32));
    const auto t = hn::Add(hn::MulEven(hn::BitCast(d32, v), hn::BitCast(d32, m)), hn::BitCast(d64, half64));
    const auto sign = hn::BroadcastSignBit(t);
    const auto r = hn::Xor(hn::BitCast(d64, hn::BitCast(du64, hn::Xor(t, sign)) >> shift64), sign);
    const auto c = hn::Min(hn::Max(r, lo_v), hi_v);
    return std::make_pair(c, hn::Eq(r, c));
  };
  for (size_t s = 0; s < samples; ++s) {
    const int32_t* xs = x + s * x_stride;
    int32_t* ys = y + s * y_stride;
    for (size_t j = 0; j < whole; j += n) {
      const auto [c, kept] = requant(hn::LoadU(d32h, xs + j), hn::LoadU(d32h, bias + j), hn::LoadU(du32h, mult + j),
                                     hn::LoadU(du64, half + j), hn::LoadU(du64, shift + j));
      saturations += n - hn::CountTrue(d64, kept);
      hn::StoreU(Int32Of(c), d32h, ys + j);
    }
    if (whole < count) {
      const size_t j = whole;
      const auto m32 = hn::FirstN(d32h, count - whole);
      const auto m64 = hn::FirstN(du64, count - whole);
      const auto [c, kept] = requant(hn::MaskedLoad(m32, d32h, xs + j), hn::MaskedLoad(m32, d32h, bias + j),
                                     hn::MaskedLoad(hn::RebindMask(du32h, m32), du32h, mult + j),
                                     hn::MaskedLoad(m64, du64, half + j), hn::MaskedLoad(m64, du64, shift + j));
      saturations += hn::CountTrue(d64, hn::AndNot(kept, hn::RebindMask(d64, m64)));
      hn::BlendedStore(Int32Of(c), m32, d32h, ys + j);
    }
  }
#endif
  if (vector_end < count) {
    for (size_t s = 0; s < samples; ++s)
      for (size_t j = vector_end; j < count; ++j) {
        const int64_t v = int64_t(x[s * x_stride + j]) + bias[j];
        const int64_t r = (v * int64_t(mult[j]) + int64_t(half[j])) >> shift[j];
        const int64_t c = r < lo ? lo : (r > hi ? hi : r);
        saturations += c != r;
        y[s * y_stride + j] = int32_t(c);
      }
  }
  return saturations;
}

// tme_add_terms (tme_kernel.h).
uint64_t AddTerms(int32_t* HWY_RESTRICT sum, size_t sum_stride, size_t samples, size_t count,
                  const int64_t* HWY_RESTRICT base, const int64_t* const* HWY_RESTRICT terms, int acc_bits) {
  const int64_t hi = (int64_t(1) << (acc_bits - 1)) - 1, lo = -hi - 1;
  uint64_t saturations = 0;
  size_t vector_end = 0;
#if HWY_TARGET != HWY_SCALAR
  const hn::ScalableTag<int64_t> d64;
  const hn::Rebind<int32_t, decltype(d64)> d32h;
  const size_t n = hn::Lanes(d64);
  vector_end = count / n * n;
  const auto hi_v = hn::Set(d64, hi), lo_v = hn::Set(d64, lo);
  for (size_t s = 0; s < samples; ++s) {
    int32_t* ss = sum + s * sum_stride;
    const int64_t* ts = terms[s];
    for (size_t j = 0; j < vector_end; j += n) {
      const auto v = hn::Add(hn::Add(hn::LoadU(d64, base + j), hn::PromoteTo(d64, hn::LoadU(d32h, ss + j))),
                             hn::LoadU(d64, ts + j));
      const auto c = hn::Min(hn::Max(v, lo_v), hi_v);
      saturations += n - hn::CountTrue(d64, hn::Eq(v, c));
      hn::StoreU(Int32Of(c), d32h, ss + j);
    }
  }
#endif
  if (vector_end < count) {
    for (size_t s = 0; s < samples; ++s)
      for (size_t j = vector_end; j < count; ++j) {
        const int64_t v = base[j] + sum[s * sum_stride + j] + terms[s][j];
        const int64_t c = v < lo ? lo : (v > hi ? hi : v);
        saturations += c != v;
        sum[s * sum_stride + j] = int32_t(c);
      }
  }
  return saturations;
}

const char* TargetName() { return hwy::TargetName(HWY_TARGET); }
size_t LanePad() { return hn::Lanes(hn::ScalableTag<int32_t>()); }

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::chip
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::chip {

HWY_EXPORT(DotColumns);
HWY_EXPORT(DotColumnsPairs);
HWY_EXPORT(RequantRelu);
HWY_EXPORT(RequantSigned);
HWY_EXPORT(AddTerms);
HWY_EXPORT(TargetName);
HWY_EXPORT(LanePad);

void tme_dot_columns(const int32_t* wt, size_t out_pad, size_t i_begin, size_t i_end, const int32_t* x, size_t x_stride,
                     size_t samples, int32_t* y, size_t y_stride) {
  HWY_DYNAMIC_DISPATCH(DotColumns)(wt, out_pad, i_begin, i_end, x, x_stride, samples, y, y_stride);
}

std::vector<int16_t> tme_pair_weights(const int32_t* wt, size_t in, size_t out_pad) {
  std::vector<int16_t> pairs(in / 2 * out_pad * 2);
  for (size_t p = 0; p < in / 2; ++p)
    for (size_t j = 0; j < out_pad; ++j)
      for (size_t h = 0; h < 2; ++h) {
        const int32_t w = wt[(2 * p + h) * out_pad + j];
        if (w < -128 || w > 127) throw std::invalid_argument("tme_pair_weights: a weight outside int8");
        pairs[2 * (p * out_pad + j) + h] = int16_t(w);
      }
  return pairs;
}

void tme_dot_columns_pairs(const int16_t* wt_pairs, const int32_t* wt, size_t out_pad, size_t i_end, const int32_t* x,
                           size_t x_stride, size_t samples, int32_t* y, size_t y_stride) {
  if (i_end / 2 > kTmeMaxPairs) throw std::invalid_argument("tme_dot_columns_pairs: too many inputs");
  HWY_DYNAMIC_DISPATCH(DotColumnsPairs)(wt_pairs, wt, out_pad, i_end, x, x_stride, samples, y, y_stride);
}

uint64_t tme_requant_relu(const int32_t* sum, size_t sum_stride, size_t samples, const int32_t* bias,
                          const uint32_t* mult, const uint64_t* half, const uint64_t* shift, size_t out_pad,
                          int out_bits, int32_t* y, size_t y_stride) {
  return HWY_DYNAMIC_DISPATCH(RequantRelu)(sum, sum_stride, samples, bias, mult, half, shift, out_pad, out_bits, y,
                                           y_stride);
}

uint64_t tme_requant_signed(const int32_t* x, size_t x_stride, size_t samples, size_t count, const int32_t* bias,
                            const uint32_t* mult, const uint64_t* half, const uint64_t* shift, int out_bits, int32_t* y,
                            size_t y_stride) {
  return HWY_DYNAMIC_DISPATCH(RequantSigned)(x, x_stride, samples, count, bias, mult, half, shift, out_bits, y,
                                             y_stride);
}

uint64_t tme_add_terms(int32_t* sum, size_t sum_stride, size_t samples, size_t count, const int64_t* base,
                       const int64_t* const* terms, int acc_bits) {
  return HWY_DYNAMIC_DISPATCH(AddTerms)(sum, sum_stride, samples, count, base, terms, acc_bits);
}

const char* tme_kernel_target() { return HWY_DYNAMIC_DISPATCH(TargetName)(); }

size_t tme_lane_pad() {
  const size_t n = HWY_DYNAMIC_DISPATCH(LanePad)();
  if (n == 0 || n > kTmeLanePad || kTmeLanePad % n != 0)
    throw std::logic_error("tme_lane_pad: the SIMD target's int32 lanes do not divide kTmeLanePad");
  return n;
}

}  // namespace edrnr::chip
#endif
