// Highway kernel of the CFIU, compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "chip/cfiu_kernel.h"

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

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::chip
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::chip {

HWY_EXPORT(CornerSums);

void cfiu_corner_sums(const uint8_t* q4, const size_t* byte_first, const int32_t* coef, size_t bytes, int32_t* even,
                      int32_t* odd) {
  HWY_DYNAMIC_DISPATCH(CornerSums)(q4, byte_first, coef, bytes, even, odd);
}

}  // namespace edrnr::chip
#endif
