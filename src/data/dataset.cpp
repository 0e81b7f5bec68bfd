#include "data/dataset.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <utility>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr int kMaxImageSidePx = limits::kMaxImageSide;

// The number under `key`, which must be finite. `field` names it in messages.
double finite_number(const json& value, const std::string& source, const std::string& field) {
  if (!value.is_number()) fail("{}: '{}' must be a number, got {}", source, field, value.type_name());
  double x = value.get<double>();
  if (!std::isfinite(x)) fail("{}: '{}' is not a finite number", source, field);
  return x;
}

// A per-frame value overrides the top-level one (Instant-NGP allows both).
// Returns the field's name for messages in `field`, or nullptr when absent.
const json* find_key(const json& frame, const json& top, int frame_index, const char* key, std::string& field) {
  if (auto it = frame.find(key); it != frame.end()) {
    field = fmt::format("frames[{}].{}", frame_index, key);
    return &*it;
  }
  if (auto it = top.find(key); it != top.end()) {
    field = key;
    return &*it;
  }
  return nullptr;
}

std::optional<double> lookup_number(const json& frame, const json& top, int frame_index, const char* key,
                                    const std::string& source) {
  std::string field;
  const json* v = find_key(frame, top, frame_index, key, field);
  if (!v) return std::nullopt;
  return finite_number(*v, source, field);
}

// An image side length in pixels: a positive integer (written as 800 or 800.0).
std::optional<int> lookup_size(const json& frame, const json& top, int frame_index, const char* key,
                               const std::string& source) {
  std::string field;
  const json* v = find_key(frame, top, frame_index, key, field);
  if (!v) return std::nullopt;
  double x = finite_number(*v, source, field);
  if (x != std::floor(x) || x < 1 || x > kMaxImageSidePx)
    fail("{}: '{}' must be an integer from 1 to {}, got {}", source, field, kMaxImageSidePx, x);
  return int(x);
}

// Width and height from a PNG's IHDR chunk, without decoding the image.
std::pair<int, int> png_size(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("cannot open image '{}'", path.string());
  unsigned char head[24] = {};
  in.read(reinterpret_cast<char*>(head), sizeof head);
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (in.gcount() != sizeof head || std::memcmp(head, kSignature, 8) != 0 || std::memcmp(head + 12, "IHDR", 4) != 0)
    fail("'{}' is not a PNG", path.string());
  auto be32 = [](const unsigned char* p) {
    return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
  };
  uint32_t w = be32(head + 16), h = be32(head + 20);
  limits::check_image_size(int64_t(w), int64_t(h), fmt::format("PNG '{}':", path.string()));
  return {int(w), int(h)};
}

// file_path relative to `base` (or absolute), as given if that file exists,
// else with ".png" appended. A missing image is reported when it is loaded.
fs::path resolve_image(const fs::path& base, const std::string& file_path) {
  fs::path given(file_path);
  fs::path path = (given.is_absolute() ? given : base / given).lexically_normal();
  std::error_code ec;
  if (fs::is_regular_file(path, ec)) return path;
  fs::path with_png = path;
  with_png += ".png";
  if (fs::is_regular_file(with_png, ec) || !path.has_extension()) return with_png;
  return path;
}

std::array<double, 16> parse_matrix(const json& frame, int frame_index, const std::string& source) {
  std::string field = fmt::format("frames[{}].transform_matrix", frame_index);
  auto it = frame.find("transform_matrix");
  if (it == frame.end()) fail("{}: missing key '{}'", source, field);
  const json& m = *it;
  if (!m.is_array() || m.size() != 4) fail("{}: '{}' must be a 4x4 array (4 rows of 4 numbers)", source, field);
  std::array<double, 16> out{};
  for (int r = 0; r < 4; ++r) {
    if (!m[r].is_array() || m[r].size() != 4)
      fail("{}: '{}' must be a 4x4 array (4 rows of 4 numbers); row {} is not 4 numbers", source, field, r);
    for (int c = 0; c < 4; ++c) out[r * 4 + c] = finite_number(m[r][c], source, fmt::format("{}[{}][{}]", field, r, c));
  }
  const double kTolerance = 1e-6;
  if (std::fabs(out[12]) > kTolerance || std::fabs(out[13]) > kTolerance || std::fabs(out[14]) > kTolerance ||
      std::fabs(out[15] - 1) > kTolerance)
    fail("{}: the last row of '{}' must be [0, 0, 0, 1]", source, field);
  return out;
}

