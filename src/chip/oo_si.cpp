#include "chip/oo_si.h"

#include <algorithm>
#include <stdexcept>

#include "core/error.h"
#include "model/scene_model.h"

namespace edrnr::chip {

OooSi::OooSi(int depth, bool out_of_order) : depth_(depth), out_of_order_(out_of_order) {
  if (depth < 1) fail("OoO-SI queue depth must be at least 1 (got {})", depth);
}

void OooSi::push(const LsEntry& entry) {
  if (full()) throw std::logic_error("OoO-SI push: the location shifter is full");
  queue_.push_back(entry);
  ++counters_.pushed;
  counters_.peak_occupancy = std::max<uint64_t>(counters_.peak_occupancy, queue_.size());
}

std::optional<int> OooSi::select(const FeatureCache& cache) {
  // A block becomes present only by a fill, and an entry only by a push:
  // with neither since the last empty answer, the answer stays empty.
  if (!known_waiting(cache)) {
    const int n = out_of_order_ ? size() : std::min(size(), 1);
    for (int i = 0; i < n; ++i)
      if (cache.present(queue_[size_t(i)].block)) {
        waiting_ = false;
        return i;
      }
    waiting_ = true;
    waited_fills_ = cache.counters().fills;
    waited_pushes_ = counters_.pushed;
  }
  ++counters_.waits;
  return std::nullopt;
}

LsEntry OooSi::take(int position) {
  if (position < 0 || position >= size()) throw std::logic_error("OoO-SI take: no entry at that position");
  LsEntry e = queue_[size_t(position)];
  queue_.erase(queue_.begin() + position);
  ++counters_.issued;
  if (position > 0) ++counters_.issued_out_of_order;
  return e;
}

namespace {
// The coordinate with each axis's fraction f in [0, 1] brought to fixed point by to_fixed(f).
template <class ToFixed>
SampleCoord coordinate_with(const RayMath& math, const ChipRay& ray, int64_t k, ToFixed to_fixed) {
  const Vec3d p = math.point(ray, k);
  SampleCoord s;
  s.micro = math.micro_voxel(p);
  for (int a = 0; a < 3; ++a) {
    s.local[a] = s.micro[a] % kMicroPerFine;
    const double f = std::clamp(p[a] - double(s.micro[a]), 0.0, 1.0);  // exact: p has few significant bits
    s.frac[size_t(a)] = to_fixed(f);
  }
  return s;
}
}  // namespace

SampleCoord sample_coordinate(const RayMath& math, const ChipRay& ray, int64_t k, int frac_bits,
                              fx::Rounding rounding) {
  // The fraction f is in [0, 1]: f 2^frac_bits is exact and at most
  // 2^frac_bits, which frac_bits + 1 bits hold (nothing saturates).
  if (frac_bits >= 0 && frac_bits <= fx::kSmallScaleFracBitsMax) {
    const double scale = fx::pow2(frac_bits);
    switch (rounding) {
      case fx::Rounding::Floor:
        return coordinate_with(math, ray, k,
                               [scale](double f) { return fx::round_scaled_small<fx::Rounding::Floor>(f, scale); });
      case fx::Rounding::HalfUp:
        return coordinate_with(math, ray, k,
                               [scale](double f) { return fx::round_scaled_small<fx::Rounding::HalfUp>(f, scale); });
      case fx::Rounding::HalfEven:
        return coordinate_with(math, ray, k,
                               [scale](double f) { return fx::round_scaled_small<fx::Rounding::HalfEven>(f, scale); });
    }
  }
  return coordinate_with(math, ray, k,
                         [&](double f) { return fx::to_fixed_unsigned(f, frac_bits, frac_bits + 1, rounding); });
}

}  // namespace edrnr::chip
