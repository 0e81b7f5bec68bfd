#pragma once
// LFAU, the lag-first aggregate unit (paper Sections III-B and IV-C, Fig. 12).
//
// Rays of one ray packet (RP) may sit in different voxels (ray divergence).
// Each traversal iteration of the CTU (coarse voxels) or the FTU (fine voxels)
// advances only the rays of one voxel; the LFAU picks that voxel. Lag first:
// the voxel indices of the active rays are compared along X, then Y, then Z,
// each axis oriented along the packet's travel direction (travel_sign), and
// the most lagging voxel wins: EN1 keeps the rays with the smallest oriented X,
// EN2 those of them with the smallest oriented Y, EN3 those with the smallest
// oriented Z. Every active ray in the winning voxel (the selected tag) is
// selected, so rays in one voxel always advance together.
//
// With lag first switched off, the voxel of the lowest-numbered active ray is
// selected instead (and again every active ray in that voxel).
#include <array>
#include <cstdint>

#include "chip/zorg.h"
#include "core/vec.h"

namespace edrnr::chip {

struct LfauSelection {
  uint8_t selected_mask = 0;  // rays that advance this iteration (0 when no ray is active)
  Vec3i voxel;                // their common voxel (the selected tag)
  int selected_rays() const;  // popcount of selected_mask
};

// Picks the rays to advance. voxel[r] is ray r's current voxel at the tier
// being traversed; only rays with their bit set in active_mask take part.
// travel_sign holds +1 or -1 per axis.
LfauSelection lfau_select(const std::array<Vec3i, kRaysPerPacket>& voxel, uint8_t active_mask, const Vec3i& travel_sign,
                          bool lag_first);

}  // namespace edrnr::chip
