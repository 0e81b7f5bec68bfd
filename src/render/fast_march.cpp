#include "render/fast_march.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "model/mlp.h"

namespace edrnr {
namespace {

// micro_voxel_of (model/mlp.h) without a floor call: for the non-negative
// coordinates it accepts, truncation is floor.
inline bool voxel_of(const Vec3f& p, int micro_res, float hi, Vec3i& v) {
  if (!(p.x >= 0.f && p.x <= hi && p.y >= 0.f && p.y <= hi && p.z >= 0.f && p.z <= hi)) return false;
  v.x = std::min(int(p.x), micro_res - 1);
  v.y = std::min(int(p.y), micro_res - 1);
  v.z = std::min(int(p.z), micro_res - 1);
  return true;
}

// ceil(x) for |x| < 2^62 without a library call.
inline double ceil_small(double x) {
  const double t = double(int64_t(x));  // toward zero
  return t < x ? t + 1.0 : t;
}

}  // namespace

FastSkipGrid::FastSkipGrid(const SceneModel& model) : res(model.fine_res()) {
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

  const Bitmap3& fine = model.occupancy[int(Tier::Fine)];
  const size_t n = size_t(res) * res * res;
  distance.assign(n, uint8_t(kMaxDistance));
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

  const Bitmap3& micro = model.occupancy[int(Tier::Micro)];
  const int fr = res;
  micro_mask.assign(model.block_count(), 0);
  for (size_t b = 0; b < model.block_count(); ++b) {
    const uint32_t f = model.block_fine_index[b];
    const int fx = int(f % uint32_t(fr)), fy = int(f / uint32_t(fr) % uint32_t(fr)), fz = int(f / uint32_t(fr * fr));
    uint64_t m = 0;
    for (int i = 0; i < 64; ++i)
      if (micro.get(4 * fx + (i & 3), 4 * fy + ((i >> 2) & 3), 4 * fz + (i >> 4))) m |= uint64_t(1) << i;
    micro_mask[b] = m;
  }
}

FastMarcher::FastMarcher(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray)
    : model_(&model), skip_(&skip), ray_(micro_ray) {
  // The candidate range of SampleMarcher with the tiers: one step either side of the region.
  double t_near, t_far;
  if (!intersect_box(ray.origin, ray.dir, skip.region, t_near, t_far) || !(t_far >= 0) || !std::isfinite(t_far) ||
      !std::isfinite(t_near))
    return;
  const double delta = double(ray_.delta);
  // As SampleMarcher (floor and ceil of values below 2^62 after the checks above).
  const double first = std::min(std::max(t_near, 0.0) / delta - 0.5, 4e18), last = std::min(t_far / delta - 0.5, 4e18);
  k_ = std::max<int64_t>(0, int64_t(-ceil_small(-first)) - 1);
  k_end_ = int64_t(ceil_small(last)) + 1;
  // A step of at least half a micro voxel along the ray (in micro units).
  const double step_micro = delta * std::sqrt(double(ray_.dir.x) * ray_.dir.x + double(ray_.dir.y) * ray_.dir.y +
                                              double(ray_.dir.z) * ray_.dir.z);
  small_step_ = step_micro >= 0.5;
  // A candidate's float point o_m + d_m t_k (t_k rounded, then one rounding
  // per operation) lies within 3 float steps of max(|o_m|, |d_m t_k|, |p_k|)
  // of the exact line: less than scale * 2^-22. The margin is 8 times that.
  const double t_max = (double(k_end_) + 1.5) * delta;
  double scale = double(model.micro_res);
  for (int a = 0; a < 3; ++a)
    scale = std::max(scale, std::abs(double(ray_.origin[a])) + std::abs(double(ray_.dir[a])) * t_max);
  margin_ = scale * (1.0 / 524288.0);  // 2^-19
  // skip_box: the exit face lo + exit_ size at margin_ inside, in steps.
  for (int a = 0; a < 3; ++a) {
    const double d = double(ray_.dir[a]), o = double(ray_.origin[a]);
    if (d == 0.0) {
      exit_[a] = 0;
      scale_[a] = 0;
      offset_[a] = INFINITY;
      continue;
    }
    const double inv = 1.0 / (d * delta);
    exit_[a] = d > 0 ? 1.0 : 0.0;
    scale_[a] = inv;
    offset_[a] = ((d > 0 ? -margin_ : margin_) - o) * inv - 0.5;
  }
}

uint64_t FastMarcher::mask_from_bitmap(const Vec3i& f) const {
  const Bitmap3& micro = model_->occupancy[int(Tier::Micro)];
  uint64_t m = 0;
  for (int i = 0; i < 64; ++i)
    if (micro.get(4 * f.x + (i & 3), 4 * f.y + ((i >> 2) & 3), 4 * f.z + (i >> 4))) m |= uint64_t(1) << i;
  return m;
}

FastMarcher::Step FastMarcher::step(MarchSample& s) {
  if (k_ > k_end_) return Step::End;
  const int R = model_->micro_res;
  const int64_t k = k_;
  const Vec3f p = ray_.point(k);
  Vec3i v;
  if (!voxel_of(p, R, float(R), v)) {
    k_ = k + 1;
    return Step::More;
  }
  const Vec3i f{v.x >> 2, v.y >> 2, v.z >> 2};
  if (!(f == fine_)) {
    ++checks_;
    const int r = skip_->at(f.x, f.y, f.z);
    if (r > 0) {  // the cube of fine voxels within r - 1 is empty
      const Vec3i lo{4 * (f.x - r + 1), 4 * (f.y - r + 1), 4 * (f.z - r + 1)};
      k_ = skip_box(k, lo, 4 * (2 * r - 1));
      return Step::More;
    }
    fine_ = f;
    block_ = model_->fine_to_block[linear_index(f.x, f.y, f.z, skip_->res)];
    // An occupied fine voxel without a block (the model then breaks its
    // invariants) reads its micro voxels from the bitmap.
    mask_ = block_ >= 0 ? skip_->micro_mask[size_t(block_)] : mask_from_bitmap(f);
  }
  // Leaf cell and micro voxel from the fine voxel's mask. Empty ones hold a
  // candidate or two (at the usual step of one micro voxel): stepping to the
  // next candidate is cheaper than computing and checking the exit, and
  // skips nothing.
  const int lx = v.x & 3, ly = v.y & 3, lz = v.z & 3;
  ++checks_;
  constexpr uint64_t kLeafCell = 0x330033;  // micro voxels (0..1, 0..1, 0..1) of a fine voxel
  if (!(mask_ & (kLeafCell << ((lx & 2) + 4 * (ly & 2) + 16 * (lz & 2))))) {
    k_ = small_step_ ? k + 1 : skip_box(k, {v.x & ~1, v.y & ~1, v.z & ~1}, 2);
    return Step::More;
  }
  ++checks_;
  if (!((mask_ >> (lx + 4 * ly + 16 * lz)) & 1)) {
    k_ = small_step_ ? k + 1 : skip_box(k, v, 1);
    return Step::More;
  }
  s.k = k;
  s.p_micro = p;
  s.voxel = v;
  k_ = k + 1;
  return Step::Sample;
}

bool FastMarcher::next(MarchSample& s) {
  for (;;) {
    const Step st = step(s);
    if (st == Step::Sample) return true;
    if (st == Step::End) return false;
  }
}

void fast_march_group(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks,
                      int* counts, bool* ended) {
  // The marchers' iterations interleaved: their dependency chains (point,
  // voxel, lookup, jump) are independent, so the CPU overlaps them.
  int active = 0;
  bool done[kFastMarchGroup];
  for (int i = 0; i < n; ++i) {
    counts[i] = 0;
    ended[i] = false;
    done[i] = limit <= 0;
    active += !done[i];
  }
  while (active > 0) {
    for (int i = 0; i < n; ++i) {
      if (done[i]) continue;
      FastMarcher& m = *marchers[i];
      const size_t at = size_t(i) * size_t(limit) + size_t(counts[i]);
      const FastMarcher::Step st = m.step(samples[at]);
      if (st == FastMarcher::Step::Sample) {
        blocks[at] = m.block();
        if (++counts[i] == limit) {
          done[i] = true;
          --active;
        }
      } else if (st == FastMarcher::Step::End) {
        ended[i] = done[i] = true;
        --active;
      }
    }
  }
}

}  // namespace edrnr
