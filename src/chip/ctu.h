#pragma once
// CTU, the coarse traversal unit (paper Sections III-A, IV-A): finds the first
// non-empty coarse voxel (CV) along a ray packet.
//
// Each iteration the LFAU picks the lagging CV among the live rays, the CTU
// reads that CV's bit in the coarse bitmap, and
//   - the CV is occupied: the rays in it form a candidate RP (CRP) tagged with
//     the CV's linear index, for the RP-ROB; the RP stops here;
//   - the CV is empty: each selected ray jumps to its first candidate past the
//     CV (exact, see RayMath::cell_exit); a ray past the traversal box has
//     left it for good.
// The RP is finished when no ray is live.
#include <cstdint>

#include "chip/chip_ray.h"
#include "chip/rp_buffer.h"
#include "model/scene_model.h"

namespace edrnr::chip {

inline constexpr int kCoarseCellMicro = kMicroPerFine * kFinePerCoarse;  // 32 micro voxels per CV edge

struct CtuCounters {
  uint64_t iterations = 0;     // LFAU selections, one coarse bitmap check each
  uint64_t rays_advanced = 0;  // sum over iterations of the rays selected
  uint64_t coarse_checks = 0;
  uint64_t position_evals = 0;  // positions computed to find exits
  uint64_t candidates = 0;      // CRPs produced
};

struct CtuResult {
  bool found = false;    // true: a CRP in CV cv_tag; false: the RP has no live ray left
  uint32_t cv_tag = 0;   // linear CV index
  uint8_t ray_mask = 0;  // the rays in that CV
};

class Ctu {
 public:
  Ctu(const SceneModel& model, const RayMath& math, bool lag_first);

  enum class Step { Found, Advanced, Finished };
  // One iteration (a timing shell calls this once per cycle budget).
  Step step(RayPacket& rp, CtuResult& out);
  // Iterates until Found or Finished.
  CtuResult run(RayPacket& rp);

  const CtuCounters& counters() const { return counters_; }

 private:
  const SceneModel& model_;
  const RayMath& math_;
  bool lag_first_;
  CtuCounters counters_;
};

}  // namespace edrnr::chip
