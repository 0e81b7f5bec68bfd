#include "chip/lfau.h"

#include <bit>

namespace edrnr::chip {

// The number of set bits of each 4-bit mask: the baseline x86-64 build has
// no popcount instruction (std::popcount is a library call there).
static_assert(kRaysPerPacket <= 4, "selected_rays counts 4-bit masks");
constexpr std::array<uint8_t, 16> kBitsSet{0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

int LfauSelection::selected_rays() const { return kBitsSet[selected_mask & 15u]; }

LfauSelection lfau_select(const std::array<Vec3i, kRaysPerPacket>& voxel, uint8_t active_mask, const Vec3i& travel_sign,
                          bool lag_first) {
  LfauSelection out;
  if (active_mask == 0) return out;
  if (lag_first) {
    // EN1, EN2, EN3 at once: the most lagging voxel is the least of the
    // oriented (X, Y, Z) in lexicographic order, compared as one packed key
    // (21 bits per axis, offset to be non-negative). Equal keys are equal
    // voxels, so the winners are the rays whose key is the least, led by the
    // lowest-numbered of them.
    constexpr int kField = 21;
    constexpr uint32_t kOffset = 1u << (kField - 1);
    std::array<uint64_t, kRaysPerPacket> key{};
    uint64_t best = ~uint64_t(0);
    uint32_t out_of_range = 0;  // a high bit set: some oriented index does not fit its field
    for (int r = 0; r < kRaysPerPacket; ++r) {
      if (!(active_mask >> r & 1)) continue;
      uint64_t k = 0;
      for (int axis = 0; axis < 3; ++axis) {
        const uint32_t field = uint32_t(voxel[size_t(r)][axis] * travel_sign[axis]) + kOffset;
        out_of_range |= field;
        k = k << kField | field;
      }
      key[size_t(r)] = k;
      best = k < best ? k : best;
    }
    if (out_of_range >> kField == 0) {
      for (int r = 0; r < kRaysPerPacket; ++r)
        if ((active_mask >> r & 1) && key[size_t(r)] == best) out.selected_mask |= uint8_t(1u << r);
      out.voxel = voxel[size_t(std::countr_zero(unsigned(out.selected_mask)))];
      return out;
    }
  }
  uint8_t candidates = active_mask;
  if (lag_first) {  // voxel indices too large to pack: axis by axis
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
