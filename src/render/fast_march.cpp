#include "render/fast_march.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "core/error.h"
#include "model/mlp.h"

namespace edrnr {
namespace {

// ceil(x) for |x| < 2^62 without a library call.
inline double ceil_small(double x) {
  const double t = double(int64_t(x));  // toward zero
  return t < x ? t + 1.0 : t;
}

// skip_box's terms per axis (FastMarcher::State) for a march of micro_ray
// up to candidate k_end in a grid of micro_res.
void jump_terms(int micro_res, const MicroRay& micro_ray, int64_t k_end, double exit[3], double scale[3],
                double offset[3]) {
  const double delta = double(micro_ray.delta);
  // A candidate's float point o_m + d_m t_k (t_k rounded, then one rounding
  // per operation) lies within 3 float steps of max(|o_m|, |d_m t_k|, |p_k|)
  // of the exact line: less than max_coord * 2^-22. The margin is 8 times that.
  const double t_max = (double(k_end) + 1.5) * delta;
  double max_coord = double(micro_res);
  for (int a = 0; a < 3; ++a)
    max_coord = std::max(max_coord, std::abs(double(micro_ray.origin[a])) + std::abs(double(micro_ray.dir[a])) * t_max);
  const double margin = max_coord * (1.0 / 524288.0);  // 2^-19
  // skip_box: the exit face lo + exit size at the margin inside, in steps.
  for (int a = 0; a < 3; ++a) {
    const double d = double(micro_ray.dir[a]), o = double(micro_ray.origin[a]);
    if (d == 0.0) {
      exit[a] = 0;
      scale[a] = 0;
      offset[a] = INFINITY;
      continue;
    }
    const double inv = 1.0 / (d * delta);
    exit[a] = d > 0 ? 1.0 : 0.0;
    scale[a] = inv;
    offset[a] = ((d > 0 ? -margin : margin) - o) * inv - 0.5;
  }
}

}  // namespace

FastSkipGrid::FastSkipGrid(const SceneModel& model) : res(model.fine_res()), micro_res(model.micro_res) {
  // SampleMarcher's region with the tiers: the object AABB's micro voxels, widened by one.
  const Vec3d lo = model.scene_box.lo.cast<double>();
  const Vec3d vs = model.micro_voxel_size().cast<double>();
  const double Rm = double(model.micro_res);
  Vec3d v_lo, v_hi;
  const Vec3d a_lo = (model.object_aabb.lo.cast<double>() - lo) / vs;
  const Vec3d a_hi = (model.object_aabb.hi.cast<double>() - lo) / vs;
  for (int a = 0; a < 3; ++a) {
    v_lo[a] = std::max(0.0, std::floor(a_lo[a]));
    v_hi[a] = std::min(Rm, std::ceil(a_hi[a]));
  }
  region = Box3d{lo + vs * (v_lo - Vec3d{1, 1, 1}), lo + vs * (v_hi + Vec3d{1, 1, 1})};

  build(model.occupancy[int(Tier::Fine)], model.occupancy[int(Tier::Micro)]);
  // Each occupied fine voxel's block and its coarse voxel's MLP.
  const size_t R = size_t(res);
  const int per_coarse = res / model.coarse_res();
  for (int fz = 0; fz < res; ++fz)
    for (int fy = 0; fy < res; ++fy)
      for (int fx = 0; fx < res; ++fx) {
        const size_t f = size_t(fx) + R * (size_t(fy) + R * size_t(fz));
        if (distance[f] != 0) continue;
        uint32_t* cell = fine_words.data() + kCellWords * f;
        cell[kCellBlock] = uint32_t(model.fine_to_block[linear_index(fx, fy, fz, res)]);
        cell[kCellMlp] = uint32_t(
            model.coarse_to_mlp[linear_index(fx / per_coarse, fy / per_coarse, fz / per_coarse, model.coarse_res())]);
      }
}

FastSkipGrid::FastSkipGrid(const Bitmap3& fine, const Bitmap3& micro) : res(fine.res()), micro_res(micro.res()) {
  if (micro_res != 4 * res) fail("FastSkipGrid: a micro grid of {} is not 4 times the fine grid of {}", micro_res, res);
  build(fine, micro);
}

void FastSkipGrid::build(const Bitmap3& fine, const Bitmap3& micro) {
  const size_t n = size_t(res) * res * res;
  distance.assign(n + 3, uint8_t(kMaxDistance));
  // Grow the occupied set by one fine voxel in every direction (a 3x3x3 cube,
  // three separable passes over rows of bits along x) per round: a voxel
  // reached in round r is at Chebyshev distance r.
  const size_t R = size_t(res), W = (R + 63) / 64, rows = R * R;
  const uint64_t last_mask = R % 64 ? (uint64_t(1) << (R % 64)) - 1 : ~uint64_t(0);
  std::vector<uint64_t> cur(rows * W, 0), tmp(rows * W), prev;
  for (size_t z = 0; z < R; ++z)
    for (size_t y = 0; y < R; ++y)
      for (size_t x = 0; x < R; ++x)
        if (fine.get(int(x), int(y), int(z))) {
          cur[(z * R + y) * W + x / 64] |= uint64_t(1) << (x % 64);
          distance[x + R * (y + R * z)] = 0;
        }
  for (int r = 1; r < kMaxDistance; ++r) {
    prev = cur;
    for (size_t row = 0; row < rows; ++row) {  // along x
      const uint64_t* c = cur.data() + row * W;
      uint64_t* t = tmp.data() + row * W;
      for (size_t w = 0; w < W; ++w) {
        const uint64_t up = (c[w] << 1) | (w > 0 ? c[w - 1] >> 63 : 0);
        const uint64_t down = (c[w] >> 1) | (w + 1 < W ? c[w + 1] << 63 : 0);
        t[w] = c[w] | up | down;
      }
      t[W - 1] &= last_mask;
    }
    for (size_t z = 0; z < R; ++z)  // along y
      for (size_t y = 0; y < R; ++y) {
        const uint64_t* c = tmp.data() + (z * R + y) * W;
        const uint64_t* lo = y > 0 ? c - W : c;
        const uint64_t* hi = y + 1 < R ? c + W : c;
        uint64_t* t = cur.data() + (z * R + y) * W;
        for (size_t w = 0; w < W; ++w) t[w] = c[w] | lo[w] | hi[w];
      }
    for (size_t z = 0; z < R; ++z) {  // along z
      const uint64_t* c = cur.data() + z * R * W;
      const uint64_t* lo = z > 0 ? c - R * W : c;
      const uint64_t* hi = z + 1 < R ? c + R * W : c;
      uint64_t* t = tmp.data() + z * R * W;
      for (size_t i = 0; i < R * W; ++i) t[i] = c[i] | lo[i] | hi[i];
    }
    cur.swap(tmp);
    bool grew = false;
    for (size_t row = 0; row < rows; ++row)
      for (size_t w = 0; w < W; ++w) {
        uint64_t fresh = cur[row * W + w] & ~prev[row * W + w];
        grew |= fresh != 0;
        while (fresh) {
          const size_t x = 64 * w + size_t(std::countr_zero(fresh));
          fresh &= fresh - 1;
          distance[row * R + x] = uint8_t(r);
        }
      }
    if (!grew) break;
  }

  fine_words.assign(kCellWords * n, 0);
  for (int fz = 0; fz < res; ++fz)
    for (int fy = 0; fy < res; ++fy)
      for (int fx = 0; fx < res; ++fx) {
        const size_t f = size_t(fx) + R * (size_t(fy) + R * size_t(fz));
        uint32_t* cell = fine_words.data() + kCellWords * f;
        cell[kCellBlock] = cell[kCellMlp] = uint32_t(-1);
        if (distance[f] != 0) continue;
        uint64_t m = 0;
        for (int i = 0; i < 64; ++i)
          if (micro.get(4 * fx + (i & 3), 4 * fy + ((i >> 2) & 3), 4 * fz + (i >> 4))) m |= uint64_t(1) << i;
        cell[0] = uint32_t(m);
        cell[1] = uint32_t(m >> 32);
      }

  // The micro gaps. Near the object (r <= kExactReach) only the shell of fine voxels
  // at distance r can hold the nearest occupied micro voxel below 4 r (those
  // nearer are empty, those farther are 4 r or more away); along an axis
  // where the shell voxel is r away its micro voxel l is 4 (r - 1) + l (or
  // + 3 - l) away, along the others less than 4 (r - 1). So the gap is
  // 4 (r - 1) + x for the least x in 0..3 at which some shell mask meets
  // the micro voxels within x of the near faces, or 4 r if none does.
  reach.assign(n + 3, 0);
  // near[kx + 3 ky + 9 kz][x]: the micro voxels within x of the near faces,
  // per axis kind k: 0 all four (the shell voxel is nearer than r along the
  // axis), 1 l <= x (r ahead), 2 l >= 3 - x (r behind).
  uint64_t near[27][4];
  for (int kind = 0; kind < 27; ++kind)
    for (int x = 0; x < 4; ++x) {
      uint32_t bits[3];
      for (int a = 0, k = kind; a < 3; ++a, k /= 3)
        bits[a] = k % 3 == 0 ? 0xFu : k % 3 == 1 ? (2u << x) - 1 : (0xFu << (3 - x)) & 0xFu;
      uint64_t m = 0;
      for (int i = 0; i < 64; ++i)
        if ((bits[0] >> (i & 3)) & (bits[1] >> ((i >> 2) & 3)) & (bits[2] >> (i >> 4)) & 1) m |= uint64_t(1) << i;
      near[kind][x] = m;
    }
  const auto kind_of = [](int d, int r) { return d == r ? 1 : d == -r ? 2 : 0; };
  for (int fz = 0; fz < res; ++fz)
    for (int fy = 0; fy < res; ++fy)
      for (int fx = 0; fx < res; ++fx) {
        const size_t f = size_t(fx) + R * (size_t(fy) + R * size_t(fz));
        const int r = distance[f];
        if (r == 0) continue;
        if (r > kExactReach) {
          reach[f] = uint8_t(4 * (r - 1));
          continue;
        }
        int best = 4;  // x, or 4: no shell mask within 3
        for (int dz = std::max(-r, -fz); dz <= std::min(r, res - 1 - fz); ++dz)
          for (int dy = std::max(-r, -fy); dy <= std::min(r, res - 1 - fy); ++dy)
            for (int dx = std::max(-r, -fx); dx <= std::min(r, res - 1 - fx); ++dx) {
              const size_t gi = size_t(fx + dx) + R * (size_t(fy + dy) + R * size_t(fz + dz));
              if (distance[gi] != 0) continue;  // also every voxel inside the shell
              const uint64_t m =
                  uint64_t(fine_words[kCellWords * gi]) | (uint64_t(fine_words[kCellWords * gi + 1]) << 32);
              const uint64_t* nm = near[kind_of(dx, r) + 3 * kind_of(dy, r) + 9 * kind_of(dz, r)];
              for (int x = 0; x < best; ++x)
                if (m & nm[x]) {
                  best = x;
                  break;
                }
            }
        reach[f] = uint8_t(4 * (r - 1) + best);
      }
}

FastMarcher::FastMarcher(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray) {
  set_up(model, skip, ray, micro_ray);
}

void FastMarcher::set_up(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray) {
  int64_t k = 0, k_end = -1;
  double exit[3] = {0, 0, 0}, scale[3] = {0, 0, 0}, offset[3] = {0, 0, 0};
  // The candidate range of SampleMarcher with the tiers: one step either side of the region.
  double t_near, t_far;
  if (!intersect_box(ray.origin, ray.dir, skip.region, t_near, t_far) || !(t_far >= 0) || !std::isfinite(t_far) ||
      !std::isfinite(t_near)) {
    assign(model, skip, micro_ray, k, k_end, exit, scale, offset);
    return;
  }
  const double delta = double(micro_ray.delta);
  // As SampleMarcher (floor and ceil of values below 2^62 after the checks above).
  const double first = std::min(std::max(t_near, 0.0) / delta - 0.5, 4e18), last = std::min(t_far / delta - 0.5, 4e18);
  k = std::max<int64_t>(0, int64_t(-ceil_small(-first)) - 1);
  k_end = int64_t(ceil_small(last)) + 1;
  jump_terms(skip.micro_res, micro_ray, k_end, exit, scale, offset);
  assign(model, skip, micro_ray, k, k_end, exit, scale, offset);
}

void FastMarcher::set_up_range(const FastSkipGrid& skip, const MicroRay& micro_ray, int64_t k, int64_t k_end) {
  double exit[3] = {0, 0, 0}, scale[3] = {0, 0, 0}, offset[3] = {0, 0, 0};
  if (k_end >= k) jump_terms(skip.micro_res, micro_ray, k_end, exit, scale, offset);
  assign(nullptr, skip, micro_ray, k, k_end, exit, scale, offset);
}

bool FastMarcher::next(MarchSample& s) {
  FastMarcher* self = this;
  int count = 0;
  bool ended = false;
  int32_t block = -1;
  fast_march_group(&self, 1, 1, &s, &block, &count, &ended);
  return count == 1;
}

}  // namespace edrnr
