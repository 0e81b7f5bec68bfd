// Float lanes to int32 lanes for the fast renderer's kernels, without the
// fix-up of out-of-range lanes that Highway's conversions add on x86: the
// callers' values fit int32 (or their lanes are masked afterwards). Included
// once per SIMD target by the kernels' .cpp files and -inl.h headers.
#if defined(EDRNR_RENDER_FAST_CONVERT_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef EDRNR_RENDER_FAST_CONVERT_INL_H_
#undef EDRNR_RENDER_FAST_CONVERT_INL_H_
#else
#define EDRNR_RENDER_FAST_CONVERT_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// The lanes of v as int32: truncated toward zero (kTruncate), or rounded
// to nearest even. One conversion on x86 (the discarded branches are not
// instantiated for vectors of other widths).
template <bool kTruncate, class DI, class VF>
HWY_INLINE hn::Vec<DI> ToInt32(DI di, VF v) {
#if HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  hn::Vec<DI> r = hn::Zero(di);
  if constexpr (sizeof(v.raw) == 64)
    r.raw = kTruncate ? _mm512_cvttps_epi32(v.raw) : _mm512_cvtps_epi32(v.raw);
  else if constexpr (sizeof(v.raw) == 32)
    r.raw = kTruncate ? _mm256_cvttps_epi32(v.raw) : _mm256_cvtps_epi32(v.raw);
  else
    r.raw = kTruncate ? _mm_cvttps_epi32(v.raw) : _mm_cvtps_epi32(v.raw);
  return r;
#else
  if constexpr (kTruncate)
    return hn::ConvertTo(di, v);
  else
    return hn::NearestInt(v);
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#endif  // EDRNR_RENDER_FAST_CONVERT_INL_H_
