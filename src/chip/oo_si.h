#pragma once
// OoO-SI, the out-of-order sample issuer (paper Sections III-B, IV-E, Fig. 14).
//
// CCRP_SPs from the FTU (one RP's samples in one fine voxel, so one feature
// block each) wait in the location shifter (LS): a queue of `depth` entries
// holding each CCRP_SP's control state and the base address of its data in
// the computation SRAM. When an entry is pushed, the CFIU is asked to
// prefetch its block. At issue, the oldest entry whose block is on chip goes
// first (out of order); the entries behind it shift down one place. In order
// (the switch off), only the head may issue, and the pipeline waits while its
// block is being fetched.
//
// The sample coordinate calculator (SCC) turns a sample (ray, k) into what the
// CFIU needs: its micro voxel, its place in the fine voxel's block, and its
// per-axis position inside the micro voxel in fixed point.
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/feature_cache.h"
#include "core/fixed_point.h"

namespace edrnr::chip {

struct LsEntry {
  uint32_t rp = 0;
  uint32_t block = 0;      // feature block (cache tag)
  uint32_t data_base = 0;  // where the CCRP_SP's samples sit in the computation SRAM
};

struct OooCounters {
  uint64_t pushed = 0;
  uint64_t issued = 0;
  uint64_t issued_out_of_order = 0;  // issued from behind the head
  uint64_t waits = 0;                // select() calls that found nothing to issue
  uint64_t peak_occupancy = 0;
};

class OooSi {
 public:
  // Throws Error unless depth >= 1.
  OooSi(int depth, bool out_of_order);

  bool full() const { return int(queue_.size()) >= depth_; }
  bool empty() const { return queue_.empty(); }
  int size() const { return int(queue_.size()); }
  const LsEntry& at(int position) const { return queue_[size_t(position)]; }

  void push(const LsEntry& entry);  // throws std::logic_error when full
  // The queue position to issue next, or nothing (wait for a fill).
  std::optional<int> select(const FeatureCache& cache);
  // True when select() is known to find nothing: it found nothing last time
  // and no fill and no push came since.
  bool known_waiting(const FeatureCache& cache) const {
    return waiting_ && waited_fills_ == cache.counters().fills && waited_pushes_ == counters_.pushed;
  }
  // Counts n select() calls that known_waiting() said find nothing.
  void repeat_waits(uint64_t n) { counters_.waits += n; }
  // Removes the entry at `position`; the younger entries shift down.
  LsEntry take(int position);

  const OooCounters& counters() const { return counters_; }

 private:
  int depth_;
  bool out_of_order_;
  std::vector<LsEntry> queue_;
  OooCounters counters_;
  // The last select() found nothing, at these fill and push counts.
  bool waiting_ = false;
  uint64_t waited_fills_ = 0, waited_pushes_ = 0;
};

// SCC output for one sample.
struct SampleCoord {
  Vec3i micro;                    // micro voxel
  Vec3i local;                    // micro voxel inside its fine voxel, 0..3 per axis
  std::array<int64_t, 3> frac{};  // position inside the micro voxel, frac_bits fraction bits, 0..2^frac_bits
};

// The sample coordinate of candidate k of `ray`; the fraction p - floor(p) is
// exact and rounded once to frac_bits (a fraction that rounds up to 1 is kept
// as 2^frac_bits: the weights are then 0 and 1, as interpolation wants).
SampleCoord sample_coordinate(const RayMath& math, const ChipRay& ray, int64_t k, int frac_bits, fx::Rounding rounding);

}  // namespace edrnr::chip
