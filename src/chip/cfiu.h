#pragma once
// CFIU, the conflict-free interpolation unit (paper Sections III-C, IV-F,
// Fig. 15).
//
// Holds the feature cache (lines, MSHR, reservation monitor, bank layout; see
// feature_cache.h) and interpolates a sample's feature from the 8 corners of
// its micro voxel. The corners are read from the banks the layout assigns
// them (8 different banks: one cycle); the trilinear coefficients are
// reordered into bank order to meet them.
//
// Numerics (ChipNumerics): per axis the SCC gives the fraction f with
// fb = interp_fraction_bits bits; a corner's coefficient is the product of
// f or (1 - f) over the axes, exact in 3 fb fraction bits (they sum to one).
// The interpolated feature of channel c is
//   round(sum_corners coef * (code - zero_point[c]))
// rounded once to interp_feature_frac_bits and saturated to
// interp_feature_bits: a feature in feature-code steps. The sum is exact, so
// bank order, and so the bank mapping, never changes the result.
#include <array>
#include <cstdint>
#include <vector>

#include "chip/feature_cache.h"
#include "chip/numerics.h"
#include "chip/oo_si.h"
#include "model/scene_model.h"

namespace edrnr::chip {

struct CfiuCounters {
  uint64_t samples = 0;
  uint64_t corner_reads = 0;     // vertex vectors read from the banks
  uint64_t fetch_cycles = 0;     // bank access cycles: 1 per sample without conflicts
  uint64_t conflict_cycles = 0;  // extra cycles from two corners in one bank
  std::array<uint64_t, kFeatureBanks> bank_reads{};
};

class Cfiu {
 public:
  // Throws Error if the model has no INT4 features.
  Cfiu(const SceneModel& model, const ChipNumerics& numerics, const FeatureCacheConfig& cache);

  FeatureCache& cache() { return cache_; }
  const FeatureCache& cache() const { return cache_; }

  // Writes F interpolated features of a sample in `block`, whose line must be
  // valid and reserved (CacheAccess and fill before; see FeatureCache).
  // The same as read_corners() followed by weighted_sum().
  void interpolate(uint32_t block, const SampleCoord& s, int32_t* out);

  // The bank side of interpolate(): reads the 8 corners of the sample at
  // micro voxel `local` of its fine voxel from the line of `block` (which
  // becomes most recently used) and counts the bank reads. Returns the extra
  // cycles its bank conflicts cost.
  int read_corners(uint32_t block, const Vec3i& local);
  // Whether read_corners() can find bank conflicts (it ignores `local` when not).
  bool corners_can_conflict() const { return !cache_.layout().corners_one_per_bank(); }
  // The arithmetic side of interpolate(): the F features of the sample from
  // the model's codes of `block`. Reads only the model and the numerics, so it
  // may run on another thread while the cache changes. The sum is exact, so
  // its order (here corner order; bank order in the hardware) cannot change it.
  void weighted_sum(uint32_t block, const SampleCoord& s, int32_t* out) const;

  int feature_channels() const { return channels_; }
  const CfiuCounters& counters() const { return counters_; }

 private:
  const SceneModel& model_;
  ChipNumerics numerics_;
  FeatureCache cache_;
  int channels_;
  std::vector<int64_t> zero_point_sum_;  // per channel: zero_point * 2^(3 interp_fraction_bits)
  // The whole interpolation in the SIMD kernel (cfiu_corner_features), in
  // int32 (see the constructor); the zero-point terms of the even and odd
  // channels, and the rounding's half.
  bool finish_in_int32_ = false;
  std::vector<int32_t> zero_even_, zero_odd_;
  int32_t finish_half_ = 0;
  CfiuCounters counters_;
};

}  // namespace edrnr::chip
