#include "train/error_map.h"

#include <algorithm>

#include "core/error.h"

namespace edrnr::train {

ErrorMap::ErrorMap(const std::vector<int>& widths, const std::vector<int>& heights, int cell, float initial)
    : cell_(cell), width_(widths), height_(heights) {
  if (cell < 1) fail("error map: cells of {} pixels", cell);
  if (widths.size() != heights.size()) fail("error map: {} widths for {} heights", widths.size(), heights.size());
  first_.assign(1, 0);
  for (size_t f = 0; f < widths.size(); ++f) {
    if (widths[f] < 1 || heights[f] < 1) fail("error map: frame {} is {}x{}", f, widths[f], heights[f]);
    const int cx = (widths[f] + cell - 1) / cell, cy = (heights[f] + cell - 1) / cell;
    cells_x_.push_back(cx);
    first_.push_back(first_.back() + uint32_t(cx) * uint32_t(cy));
  }
  values_.assign(first_.back(), initial);
}

uint32_t ErrorMap::cell_of(uint32_t frame, int x, int y) const {
  return first_[frame] + uint32_t(y / cell_) * uint32_t(cells_x_[frame]) + uint32_t(x / cell_);
}

int ErrorMap::cell_pixels(uint32_t cell) const {
  const size_t f = size_t(std::upper_bound(first_.begin(), first_.end(), cell) - first_.begin()) - 1;
  const uint32_t local = cell - first_[f];
  const int cx = int(local % uint32_t(cells_x_[f])), cy = int(local / uint32_t(cells_x_[f]));
  return std::min(cell_, width_[f] - cx * cell_) * std::min(cell_, height_[f] - cy * cell_);
}

void ErrorMap::rebuild() {
  cdf_.resize(values_.size() + 1);
  cdf_[0] = 0;
  for (size_t c = 0; c < values_.size(); ++c) cdf_[c + 1] = cdf_[c] + double(values_[c]);
}

MapPixel ErrorMap::draw(double u, uint64_t bits) const {
  MapPixel p;
  const double target = u * total();
  // The first cell whose running sum passes the target (a cell of zero error is never drawn).
  p.cell = uint32_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), target) - (cdf_.begin() + 1));
  p.cell = std::min<uint32_t>(p.cell, uint32_t(values_.size() - 1));
  p.frame = uint32_t(std::upper_bound(first_.begin(), first_.end(), p.cell) - first_.begin()) - 1;
  const uint32_t local = p.cell - first_[p.frame];
  const int cx = int(local % uint32_t(cells_x_[p.frame])), cy = int(local / uint32_t(cells_x_[p.frame]));
  const int w = std::min(cell_, width_[p.frame] - cx * cell_), h = std::min(cell_, height_[p.frame] - cy * cell_);
  p.x = cx * cell_ + int((bits & 0xffffffffu) % uint64_t(w));
  p.y = cy * cell_ + int((bits >> 32) % uint64_t(h));
  return p;
}

double ErrorMap::probability(uint32_t cell) const {
  const double t = total();
  return t > 0 ? double(values_[cell]) / t / double(cell_pixels(cell)) : 0.0;
}

}  // namespace edrnr::train
