#pragma once
// Images: linear float channels in [0, 1], row-major, top row first.
#include <cstdint>
#include <filesystem>
#include <vector>

namespace edrnr {

struct Image {
  int width = 0, height = 0, channels = 3;
  std::vector<float> data;  // width * height * channels

  Image() = default;
  Image(int w, int h, int c = 3, float fill = 0.f) : width(w), height(h), channels(c), data(size_t(w) * h * c, fill) {}
  float* at(int x, int y) { return &data[(size_t(y) * width + x) * channels]; }
  const float* at(int x, int y) const { return &data[(size_t(y) * width + x) * channels]; }
};

// Reads an 8- or 16-bit PNG of any colour type as RGBA (4 channels). Throws
// Error naming the file if it is missing or not a valid PNG.
Image read_png_rgba(const std::filesystem::path& path);

// Composites an RGBA image over a constant background: rgb*a + bg*(1-a).
Image composite_rgba(const Image& rgba, const float background[3]);

// Box-filter downscale by an integer factor (width and height must divide).
Image downscale(const Image& img, int factor);

// Writes an 8-bit RGB (3 channels) or RGBA (4 channels) PNG atomically.
// Values are clamped to [0, 1] and rounded to nearest.
void write_png(const std::filesystem::path& path, const Image& img);

}  // namespace edrnr
