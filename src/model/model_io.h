#pragma once
// The .edrnr file format (docs/format.md): little-endian; a header with magic
// "EDRNRMDL", format version, section count and a CRC-32 of everything after
// the header; a section table; then the sections (grid, the four occupancy
// bitmaps, block index, INT4 features and their quantization, float features,
// MLP shape, INT8 MLPs, float MLPs, metadata JSON).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "model/scene_model.h"

namespace edrnr {

inline constexpr uint32_t kModelFormatVersion = 1;
inline constexpr size_t kModelHeaderBytes = 32;        // magic, version, section count, total size, CRC, reserved
inline constexpr size_t kModelSectionEntryBytes = 24;  // tag, reserved, offset, size
inline constexpr int kMaxMicroRes = 1024;
inline constexpr int kMaxFeatureChannels = 64;
inline constexpr int kMaxMlpLayers = 8;       // per net (density, colour)
inline constexpr int kMaxMlpWidth = 256;      // neurons in any layer
inline constexpr int kMaxDirFrequencies = 8;  // L in the direction encoding

// Serializes a model. Throws Error if the model is inconsistent (sizes that do
// not match its counts).
std::vector<uint8_t> serialize_model(const SceneModel& model);

struct ModelLoadOptions {
  // Run the model checks (model_checks) after parsing and throw on any failure.
  // Only tools that report the checks themselves (edrnr inspect) turn this off.
  bool check_invariants = true;
};

// Parses and validates a model from bytes. Every count, size and index is
// checked before anything is allocated or read; a corrupt, truncated or
// hostile input throws Error with a message naming what is wrong (`source`
// names the input in messages). The result is finalize()d.
SceneModel parse_model(const uint8_t* data, size_t size, const std::string& source = "model");
SceneModel parse_model(const uint8_t* data, size_t size, const std::string& source, const ModelLoadOptions& options);

// Reads a model file's bytes for parse_model: the header is read first, and a
// file that does not start with the magic, or whose size differs from the
// header's total (at most limits::kMaxModelFileBytes), is refused before the
// rest is read. Throws Error naming the file.
std::vector<uint8_t> read_model_file(const std::filesystem::path& path);

// File wrappers (load reads with read_model_file); save writes with
// write_file_atomic (a temporary file renamed over a regular file; devices and
// FIFOs written through; symbolic links followed).
SceneModel load_model(const std::filesystem::path& path);
SceneModel load_model(const std::filesystem::path& path, const ModelLoadOptions& options);
void save_model(const std::filesystem::path& path, const SceneModel& model);

// One structural check of a finalize()d model: its name, whether it holds, and
// what is wrong when it does not.
struct ModelCheck {
  std::string name;
  bool passed = true;
  std::string detail;
};

// The checks a loaded model must pass: each tier is the OR of the tier below;
// feature blocks and occupied fine voxels match one to one; MLPs and occupied
// coarse voxels match one to one; no occupied micro voxel lies outside the
// object AABB. A superset of SceneModel::check_invariants().
std::vector<ModelCheck> model_checks(const SceneModel& model);

}  // namespace edrnr
