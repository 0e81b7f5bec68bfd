#pragma once
// The trainable feature representations and their kernels.
//
// FeaturePyramid (the main phase): L dense grids whose resolutions divide the
// micro resolution Rm, kLevelChannels channels each, concatenated into
// F = 4 L channels. A sample in micro voxel m reads, at every level, the cell
// m >> shift that contains m, so the pyramid restricted to a micro voxel is a
// trilinear function and bakes exactly into the model's 5^3 blocks.
//
// BlockFeatures (the final phases): exactly the model's representation, one
// block of 5^3 vertices x F channels per occupied fine voxel, optionally read
// through INT4 fake quantization (quantization-aware training).
//
// Gradients are scattered by z-slab tasks (GradientSlabs): each grid vertex is
// owned by one slab, and its gradient sums run over samples in a fixed order,
// so results do not depend on the number of threads. Adam updates only the
// vertices a step touched.
#include <cstdint>
#include <vector>

#include "core/vec.h"
#include "model/scene_model.h"
#include "train/adam.h"

namespace edrnr::train {

inline constexpr int kLevelChannels = 4;

// Samples bucketed by z-slab of the micro grid: bucket j holds, in increasing
// order, the samples whose micro voxel z lies in [j * slab_micro, (j+1) * slab_micro).
struct GradientSlabs {
  int slab_micro = 8;
  std::vector<int32_t> begin;    // slabs + 1 offsets into samples
  std::vector<int32_t> samples;  // sample indices, bucket by bucket
  int slabs() const { return int(begin.size()) - 1; }
  // ids: sample ids in increasing order; micro: 3 micro voxel coordinates per sample id.
  void build(int micro_res, int slab_micro_, const std::vector<int32_t>& ids, const std::vector<int16_t>& micro);
};

// Per-vertex optimizer state for a grid of vertices x channels. A vertex is
// "touched" by a step when its gradient turns non-zero; it is then listed
// (in the list of the slab task that owns it) for the Adam step, which zeroes
// the gradient again.
struct LazyAdamArray {
  std::vector<float> grad, m, v;
  std::vector<std::vector<int32_t>> touched_list;  // per slab task
  void resize(size_t vertices, int channels, int slabs);
};

struct PyramidLevel {
  int res = 0;               // cells per axis (vertices: res + 1)
  int shift = 0;             // log2(micro_res / res)
  std::vector<float> value;  // (res+1)^3 x kLevelChannels, vertex index x fastest
  LazyAdamArray adam;
  size_t vertex_index(int x, int y, int z) const {
    size_t n = size_t(res) + 1;
    return size_t(x) + n * (size_t(y) + n * size_t(z));
  }
};

class FeaturePyramid {
 public:
  FeaturePyramid() = default;
  // Throws Error unless every resolution divides micro_res and is at most it.
  // Values start uniform in +-init_scale (deterministic in seed).
  FeaturePyramid(int micro_res, const std::vector<int>& level_res, uint64_t seed, float init_scale);

  int micro_res() const { return micro_res_; }
  int channels() const { return kLevelChannels * int(levels_.size()); }
  // Micro voxels per z-slab: the coarsest level's cell edge, so that a sample
  // touches vertices of its own slab and the next one only.
  int slab_micro() const;
  std::vector<PyramidLevel>& levels() { return levels_; }
  const std::vector<PyramidLevel>& levels() const { return levels_; }

  // Which levels are read and trained: bit l for level l (all by default).
  // An inactive level's channels interpolate to zero and get no gradient.
  void set_active_levels(uint32_t mask) { active_ = mask; }
  bool level_active(size_t l) const { return (active_ >> l) & 1u; }

  // Features at micro position p inside micro voxel m (F values).
  void interpolate(const Vec3f& p, const Vec3i& m, float* out) const;
  // Asks the memory system for the values interpolate(., m) will read (a hint).
  void prefetch(const Vec3i& m) const;
  // Adds the gradient of every sample (d_feat: F values per sample, rows of
  // `pos`/`micro` indexed by sample id) into the levels' Adam gradient arrays
  // and records touched vertices. Parallel over slabs.
  void scatter_gradients(const GradientSlabs& slabs, const std::vector<float>& pos, const std::vector<int16_t>& micro,
                         const std::vector<float>& d_feat);
  // Adam step on touched vertices; clears their gradients.
  void adam_step(const AdamStep& step);
  // Adds weight * dTV/dvalue of the total variation (sum of squared
  // differences between neighbouring vertices) over the touched vertices of
  // the `levels` finest levels to their gradients. Call after scatter_gradients.
  void add_tv_gradient(float weight, int levels = 1);
  // Decoupled smoothing of the touched vertices of the `levels` finest
  // levels: value -= rate * sum over neighbours of (value - neighbour), all
  // from the values before the call (the result does not depend on the
  // thread count). Call between scatter_gradients and adam_step.
  void smooth(float rate, int levels = 1);

