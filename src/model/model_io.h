#pragma once
// The .edrnr file format (docs/format.md): little-endian; a header with magic
// "EDRNRMDL", format version, section count and a CRC-32 of everything after
// the header; a section table; then the sections (grid, the four occupancy
// bitmaps, block index, INT4 features and their quantization, float features,
// MLP shape, INT8 MLPs, float MLPs, metadata JSON).
#include <cstdint>
#include <filesystem>
#include <vector>

#include "model/scene_model.h"

namespace edrnr {

inline constexpr uint32_t kModelFormatVersion = 1;

// Serializes a model. Throws Error if the model is inconsistent (sizes that do
// not match its counts).
std::vector<uint8_t> serialize_model(const SceneModel& model);

// Parses and validates a model from bytes. Every count, size and index is
// checked before anything is allocated or read; a corrupt, truncated or
// hostile input throws Error with a message naming what is wrong (`source`
// names the input in messages). The result is finalize()d.
SceneModel parse_model(const uint8_t* data, size_t size, const std::string& source = "model");

// File wrappers; save writes atomically (temporary file, then rename).
SceneModel load_model(const std::filesystem::path& path);
void save_model(const std::filesystem::path& path, const SceneModel& model);

}  // namespace edrnr
