#pragma once
// The scene model the EDR-NR chip consumes (DESIGN.md, "Scene model").
//
// Geometry: a scene box is divided into Rm^3 micro voxels (Rm = micro_res).
// Tiers: micro Rm, leaf Rm/2, fine Rm/4, coarse Rm/32. A fine voxel is 2^3
// leaf = 4^3 micro voxels; a coarse voxel (CV) is 8^3 fine voxels. Each tier
// has a dense occupancy bitmap; a tier's bit is the OR of the 8 (or 512, ...)
// bits below it. No micro voxel outside the object AABB is occupied.
//
// Features: one block per occupied fine voxel, holding F channels at the
// 5x5x5 micro-lattice vertices of that fine voxel (vertex (i,j,k), i,j,k in
// 0..4, sits at micro coordinate 4*fine + (i,j,k)). A sample is trilinearly
// interpolated from the 8 corners of its micro voxel, all inside its block.
//
// MLP: one per occupied CV. density net: F -> ... -> G outputs (output 0 is
// the raw density, sigma = exp(raw)). colour net: [G outputs, direction
// encoding] -> ... -> 3 (rgb = sigmoid). Hidden layers use ReLU; output layers
// are linear. Direction encoding: [d, sin(2^k d), cos(2^k d) for k < L].
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/vec.h"

namespace edrnr {

enum class Tier : int { Coarse = 0, Fine = 1, Leaf = 2, Micro = 3 };
inline constexpr int kTierCount = 4;
inline constexpr int kBlockVertsPerAxis = 5;
inline constexpr int kBlockVerts = 125;         // 5^3 vertices per fine voxel block
inline constexpr int kMicroPerFine = 4;         // micro voxels per fine voxel, per axis
inline constexpr int kFinePerCoarse = 8;        // fine voxels per CV, per axis
inline constexpr size_t kMlpCacheBytes = 8448;  // the chip's 8.25 KB MLP cache

const char* tier_name(Tier t);

// Dense 3D bitmap, x fastest: index = x + res * (y + res * z).
class Bitmap3 {
 public:
  Bitmap3() = default;
  explicit Bitmap3(int res) : res_(res), words_((size_t(res) * res * res + 63) / 64, 0) {}

  int res() const { return res_; }
  size_t size() const { return size_t(res_) * res_ * res_; }
  size_t index(int x, int y, int z) const { return size_t(x) + size_t(res_) * (size_t(y) + size_t(res_) * size_t(z)); }
  bool get(size_t i) const { return (words_[i >> 6] >> (i & 63)) & 1u; }
  bool get(int x, int y, int z) const { return get(index(x, y, z)); }
  void set(size_t i, bool v = true) {
    if (v)
      words_[i >> 6] |= uint64_t(1) << (i & 63);
    else
      words_[i >> 6] &= ~(uint64_t(1) << (i & 63));
  }
  void set(int x, int y, int z, bool v = true) { set(index(x, y, z), v); }
  size_t count() const;
  const std::vector<uint64_t>& words() const { return words_; }
  std::vector<uint64_t>& words() { return words_; }
  bool operator==(const Bitmap3& o) const = default;

