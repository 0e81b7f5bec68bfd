#pragma once
// The training images' error map (train config error_map_share): every image
// in square cells of `cell` pixels, each cell holding the running mean
// squared error of the training rays through it, from which pixels are drawn
// in proportion to their cell's error. Deterministic: a draw is a function of
// a hash and the map.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace edrnr::train {

struct MapPixel {
  uint32_t frame = 0;
  int x = 0, y = 0;
  uint32_t cell = 0;
};

class ErrorMap {
 public:
  ErrorMap() = default;
  // Images of the given sizes (pixels across and down, one entry per frame);
  // every cell starts at `initial`.
  ErrorMap(const std::vector<int>& widths, const std::vector<int>& heights, int cell, float initial);

  bool empty() const { return values_.empty(); }
  size_t cells() const { return values_.size(); }
  uint32_t cell_of(uint32_t frame, int x, int y) const;
  // Pixels in a cell (fewer at an image's right and bottom edges).
  int cell_pixels(uint32_t cell) const;

  // Prefix sums for draw() and probability(); call after the values change.
  void rebuild();
  double total() const { return cdf_.empty() ? 0.0 : cdf_.back(); }
  // A pixel drawn with probability proportional to its cell's error: u in
  // [0, 1) picks the cell, `bits` the pixel inside it. Needs total() > 0.
  MapPixel draw(double u, uint64_t bits) const;
  // The probability of one pixel of `cell` under draw().
  double probability(uint32_t cell) const;

  // The cell's value moves halfway to `sq_err`.
  void update(uint32_t cell, float sq_err) { values_[cell] = 0.5f * values_[cell] + 0.5f * sq_err; }

  const std::vector<float>& values() const { return values_; }
  std::vector<float>& values() { return values_; }

 private:
  int cell_ = 1;
  std::vector<int> width_, height_, cells_x_;
  std::vector<uint32_t> first_;  // first cell of each frame; frames + 1 entries
  std::vector<float> values_;
  std::vector<double> cdf_;  // cells + 1 entries
};

}  // namespace edrnr::train
