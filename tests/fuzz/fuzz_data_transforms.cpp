// libFuzzer harness for the NeRF transforms JSON parser (scripts/fuzz.sh).
//
// Each input is parsed as a transforms_<split>.json text with downscale 1 and
// 2. A parse may only end in edrnr::Error; anything else (a crash, a sanitizer
// report, another exception) is a finding. Parsed cameras must be finite and
// within the image-size limit.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness writes a few valid
// transforms files into DIR as the seed corpus and exits.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "data/dataset.h"

namespace {

using namespace edrnr;

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  write_file_atomic(dir / "blender.json", std::string(R"({
  "camera_angle_x": 0.6911112070083618,
  "w": 800, "h": 800,
  "frames": [
    {"file_path": "./test/r_0", "rotation": 0.012,
     "transform_matrix": [[-1.0, 0.0, 0.0, 0.0], [0.0, -0.73, 0.68, 2.74], [0.0, 0.68, 0.73, 2.95], [0.0, 0.0, 0.0, 1.0]]},
    {"file_path": "./test/r_1",
     "transform_matrix": [[0.98, 0.1, -0.1, -0.4], [-0.15, 0.71, -0.69, -2.8], [0.0, 0.7, 0.71, 2.9], [0, 0, 0, 1]]}
  ]
})"));
  write_file_atomic(dir / "ngp.json", std::string(R"({
  "fl_x": 1111.1, "fl_y": 1111.1, "cx": 400, "cy": 400, "w": 800, "h": 800, "k1": 0, "p1": 0,
  "frames": [{"file_path": "images/0001.png", "fl_x": 1000, "w": 800.0,
              "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]
})"));
  write_file_atomic(dir / "angles.json", std::string(R"({"camera_angle_x": 0.5, "camera_angle_y": 0.4, "w": 64, "h": 32,
  "frames": [{"file_path": "a", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]})"));
  std::printf("wrote 3 seed transforms files to %s\n", dir.c_str());
}

void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "a parsed dataset breaks an invariant: %s\n", what);
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (int downscale : {1, 2}) {
    try {
      const std::vector<Frame> frames = parse_transforms(text, "/nonexistent-fuzz-base", "fuzz.json", downscale);
      check(!frames.empty(), "no frames");
      for (const Frame& f : frames) {
        const Camera& c = f.camera;
        check(c.width >= 1 && c.height >= 1, "image size below 1");
        check(int64_t(c.width) * c.height <= limits::kMaxImagePixels, "image over the pixel limit");
        check(std::isfinite(c.fx) && std::isfinite(c.fy) && c.fx > 0 && c.fy > 0, "focal length");
        check(std::isfinite(c.cx) && std::isfinite(c.cy), "principal point");
        for (double v : c.c2w) check(std::isfinite(v), "matrix");
      }
    } catch (const Error&) {
    }
  }
  return 0;
}