double focal_from_angle(const json& frame, const json& top, int frame_index, const char* key, double size_px,
                        const std::string& source) {
  std::string field;
  const json* v = find_key(frame, top, frame_index, key, field);
  double angle = finite_number(*v, source, field);
  if (!(angle > 0 && angle < std::numbers::pi))
    fail("{}: '{}' must be in (0, pi) radians, got {}", source, field, angle);
  return focal_from_fov(size_px, angle);
}

Camera parse_camera(const json& frame, const json& top, int frame_index, const std::string& source,
                    const fs::path& first_image, std::optional<std::pair<int, int>>& first_image_size) {
  Camera cam;
  cam.c2w = parse_matrix(frame, frame_index, source);

  std::optional<int> w = lookup_size(frame, top, frame_index, "w", source);
  std::optional<int> h = lookup_size(frame, top, frame_index, "h", source);
  if (!w || !h) {
    if (!first_image_size) {
      std::error_code ec;
      if (!fs::is_regular_file(first_image, ec))
        fail("{}: image '{}' not found (its size is needed because the JSON gives no 'w'/'h')", source,
             first_image.string());
      first_image_size = png_size(first_image);
    }
    if (!w) w = first_image_size->first;
    if (!h) h = first_image_size->second;
  }
  cam.width = *w;
  cam.height = *h;
  limits::check_image_size(cam.width, cam.height, fmt::format("{}: frames[{}]: image size", source, frame_index));

  std::string field;
  if (auto fl_x = lookup_number(frame, top, frame_index, "fl_x", source)) {
    cam.fx = *fl_x;
  } else if (find_key(frame, top, frame_index, "camera_angle_x", field)) {
    cam.fx = focal_from_angle(frame, top, frame_index, "camera_angle_x", cam.width, source);
  } else {
    fail("{}: frames[{}] has no focal length: give 'camera_angle_x' or 'fl_x'", source, frame_index);
  }
  if (auto fl_y = lookup_number(frame, top, frame_index, "fl_y", source)) {
    cam.fy = *fl_y;
  } else if (find_key(frame, top, frame_index, "camera_angle_y", field)) {
    cam.fy = focal_from_angle(frame, top, frame_index, "camera_angle_y", cam.height, source);
  } else {
    cam.fy = cam.fx;
  }
  if (!(cam.fx > 0) || !(cam.fy > 0))
    fail("{}: frames[{}]: focal lengths must be positive, got fl_x = {} and fl_y = {}", source, frame_index, cam.fx,
         cam.fy);
  cam.cx = lookup_number(frame, top, frame_index, "cx", source).value_or(0.5 * cam.width);
  cam.cy = lookup_number(frame, top, frame_index, "cy", source).value_or(0.5 * cam.height);

  for (const char* key : {"k1", "k2", "k3", "k4", "p1", "p2"}) {
    auto k = lookup_number(frame, top, frame_index, key, source);
    if (k && *k != 0)
      fail("{}: frames[{}]: lens distortion ('{}' = {}) is not supported; undistort the images first", source,
           frame_index, key, *k);
  }
  return cam;
}

Image load_frame_image(const Frame& frame, int frame_index, const DatasetOptions& options, const std::string& source) {
  Image rgba;
  try {
    rgba = read_frame_rgba(frame, options.downscale);
  } catch (const Error& e) {
    fail("{}: frames[{}]: {}", source, frame_index, e.what());
  }
  return downscale(composite_rgba(rgba, options.background), options.downscale);
}

}  // namespace

Image read_frame_rgba(const Frame& frame, int downscale) {
  std::error_code ec;
  if (!fs::is_regular_file(frame.image_path, ec)) fail("image not found: '{}'", frame.image_path.string());
  Image rgba = read_png_rgba(frame.image_path);
  const int expected_w = frame.camera.width * downscale, expected_h = frame.camera.height * downscale;
  if (rgba.width != expected_w || rgba.height != expected_h)
    fail("image '{}' is {}x{}, but its camera expects {}x{} (all images of a split must have the same size)",
         frame.image_path.string(), rgba.width, rgba.height, expected_w, expected_h);
  return rgba;
}

