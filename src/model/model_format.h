#pragma once
// The .edrnr file layout shared by the model file's reader and writer
// (model_io.cpp) and its validation (model_validate.cpp): the section
// table, the sizes derived from a model's shape, and the checks that
// saving and loading both make. Internal to src/model.
#include <fmt/format.h>

#include <cstdint>
#include <string>

#include "model/model_io.h"
#include "model/scene_model.h"

namespace edrnr::model_format {

inline constexpr char kMagic[8] = {'E', 'D', 'R', 'N', 'R', 'M', 'D', 'L'};
inline constexpr size_t kGridBytes = 64;
inline constexpr size_t kMlpShapeHeadBytes = 12;
inline constexpr size_t kSectionAlignBytes = 8;

// Section kinds, in the order they are written.
enum Section : int {
  kGrid,
  kOcc0,  // coarse; kOcc0 + Tier gives the tier's bitmap
  kOcc1,
  kOcc2,
  kOcc3,
  kBlockIndex,
  kMlpIndex,
  kFeaturesQ4,
  kFeaturesF32,
  kMlpShape,
  kMlpsQ8,
  kMlpsF32,
  kMetadata,
  kSectionKinds
};

struct SectionInfo {
  char tag[5];
  const char* what;
  bool required;
};

inline constexpr SectionInfo kSectionInfo[kSectionKinds] = {
    {"GRID", "grid", true},           {"OCC0", "coarse occupancy", true}, {"OCC1", "fine occupancy", true},
    {"OCC2", "leaf occupancy", true}, {"OCC3", "micro occupancy", true},  {"BIDX", "block index", true},
    {"MIDX", "MLP index", true},      {"FEQ4", "INT4 features", false},   {"FE32", "float features", false},
    {"MARC", "MLP shape", false},     {"MLQ8", "INT8 MLPs", false},       {"ML32", "float MLPs", false},
    {"META", "metadata", false},
};

inline std::string sec(int s) { return fmt::format("section {} ({})", kSectionInfo[s].tag, kSectionInfo[s].what); }

// ---- sizes, all derived from validated small numbers, in 64 bits ----

inline uint64_t voxel_count(int res) { return uint64_t(res) * uint64_t(res) * uint64_t(res); }
inline uint64_t bitmap_bytes(int res) { return (voxel_count(res) + 7) / 8; }
inline uint64_t feature_values(uint64_t blocks, int channels) { return blocks * kBlockVerts * uint64_t(channels); }
inline uint64_t q4_code_bytes(uint64_t blocks, int channels) { return (feature_values(blocks, channels) + 1) / 2; }

// Bytes of one MLP in section MLQ8: per layer in_scale, w_scale[out], b[out], w[out*in].
inline uint64_t mlp_q8_record_bytes(const MlpArch& a) {
  uint64_t n = 0;
  for (const auto* widths : {&a.density_widths, &a.color_widths})
    for (size_t i = 1; i < widths->size(); ++i) {
      uint64_t in = uint64_t((*widths)[i - 1]), out = uint64_t((*widths)[i]);
      n += 4 + 8 * out + in * out;
    }
  return n;
}
// Bytes of one MLP in section ML32: per layer w[out*in], b[out], all f32.
inline uint64_t mlp_f32_record_bytes(const MlpArch& a) {
  uint64_t n = 0;
  for (const auto* widths : {&a.density_widths, &a.color_widths})
    for (size_t i = 1; i < widths->size(); ++i) {
      uint64_t in = uint64_t((*widths)[i - 1]), out = uint64_t((*widths)[i]);
      n += 4 * (in * out + out);
    }
  return n;
}

// ---- validation shared by saving and loading (model_validate.cpp) ----
// Each throws Error naming `src`, the section and the field at fault.

// The scene box, object AABB, micro resolution and feature channels.
void validate_grid(const SceneModel& m, const std::string& src);
// The MLP shape: widths, layer counts, direction frequencies.
void validate_arch(const MlpArch& a, int feature_channels, const std::string& src);
// The sizes of every array against the grid and the MLP shape.
void validate_shapes(const SceneModel& m, const std::string& src);
// The values: indices in range and ascending, scales finite, metadata depth.
void validate_content(const SceneModel& m, const std::string& src);

// The two model checks parsing makes itself (model_checks makes them too).
ModelCheck check_stray_blocks(const SceneModel& m);
ModelCheck check_stray_mlps(const SceneModel& m);

}  // namespace edrnr::model_format