 private:
  int micro_res_ = 0;
  std::vector<PyramidLevel> levels_;
  uint32_t active_ = ~0u;
};

// INT4 feature quantization as the model stores it (scene_model.h):
// q = clamp(round(x / scale) + zero_point, 0, 15), value = (q - zero_point) * scale.
struct Int4Channel {
  float scale = 1.f;
  float inv_scale = 1.f;
  int zero_point = 0;
  int quantize(float x) const;
  float dequantize(int q) const { return float(q - zero_point) * scale; }
  float fake(float x) const { return dequantize(quantize(x)); }
};
// The channel's quantizer for values in [lo, hi] (the range is widened to include 0).
Int4Channel int4_channel_for_range(float lo, float hi);
// The quantizer with the least squared error over values[i * stride]
// (i < n, every error_stride-th counted) among the min/max range and the
// ranges between the q and 1 - q quantiles (q = 1e-4 .. 3e-2): outliers
// saturate rather than coarsen every step.
Int4Channel fit_int4_channel(const float* values, size_t n, size_t stride, size_t error_stride = 1);

class BlockFeatures {
 public:
  BlockFeatures() = default;
  // One block per entry of fine_index (ascending linear fine indices), values
  // copied from `values` (blocks x 125 x channels).
  BlockFeatures(int micro_res, int channels, std::vector<uint32_t> fine_index, std::vector<float> values);

  int channels() const { return channels_; }
  size_t block_count() const { return fine_index_.size(); }
  const std::vector<uint32_t>& fine_index() const { return fine_index_; }
  int32_t block_of_fine(uint32_t fine) const { return fine_to_block_[fine]; }
  std::vector<float>& values() { return value_; }
  const std::vector<float>& values() const { return value_; }
  LazyAdamArray& adam() { return adam_; }

  // Quantization-aware reads: when enabled, every read goes through the INT4
  // quantizer of its channel.
  void set_quantization(const std::vector<Int4Channel>& q);
  void clear_quantization() { quant_.clear(); }
  bool quantized() const { return !quant_.empty(); }
  const std::vector<Int4Channel>& quantization() const { return quant_; }
  // Per-channel quantizers fitted to the current values (fit_int4_channel).
  std::vector<Int4Channel> fit_quantization() const;

  // Features at micro position p inside micro voxel m. Returns false (and
  // writes zeros) when the fine voxel has no block.
  bool interpolate(const Vec3f& p, const Vec3i& m, float* out) const;
  void prefetch(const Vec3i& m) const;
  // Same contract as FeaturePyramid::scatter_gradients (straight-through
  // estimator when quantized). Slabs must be one fine voxel (4 micro) high.
  void scatter_gradients(const GradientSlabs& slabs, const std::vector<float>& pos, const std::vector<int16_t>& micro,
                         const std::vector<float>& d_feat);
  // Adds weight * dTV/dvalue to the gradient of every touched vertex: squared
  // differences to its neighbours in its block, and to its own copies in the
  // face-adjacent blocks (a vertex on a block face is stored once per block;
  // this keeps the copies together). Call after scatter_gradients.
  void add_tv_gradient(float weight);
  // FeaturePyramid::smooth over the touched vertices with add_tv_gradient's
  // neighbours (in the block, and the vertex's copies across block faces).
  void smooth(float rate);
  void adam_step(const AdamStep& step);

 private:
  // The vertices (block * 125 + id in the block) of micro voxel m's 8
  // corners, dx fastest; false when m's fine voxel has no block.
  bool corner_vertices(const Vec3i& m, int32_t vtx[8]) const;
  // Calls pull(u) with the values of each of vertex vtx's TV neighbours.
  template <class Pull>
  void for_each_neighbour(int32_t vtx, Pull pull) const;

  int micro_res_ = 0, channels_ = 0;
  std::vector<uint32_t> fine_index_;
  std::vector<int32_t> fine_to_block_;
  std::vector<float> value_;
  std::vector<Int4Channel> quant_;
  std::vector<float> quant_scale_, quant_inv_scale_, quant_zero_point_;  // quant_ by field, for the kernel
  LazyAdamArray adam_;
};

// Trilinear weights of the 8 corners (dx fastest) for fractions f in [0, 1].
inline void trilinear_weights(float fx, float fy, float fz, float w[8]) {
  float gx = 1.f - fx, gy = 1.f - fy, gz = 1.f - fz;
  w[0] = gx * gy * gz;
  w[1] = fx * gy * gz;
  w[2] = gx * fy * gz;
  w[3] = fx * fy * gz;
  w[4] = gx * gy * fz;
  w[5] = fx * gy * fz;
  w[6] = gx * fy * fz;
  w[7] = fx * fy * fz;
}

}  // namespace edrnr::train