std::vector<Frame> parse_transforms(const std::string& json_text, const fs::path& base, const std::string& source,
                                    int downscale) {
  if (downscale < 1) fail("{}: downscale must be a positive integer, got {}", source, downscale);
  json doc;
  try {
    doc = json::parse(json_text);
  } catch (const json::exception& e) {
    fail("{}: malformed JSON: {}", source, e.what());
  }
  if (!doc.is_object()) fail("{}: the top level must be a JSON object", source);
  auto frames_it = doc.find("frames");
  if (frames_it == doc.end()) fail("{}: missing key 'frames'", source);
  if (!frames_it->is_array()) fail("{}: 'frames' must be an array", source);
  if (frames_it->empty()) fail("{}: 'frames' is empty", source);

  std::vector<Frame> frames;
  frames.reserve(frames_it->size());
  std::optional<std::pair<int, int>> first_image_size;
  for (size_t i = 0; i < frames_it->size(); ++i) {
    const json& f = (*frames_it)[i];
    int index = int(i);
    if (!f.is_object()) fail("{}: frames[{}] must be an object", source, index);
    auto path_it = f.find("file_path");
    if (path_it == f.end()) fail("{}: missing key 'frames[{}].file_path'", source, index);
    if (!path_it->is_string() || path_it->get<std::string>().empty())
      fail("{}: 'frames[{}].file_path' must be a non-empty string", source, index);

    Frame frame;
    frame.image_path = resolve_image(base, path_it->get<std::string>());
    const fs::path& first_image = frames.empty() ? frame.image_path : frames[0].image_path;
    frame.camera = parse_camera(f, doc, index, source, first_image, first_image_size);
    if (!frames.empty() &&
        (frame.camera.width != frames[0].camera.width || frame.camera.height != frames[0].camera.height))
      fail("{}: frames[{}] is {}x{} but frames[0] is {}x{} (all images of a split must have the same size)", source,
           index, frame.camera.width, frame.camera.height, frames[0].camera.width, frames[0].camera.height);
    frames.push_back(std::move(frame));
  }

  const Camera& first = frames[0].camera;
  if (first.width % downscale || first.height % downscale)
    fail("{}: downscale {} does not divide the image size {}x{}", source, downscale, first.width, first.height);
  for (Frame& f : frames) f.camera = f.camera.downscaled(downscale);
  return frames;
}

Dataset load_dataset(const fs::path& root, const DatasetOptions& options) {
  fs::path json_path = root / ("transforms_" + options.split + ".json");
  std::error_code ec;
  if (!fs::is_regular_file(json_path, ec))
    fail("dataset '{}': split '{}' not found (no file '{}')", root.string(), options.split, json_path.string());
  for (float b : options.background)
    if (!std::isfinite(b)) fail("dataset '{}': the background colour must be finite", root.string());
  std::string source = json_path.string();

  Dataset ds;
  ds.root = root;
  ds.split = options.split;
  ds.frames = parse_transforms(read_file_text(json_path), root, source, options.downscale);
  if (!options.load_images) return ds;
  // All the images are decoded at full size before any downscale.
  const int64_t full_pixels =
      int64_t(ds.frames[0].camera.width) * options.downscale * int64_t(ds.frames[0].camera.height) * options.downscale;
  if (full_pixels * int64_t(ds.frames.size()) > limits::kMaxDatasetPixels)
    fail("{}: {} images of {} pixels are {} pixels in all, over the limit of {} pixels for one split", source,
         ds.frames.size(), full_pixels, full_pixels * int64_t(ds.frames.size()), limits::kMaxDatasetPixels);

  // Each thread decodes whole images into their own slots, so the result does
  // not depend on the schedule; the first error in frame order is reported.
  int n = int(ds.frames.size());
  std::vector<std::string> errors(n);
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < n; ++i) {
    try {
      ds.frames[i].image = load_frame_image(ds.frames[i], i, options, source);
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  }
  for (const std::string& e : errors)
    if (!e.empty()) throw Error(e);
  return ds;
}

}  // namespace edrnr