 private:
  int res_ = 0;
  std::vector<uint64_t> words_;
};

// INT4 feature quantization, per channel: value = (q - zero_point) * scale, q in 0..15.
struct FeatureQuant {
  std::vector<float> scale;         // F entries
  std::vector<uint8_t> zero_point;  // F entries, each 0..15
  bool operator==(const FeatureQuant& o) const = default;
};

// Shape of every per-CV MLP in a model.
struct MlpArch {
  std::vector<int> density_widths;  // [F, hidden..., G]
  std::vector<int> color_widths;    // [G + dir_dims, hidden..., 3]
  int dir_frequencies = 2;          // L in the direction encoding
  int dir_dims() const { return 3 + 6 * dir_frequencies; }
  int feature_channels() const { return density_widths.empty() ? 0 : density_widths.front(); }
  int geo_width() const { return density_widths.empty() ? 0 : density_widths.back(); }
  size_t weight_count() const;  // weights only, both nets
  size_t bias_count() const;
  // Bytes of one INT8 MLP as the chip stores it in DRAM and in its MLP cache:
  // 1 byte per weight; per output neuron an INT32 bias and an INT32
  // fixed-point requantization multiplier; and the input stage's INT32
  // multipliers, one per feature channel plus one for the density-net outputs
  // and one for the direction code.
  size_t q8_bytes() const { return weight_count() + 8 * bias_count() + 4 * size_t(feature_channels() + 2); }
  bool operator==(const MlpArch& o) const = default;
};

// Float dense layer: y = W x + b, W row-major [out][in].
struct DenseF {
  int in = 0, out = 0;
  std::vector<float> w, b;
  bool operator==(const DenseF& o) const = default;
};

// INT8 dense layer: W = w_q * w_scale[row]; the layer's input is quantized to
// INT8 with step in_scale. Bias is kept in float; the chip converts it.
struct DenseQ {
  int in = 0, out = 0;
  std::vector<int8_t> w;       // out*in
  std::vector<float> w_scale;  // out
  std::vector<float> b;        // out
  float in_scale = 1.f;
  bool operator==(const DenseQ& o) const = default;
};

struct MlpF {
  std::vector<DenseF> density, color;
  bool operator==(const MlpF& o) const = default;
};
struct MlpQ {
  std::vector<DenseQ> density, color;
  bool operator==(const MlpQ& o) const = default;
};

// The spacing of candidate samples along a ray, in micro-voxel edges, that
// the trainer, the renderers and the chip use unless told otherwise: half a
// micro voxel (about 1 dB over one on validation views, docs/training.md,
// "The sample step").
inline constexpr float kDefaultStepMicro = 0.5f;

struct SceneModel {
  Box3f scene_box{{-1.5f, -1.5f, -1.5f}, {1.5f, 1.5f, 1.5f}};
  Box3f object_aabb{{-1.5f, -1.5f, -1.5f}, {1.5f, 1.5f, 1.5f}};
  int micro_res = 256;                        // Rm, a multiple of 32
  std::array<Bitmap3, kTierCount> occupancy;  // indexed by Tier

  int feature_channels = 16;               // F
  std::vector<uint32_t> block_fine_index;  // linear fine index of each block, strictly ascending
  std::vector<float> features_f32;         // blocks * 125 * F, or empty
  std::vector<uint8_t> features_q4;        // blocks * 125 * F / 2, low nibble = even channel, or empty
  FeatureQuant feature_quant;              // present when features_q4 is

  MlpArch mlp_arch;
  std::vector<uint32_t> mlp_coarse_index;  // linear CV index of each MLP, strictly ascending
  std::vector<MlpF> mlps_f32;              // one per CV in mlp_coarse_index, or empty
  std::vector<MlpQ> mlps_q8;               // one per CV in mlp_coarse_index, or empty

  std::string metadata_json = "{}";  // source dataset, training settings, ...

  // Lookups built by finalize(): -1 where there is no block / MLP.
  std::vector<int32_t> fine_to_block;
  std::vector<int32_t> coarse_to_mlp;

  int tier_res(Tier t) const;
  int leaf_res() const { return micro_res / 2; }
  int fine_res() const { return micro_res / 4; }
  int coarse_res() const { return micro_res / 32; }
  size_t block_count() const { return block_fine_index.size(); }
  size_t mlp_count() const { return mlp_coarse_index.size(); }
  Vec3f micro_voxel_size() const { return scene_box.size() / float(micro_res); }

  // Allocates empty bitmaps for micro_res.
  void init_grids();
  // Recomputes leaf, fine and coarse bitmaps as ORs of the micro bitmap.
  void rebuild_upper_tiers();
  // Builds fine_to_block and coarse_to_mlp. Call after loading or editing.
  void finalize();

  // Feature of vertex v (0..124) in block b, channel c, dequantized from INT4
  // if there are no float features.
  float feature(size_t block, int vertex, int channel) const;
  // Unpacked INT4 code (0..15) of vertex v in block b, channel c.
  uint8_t feature_q(size_t block, int vertex, int channel) const;
  // Fills features_q4 / feature_quant from features_f32 (per-channel min/max).
  void quantize_features();
  // Fills features_f32 from features_q4.
  void dequantize_features();

  // Throws Error unless the structure is usable by a renderer: micro_res a
  // positive multiple of 32, a non-empty scene box, bitmaps of the tier
  // resolutions, and the finalize() lookups built.
  void check_structure() const;
  // Checks the invariants; returns one line per violation (empty when valid).
  std::vector<std::string> check_invariants() const;
};

// Linear index of the fine voxel containing micro voxel (x, y, z), and so on.
inline uint32_t linear_index(int x, int y, int z, int res) { return uint32_t(x + res * (y + res * z)); }

}  // namespace edrnr
