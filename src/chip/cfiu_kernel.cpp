// Highway kernel of the CFIU, compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "chip/cfiu_kernel.h"

#include <algorithm>

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "chip/cfiu_kernel.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::chip {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

void CornerSums(const uint8_t* HWY_RESTRICT q4, const size_t* HWY_RESTRICT byte_first, const int32_t* HWY_RESTRICT coef,
                size_t bytes, int32_t* HWY_RESTRICT even, int32_t* HWY_RESTRICT odd) {
  // At most 8 bytes (16 channels) a vector: one vector for the usual 16
  // channels, no wider than needed.
  const hn::CappedTag<int32_t, 8> d;
  const hn::Rebind<uint8_t, decltype(d)> d8;
  const size_t n = hn::Lanes(d);
  const auto low4 = hn::Set(d, 15);
  size_t b = 0;
  for (; b + n <= bytes; b += n) {
    auto acc_even = hn::Zero(d);
    auto acc_odd = hn::Zero(d);
    for (size_t c = 0; c < 8; ++c) {
      const auto v =
          hn::BitCast(d, hn::PromoteTo(hn::RebindToUnsigned<decltype(d)>(), hn::LoadU(d8, q4 + byte_first[c] + b)));
      const auto w = hn::Set(d, coef[c]);
      acc_even = hn::Add(acc_even, hn::Mul(hn::And(v, low4), w));
      acc_odd = hn::Add(acc_odd, hn::Mul(hn::ShiftRight<4>(v), w));
    }
    hn::StoreU(acc_even, d, even + b);
    hn::StoreU(acc_odd, d, odd + b);
  }
  for (; b < bytes; ++b) {
    int32_t e = 0, o = 0;
    for (size_t c = 0; c < 8; ++c) {
      const uint8_t v = q4[byte_first[c] + b];
      e += coef[c] * int32_t(v & 15);
      o += coef[c] * int32_t(v >> 4);
    }
    even[b] = e;
    odd[b] = o;
  }
}

void CornerFeatures(const uint8_t* HWY_RESTRICT q4, const size_t* HWY_RESTRICT byte_first,
                    const int32_t* HWY_RESTRICT coef, size_t bytes, const int32_t* HWY_RESTRICT zero_even,
                    const int32_t* HWY_RESTRICT zero_odd, int32_t half, int shift, int32_t lo, int32_t hi,
                    int32_t* HWY_RESTRICT out) {
  constexpr size_t kMaxBytes = 32;
  HWY_ALIGN int32_t even[kMaxBytes], odd[kMaxBytes];
  CornerSums(q4, byte_first, coef, bytes, even, odd);
  const hn::CappedTag<int32_t, 8> d;
  const size_t n = hn::Lanes(d);
  const auto vhalf = hn::Set(d, half), vlo = hn::Set(d, lo), vhi = hn::Set(d, hi);
  auto finish = [&](auto sum, auto zero) {
    return hn::Min(hn::Max(hn::ShiftRightSame(hn::Add(hn::Sub(sum, zero), vhalf), shift), vlo), vhi);
  };
  size_t b = 0;
  for (; b + n <= bytes; b += n) {
    const auto e = finish(hn::Load(d, even + b), hn::LoadU(d, zero_even + b));
    const auto o = finish(hn::Load(d, odd + b), hn::LoadU(d, zero_odd + b));
    hn::StoreInterleaved2(e, o, d, out + 2 * b);
  }
  for (; b < bytes; ++b) {
    out[2 * b] = std::min(std::max((even[b] - zero_even[b] + half) >> shift, lo), hi);
    out[2 * b + 1] = std::min(std::max((odd[b] - zero_odd[b] + half) >> shift, lo), hi);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::chip
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::chip {

HWY_EXPORT(CornerSums);
HWY_EXPORT(CornerFeatures);

void cfiu_corner_sums(const uint8_t* q4, const size_t* byte_first, const int32_t* coef, size_t bytes, int32_t* even,
                      int32_t* odd) {
  HWY_DYNAMIC_DISPATCH(CornerSums)(q4, byte_first, coef, bytes, even, odd);
}

void cfiu_corner_features(const uint8_t* q4, const size_t* byte_first, const int32_t* coef, size_t bytes,
                          const int32_t* zero_even, const int32_t* zero_odd, int32_t half, int shift, int32_t lo,
                          int32_t hi, int32_t* out) {
  HWY_DYNAMIC_DISPATCH(CornerFeatures)(q4, byte_first, coef, bytes, zero_even, zero_odd, half, shift, lo, hi, out);
}

}  // namespace edrnr::chip
#endif
