#include "model/footprint.h"

namespace edrnr {

namespace {
constexpr size_t kMicroGridBytesPerFine = 8;  // 4^3 = 64 micro bits

size_t bitmap_bytes(int res) { return (size_t(res) * size_t(res) * size_t(res) + 7) / 8; }
}  // namespace

size_t feature_block_q4_bytes(int feature_channels) { return (size_t(kBlockVerts) * size_t(feature_channels) + 1) / 2; }

DramFootprint dram_footprint(const SceneModel& model) {
  DramFootprint f;
  f.coarse_bitmap_bytes = bitmap_bytes(model.coarse_res());
  f.fine_bitmap_bytes = bitmap_bytes(model.fine_res());
  f.micro_grid_bytes = kMicroGridBytesPerFine * model.occupancy[int(Tier::Fine)].count();
  f.feature_bytes = model.block_count() * feature_block_q4_bytes(model.feature_channels);
  f.mlp_weight_bytes = model.mlp_count() * model.mlp_arch.q8_bytes();
  return f;
}

}  // namespace edrnr
