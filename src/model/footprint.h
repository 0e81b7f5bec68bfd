#pragma once
// DRAM footprint of a scene model, by data type, as the chip stores it.
#include <cstddef>

#include "model/scene_model.h"

namespace edrnr {

struct DramFootprint {
  size_t coarse_bitmap_bytes = 0;  // dense coarse bitmap: ceil(coarse_res^3 / 8)
  size_t fine_bitmap_bytes = 0;    // dense fine bitmap: ceil(fine_res^3 / 8)
  size_t micro_grid_bytes = 0;     // 8 bytes (4^3 micro bits) per occupied fine voxel
  size_t feature_bytes = 0;        // INT4 blocks: ceil(125 * F / 2) bytes per block
  size_t mlp_weight_bytes = 0;     // MlpArch::q8_bytes() per MLP
  size_t total_bytes() const {
    return coarse_bitmap_bytes + fine_bitmap_bytes + micro_grid_bytes + feature_bytes + mlp_weight_bytes;
  }
};

// Bytes per INT4 feature block of F channels: 125 vertices x F nibbles, rounded up to whole bytes.
size_t feature_block_q4_bytes(int feature_channels);

// The footprint of `model` (micro_res and occupancy set; the counts come from
// the fine occupancy, block_fine_index and mlp_coarse_index).
DramFootprint dram_footprint(const SceneModel& model);

}  // namespace edrnr
