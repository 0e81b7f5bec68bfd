#pragma once
// FTU, the fine traversal unit (paper Sections III-A, IV-A): fine, leaf and
// micro traversal of a clustered RP (CCRP) inside its coarse voxel (CV), and
// sample generation.
//
// The rays taking part are the live rays of the RP whose current candidate
// lies in the CV. Each fine iteration the LFAU picks the lagging fine voxel
// among them and the FTU reads its bit in the fine bitmap:
//   - empty: the selected rays jump past it (exact);
//   - occupied: the FTU reads the fine voxel's 64 micro bits once (one word
//     of the micro-grid bitmap) and derives the leaf bits from that word.
//     Each selected ray walks its candidates through the fine voxel: an empty
//     leaf voxel is jumped over, and in an occupied leaf each candidate whose
//     micro voxel is occupied is a sample. The selected rays end up past the
//     fine voxel.
// run() iterates until one fine voxel yields samples (a CCRP with sample
// positions, CCRP_SP, for the OoO-SI) or no ray is left in the CV.
#include <cstdint>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/lru_tags.h"
#include "chip/rp_buffer.h"
#include "model/scene_model.h"

namespace edrnr::chip {

struct SampleRef {
  uint8_t ray = 0;  // ray of the packet
  int64_t k = 0;    // candidate index
};

// CCRP_SP: the samples of one RP in one fine voxel, by ray, then k ascending.
struct SampleBatch {
  uint32_t rp = 0;
  uint32_t cv_tag = 0;
  uint32_t fine_index = 0;  // linear fine voxel index
  int32_t block = -1;       // its feature block
  uint8_t ray_mask = 0;     // rays that marched through the fine voxel
  std::vector<SampleRef> samples;
};

struct FtuCounters {
  uint64_t iterations = 0;     // LFAU selections, one fine bitmap check each
  uint64_t rays_advanced = 0;  // sum over iterations of the rays selected
  uint64_t fine_checks = 0;
  uint64_t micro_word_reads = 0;  // 64-bit micro-grid words read (one per occupied fine voxel visit)
  uint64_t micro_word_hits = 0;   // of those, hits in the micro-grid bitmap cache
  uint64_t leaf_checks = 0;
  uint64_t micro_checks = 0;
  uint64_t candidate_tests = 0;  // candidates of occupied leaves tested against their micro bit
  uint64_t samples = 0;
  uint64_t batches = 0;
  uint64_t position_evals = 0;

  // Adds another instance's counts (runs split over two FTU models).
  FtuCounters& operator+=(const FtuCounters& o) {
    each(o, [](uint64_t& a, uint64_t b) { a += b; });
    return *this;
  }
  // The counts since an earlier reading `o` of the same instance.
  FtuCounters& operator-=(const FtuCounters& o) {
    each(o, [](uint64_t& a, uint64_t b) { a -= b; });
    return *this;
  }

 private:
  // f(this counter, o's counter) for every counter.
  template <class F>
  void each(const FtuCounters& o, F f) {
    f(iterations, o.iterations);
    f(rays_advanced, o.rays_advanced);
    f(fine_checks, o.fine_checks);
    f(micro_word_reads, o.micro_word_reads);
    f(micro_word_hits, o.micro_word_hits);
    f(leaf_checks, o.leaf_checks);
    f(micro_checks, o.micro_checks);
    f(candidate_tests, o.candidate_tests);
    f(samples, o.samples);
    f(batches, o.batches);
    f(position_evals, o.position_evals);
  }
};
static_assert(sizeof(FtuCounters) == 11 * sizeof(uint64_t), "FtuCounters::each must visit every counter");

class Ftu {
 public:
  // micro_grid_cache_words: capacity of the micro-grid bitmap cache in 64-bit
  // words (one fine voxel each), LRU. Throws Error if an occupied fine voxel
  // has no feature block.
  Ftu(const SceneModel& model, const RayMath& math, bool lag_first, size_t micro_grid_cache_words = 0);

  // Marches rp's rays inside CV `cv_tag` to the next fine voxel holding
  // samples. Returns true with `batch` filled; false when no live ray is left
  // in the CV (the RP leaves it: a CV transition).
  bool run(RayPacket& rp, uint32_t rp_pointer, uint32_t cv_tag, SampleBatch& batch);

  // When `log` is set, run() appends the linear index of every fine voxel
  // whose micro-grid word it reads, in order (for a timing shell that models
  // the micro-grid cache); nullptr stops it. The log is never cleared here.
  void set_micro_read_log(std::vector<uint32_t>* log) { micro_read_log_ = log; }

  // The 64 micro bits of a fine voxel, bit lx + 4 (ly + 4 lz).
  uint64_t micro_word(uint32_t fine_index) const;
  const FtuCounters& counters() const { return counters_; }

 private:
  // micro_word from the micro bitmap, row by row.
  uint64_t gather_micro_word(uint32_t fine_index) const;

  const SceneModel& model_;
  const RayMath& math_;
  std::vector<uint64_t> block_words_;  // micro_word of each block's fine voxel
  bool lag_first_;
  LruTags micro_grid_cache_;
  std::vector<uint32_t>* micro_read_log_ = nullptr;
  FtuCounters counters_;
};

}  // namespace edrnr::chip
