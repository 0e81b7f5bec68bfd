#include "train/occupancy.h"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "train/occupancy_kernels.h"

namespace edrnr::train {

OccupancyGrid::OccupancyGrid(int micro_res)
    : res(micro_res), density(size_t(micro_res) * micro_res * micro_res, -1.f), micro(micro_res), fine(micro_res / 4) {
  rebuild(0.f);
}

double OccupancyGrid::mean_density() const {
  // Fixed blocks of cells, summed by the kernel's fixed order and added in
  // block order: the same bits for any thread count and SIMD target.
  constexpr size_t kBlock = size_t(1) << 16;
  const size_t n_cells = density.size();
  const size_t n_blocks = (n_cells + kBlock - 1) / kBlock;
  std::vector<double> sums(n_blocks);
  std::vector<size_t> counts(n_blocks);
#pragma omp parallel for schedule(static)
  for (size_t b = 0; b < n_blocks; ++b)
    occupancy_sum_nonnegative(density.data() + b * kBlock, std::min(kBlock, n_cells - b * kBlock), &sums[b],
                              &counts[b]);
  double sum = 0;
  size_t n = 0;
  for (size_t b = 0; b < n_blocks; ++b) {
    sum += sums[b];
    n += counts[b];
  }
  return n ? sum / double(n) : 0.0;
}

void OccupancyGrid::rebuild(float threshold) {
  micro = Bitmap3(res);
  auto& words = micro.words();
  const int n_words = int(words.size());
  // Words hold 64 consecutive x (res is a multiple of 32; 64 | res^3), so each
  // word is owned by one thread; a word holds one row's stretch, or two whole
  // rows when res == 32.
  const int row_words = std::max(1, res / 64);  // words per row (res >= 64)
  const int rows_per_word = res < 64 ? 64 / res : 1;
  constexpr int kChunk = 1024;  // words per kernel call
#pragma omp parallel for schedule(static)
  for (int c = 0; c < n_words; c += kChunk)
    occupancy_threshold_words(density.data() + size_t(c) * 64, size_t(std::min(kChunk, n_words - c)), threshold,
                              words.data() + c);
  if (!aabb_known) {
    rebuild_macro();
    return;
  }
#pragma omp parallel for schedule(static)
  for (int wi = 0; wi < n_words; ++wi) {
    uint64_t w = words[size_t(wi)];
    if (w != 0) {
      // Keep the bits of the AABB's x range in rows whose y and z lie in it.
      uint64_t keep = 0;
      for (int r = 0; r < rows_per_word; ++r) {
        const size_t row = size_t(wi) * size_t(rows_per_word) / size_t(row_words) + size_t(r);
        const int y = int(row % size_t(res)), z = int(row / size_t(res));
        if (y < aabb_lo.y || z < aabb_lo.z || y > aabb_hi.y || z > aabb_hi.z) continue;
        const int x0 = res < 64 ? 0 : (wi % row_words) * 64;  // the word's first x
        const int n = std::min(res, 64);                      // x per row in the word
        const int lo = std::max(aabb_lo.x - x0, 0), hi = std::min(aabb_hi.x - x0, n - 1);
        if (lo > hi) continue;
        const uint64_t span = (hi - lo == 63) ? ~uint64_t(0) : ((uint64_t(1) << (hi - lo + 1)) - 1) << lo;
        keep |= span << (r * n);
      }
      w &= keep;
    }
    words[size_t(wi)] = w;
  }
  rebuild_macro();
}

void OccupancyGrid::rebuild_macro() {
  static std::atomic<uint64_t> last_generation{0};
  generation = ++last_generation;
  fine = Bitmap3(res / 4);
  const auto& words = micro.words();
  if (res % 64 != 0) {  // a word may hold two rows (res == 32): bit by bit
    for (size_t wi = 0; wi < words.size(); ++wi) {
      uint64_t w = words[wi];
      while (w) {
        const size_t i = wi * 64 + size_t(__builtin_ctzll(w));
        w &= w - 1;
        const int x = int(i % size_t(res)), y = int((i / size_t(res)) % size_t(res)), z = int(i / (size_t(res) * res));
        fine.set(x / 4, y / 4, z / 4);
      }
    }
    return;
  }
  // Each fine row is the OR of 4 x 4 micro rows, each run of 4 micro x bits
  // giving one fine bit. A fine z slab's bits fill whole words (fine res >= 16),
  // so the slabs are written by one thread each.
  const int fres = res / 4, row_words = res / 64;
  auto& fwords = fine.words();
#pragma omp parallel for schedule(static)
  for (int fz = 0; fz < fres; ++fz)
    for (int fy = 0; fy < fres; ++fy)
      for (int k = 0; k < row_words; ++k) {
        uint64_t w = 0;
        for (int dz = 0; dz < 4; ++dz)
          for (int dy = 0; dy < 4; ++dy) w |= words[micro.index(0, 4 * fy + dy, 4 * fz + dz) / 64 + size_t(k)];
        if (w == 0) continue;
        uint64_t bits = 0;  // bit j: micro x bits 4j .. 4j+3 of the word
        for (int j = 0; j < 16; ++j) bits |= uint64_t(((w >> (4 * j)) & 0xF) != 0) << j;
        const size_t fi = fine.index(16 * k, fy, fz);
        fwords[fi / 64] |= bits << (fi % 64);
      }
}

bool OccupancyGrid::update_aabb(float threshold, float filter_sigma, float keep) {
  std::vector<float> occ(density.size());
  for (size_t i = 0; i < density.size(); ++i) occ[i] = (density[i] < 0.f || density[i] > threshold) ? 1.f : 0.f;
  std::vector<float> f = filter_sigma > 0.f ? gaussian_filter3(occ, res, filter_sigma) : std::move(occ);
  Vec3i lo{res, res, res}, hi{-1, -1, -1};
  for (int z = 0; z < res; ++z)
    for (int y = 0; y < res; ++y)
      for (int x = 0; x < res; ++x)
        if (f[micro.index(x, y, z)] >= keep) {
          lo = vmin(lo, Vec3i{x, y, z});
          hi = vmax(hi, Vec3i{x, y, z});
        }
  if (hi.x < 0) return false;
  aabb_known = true;
  aabb_lo = lo;
  aabb_hi = hi;
  return true;
}

size_t drop_outlying_parts(Bitmap3& micro, float min_fraction) {
  if (!(min_fraction > 0.f)) return 0;
  const int res = micro.res();
  struct Part {
    size_t first = 0, count = 0;  // range in `voxels`
    Vec3i lo, hi;                 // inclusive micro bounds
  };
  std::vector<Part> parts;
  std::vector<uint32_t> voxels;  // every occupied voxel, grouped by part
  voxels.reserve(micro.count());
  Bitmap3 seen(res);
  const auto& words = micro.words();
  for (size_t wi = 0; wi < words.size(); ++wi)
    for (uint64_t w = words[wi]; w; w &= w - 1) {
      const size_t start = wi * 64 + size_t(__builtin_ctzll(w));
      if (seen.get(start)) continue;
      Part part;
      part.first = voxels.size();
      part.lo = {res, res, res};
      part.hi = {-1, -1, -1};
      seen.set(start);
      voxels.push_back(uint32_t(start));
      // Breadth first: `voxels` from part.first on is the queue.
      for (size_t q = part.first; q < voxels.size(); ++q) {
        const size_t i = voxels[q];
        const Vec3i p{int(i % size_t(res)), int((i / size_t(res)) % size_t(res)), int(i / (size_t(res) * res))};
        part.lo = vmin(part.lo, p);
        part.hi = vmax(part.hi, p);
        for (int dz = -1; dz <= 1; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int x = p.x + dx, y = p.y + dy, z = p.z + dz;
              if (x < 0 || y < 0 || z < 0 || x >= res || y >= res || z >= res) continue;
              const size_t j = micro.index(x, y, z);
              if (micro.get(j) && !seen.get(j)) {
                seen.set(j);
                voxels.push_back(uint32_t(j));
              }
            }
      }
      part.count = voxels.size() - part.first;
      parts.push_back(part);
    }
  size_t largest = 0;
  for (const Part& p : parts) largest = std::max(largest, p.count);
  const double min_count = double(min_fraction) * double(largest);
  auto large = [&](const Part& p) { return double(p.count) >= min_count; };
  Vec3i lo{res, res, res}, hi{-1, -1, -1};
  for (const Part& p : parts)
    if (large(p)) {
      lo = vmin(lo, p.lo);
      hi = vmax(hi, p.hi);
    }
  size_t emptied = 0;
  for (const Part& p : parts) {
    if (large(p)) continue;
    const bool apart =
        p.hi.x < lo.x || p.hi.y < lo.y || p.hi.z < lo.z || p.lo.x > hi.x || p.lo.y > hi.y || p.lo.z > hi.z;
    if (!apart) continue;
    for (size_t k = p.first; k < p.first + p.count; ++k) micro.set(size_t(voxels[k]), false);
    emptied += p.count;
  }
  return emptied;
}

std::vector<float> gaussian_filter3(const std::vector<float>& grid, int res, float sigma_voxels) {
  const int radius = std::max(1, int(std::ceil(3.f * sigma_voxels)));
  std::vector<float> k(size_t(2 * radius + 1));
  float sum = 0.f;
  for (int i = -radius; i <= radius; ++i) {
    k[size_t(i + radius)] = std::exp(-0.5f * float(i * i) / (sigma_voxels * sigma_voxels));
    sum += k[size_t(i + radius)];
  }
  for (float& v : k) v /= sum;
  std::vector<float> a = grid, b(grid.size());
  const size_t R = size_t(res);
  const size_t stride[3] = {1, R, R * R};
  for (int axis = 0; axis < 3; ++axis) {
    const size_t s = stride[axis];
#pragma omp parallel for schedule(static)
    for (int z = 0; z < res; ++z)
      for (int y = 0; y < res; ++y)
        for (int x = 0; x < res; ++x) {
          const int c[3] = {x, y, z};
          const size_t i = size_t(x) + R * (size_t(y) + R * size_t(z));
          float acc = 0.f;
          for (int t = -radius; t <= radius; ++t) {
            const int u = c[axis] + t;
            if (u < 0 || u >= res) continue;
            acc += k[size_t(t + radius)] * a[size_t(int64_t(i) + int64_t(t) * int64_t(s))];
          }
          b[i] = acc;
        }
    std::swap(a, b);
  }
  return a;
}

}  // namespace edrnr::train
