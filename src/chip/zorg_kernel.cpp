// Highway kernel of ZORG's direction datapath, compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "chip/zorg_kernel.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "chip/zorg_kernel.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::chip {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// FloatFormat::round on lanes whose magnitude is in [min_normal,
// overflow_threshold): the significand rounded to p bits, ties to even, on
// the bit pattern (a carry moves into the exponent). `bad` collects the
// lanes outside that range (NaN included: its comparisons are false).
template <class D>
hn::Vec<D> RoundNormal(D d, hn::Vec<D> x, const LaneRounding& f, hn::Mask<D>& bad) {
  const hn::RebindToUnsigned<D> du;
  const auto ax = hn::Abs(x);
  bad =
      hn::Or(bad, hn::Not(hn::And(hn::Ge(ax, hn::Set(d, f.min_normal)), hn::Lt(ax, hn::Set(d, f.overflow_threshold)))));
  auto b = hn::BitCast(du, ax);
  const uint64_t half_minus_one = (uint64_t(1) << (f.drop_bits - 1)) - 1;
  b = hn::Add(b, hn::Add(hn::Set(du, half_minus_one), hn::And(hn::ShiftRightSame(b, f.drop_bits), hn::Set(du, 1))));
  b = hn::And(b, hn::Set(du, ~((uint64_t(1) << f.drop_bits) - 1)));
  return hn::CopySign(hn::BitCast(d, b), x);
}

bool Directions(const double* HWY_RESTRICT col, const double* HWY_RESTRICT row, const double* HWY_RESTRICT z,
                const double* HWY_RESTRICT dir_scale, const LaneRounding& rf, const LaneRounding& tf,
                double* HWY_RESTRICT world, double* HWY_RESTRICT dir) {
  constexpr size_t kLanes = 4;
  const hn::CappedTag<double, kLanes> d;
  const size_t n = hn::Lanes(d);
  for (size_t l0 = 0; l0 < kLanes; l0 += n) {
    auto bad = hn::FirstN(d, 0);
    hn::Vec<decltype(d)> w[3];
    for (int a = 0; a < 3; ++a) {
      const auto sum =
          RoundNormal(d, hn::Add(hn::LoadU(d, col + a * kLanes + l0), hn::LoadU(d, row + a * kLanes + l0)), rf, bad);
      w[a] = RoundNormal(d, hn::Add(sum, hn::Set(d, z[a])), rf, bad);
    }
    const auto xx = RoundNormal(d, hn::Mul(w[0], w[0]), rf, bad);
    const auto yy = RoundNormal(d, hn::Mul(w[1], w[1]), rf, bad);
    const auto zz = RoundNormal(d, hn::Mul(w[2], w[2]), rf, bad);
    const auto len2 = RoundNormal(d, hn::Add(RoundNormal(d, hn::Add(xx, yy), rf, bad), zz), rf, bad);
    const auto len = RoundNormal(d, hn::Sqrt(len2), rf, bad);
    for (int a = 0; a < 3; ++a) {
      const auto u = RoundNormal(d, hn::Div(w[a], len), rf, bad);
      const auto scaled = RoundNormal(d, hn::Mul(u, hn::Set(d, dir_scale[a])), rf, bad);
      hn::StoreU(u, d, world + a * kLanes + l0);
      hn::StoreU(RoundNormal(d, scaled, tf, bad), d, dir + a * kLanes + l0);
    }
    if (!hn::AllFalse(d, bad)) return false;
  }
  return true;
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::chip
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::chip {

HWY_EXPORT(Directions);

bool zorg_directions(const double* col, const double* row, const double* z, const double* dir_scale,
                     const LaneRounding& rf, const LaneRounding& tf, double* world, double* dir) {
  return HWY_DYNAMIC_DISPATCH(Directions)(col, row, z, dir_scale, rf, tf, world, dir);
}

}  // namespace edrnr::chip
#endif
