#pragma once
// NeRF "transforms_<split>.json" datasets (Blender synthetic and the
// Instant-NGP variant). Intrinsics come from camera_angle_x (square pixels,
// centred principal point) or from fl_x/fl_y/cx/cy/w/h when present; each
// frame has a file_path (with or without extension, relative to the JSON)
// and a 4x4 transform_matrix (camera to world).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "data/camera.h"

namespace edrnr {

struct DatasetOptions {
  std::string split = "train";            // train, val, test
  float background[3] = {1.f, 1.f, 1.f};  // RGBA images are composited on this
  int downscale = 1;                      // integer factor applied to images and intrinsics
  bool load_images = true;                // false: cameras only
};

struct Frame {
  std::filesystem::path image_path;
  Camera camera;
  Image image;  // RGB composited on the background (empty if not loaded)
};

struct Dataset {
  std::filesystem::path root;
  std::string split;
  std::vector<Frame> frames;
};

// Loads root/transforms_<split>.json and its images. Throws Error on a missing
// or malformed file, a missing image or an image whose size does not match.
Dataset load_dataset(const std::filesystem::path& root, const DatasetOptions& options);

// The frame's image as RGBA at full size (before any downscale), checked
// against its camera: the camera's size times `downscale`. Throws Error naming
// the image when it is missing, unreadable or of another size.
Image read_frame_rgba(const Frame& frame, int downscale);

// Parses only the cameras of a transforms JSON text (for tests and tools);
// `base` resolves relative image paths.
std::vector<Frame> parse_transforms(const std::string& json_text, const std::filesystem::path& base,
                                    const std::string& source, int downscale = 1);

}  // namespace edrnr
