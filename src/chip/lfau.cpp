#include "chip/lfau.h"

#include <bit>

namespace edrnr::chip {

int LfauSelection::selected_rays() const { return std::popcount(unsigned(selected_mask)); }

LfauSelection lfau_select(const std::array<Vec3i, kRaysPerPacket>& voxel, uint8_t active_mask, const Vec3i& travel_sign,
                          bool lag_first) {
  LfauSelection out;
  if (active_mask == 0) return out;
  uint8_t candidates = active_mask;
  if (lag_first) {
    // EN1, EN2, EN3: keep the rays that lag most along X, then Y, then Z.
    for (int axis = 0; axis < 3; ++axis) {
      int best = 0;
      bool first = true;
      for (int r = 0; r < kRaysPerPacket; ++r) {
        if (!(candidates >> r & 1)) continue;
        int oriented = voxel[r][axis] * travel_sign[axis];
        if (first || oriented < best) best = oriented;
        first = false;
      }
      uint8_t keep = 0;
      for (int r = 0; r < kRaysPerPacket; ++r)
        if ((candidates >> r & 1) && voxel[r][axis] * travel_sign[axis] == best) keep |= uint8_t(1u << r);
      candidates = keep;
    }
  }
  int lead = std::countr_zero(unsigned(candidates));
  out.voxel = voxel[lead];
  for (int r = 0; r < kRaysPerPacket; ++r)
    if ((active_mask >> r & 1) && voxel[r] == out.voxel) out.selected_mask |= uint8_t(1u << r);
  return out;
}

}  // namespace edrnr::chip
