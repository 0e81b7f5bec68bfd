// The traversal's fast position tests (thresholds instead of rounding each
// coordinate) against the rounded arithmetic they replace: micro voxels, cell
// exits and their position-evaluation counts must be identical.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <cmath>
#include <random>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/lfau.h"
#include "chip/numerics.h"
#include "chip/zorg.h"
#include "data/camera.h"

namespace edrnr::chip {
namespace {

// The formats tried: the chip's traversal float, binary32, narrower ones, one
// with subnormals and IEEE specials, and some without thresholds for every
// integer below Rm (p = 6 at Rm = 128; e3's largest value is below 16).
struct Case {
  FloatFormat format;
  int micro_res;
};
std::vector<Case> cases() {
  return {
      {ChipNumerics{}.traversal_float, 64},
      {ChipNumerics{}.traversal_float, 512},
      {FloatFormat(), 64},
      {FloatFormat(8, 11, false, FloatSpecials::Saturate), 32},
      {FloatFormat(5, 10, true, FloatSpecials::Ieee), 128},
      {FloatFormat(4, 6, false, FloatSpecials::Saturate), 64},
      {FloatFormat(4, 6, false, FloatSpecials::Saturate), 128},
      {FloatFormat(3, 8, false, FloatSpecials::Saturate), 32},
  };
}

// Random rays of the format: origins inside and around the grid, directions
// with some components zero or tiny (nearly parallel to a face).
std::vector<ChipRay> rays_for(const FloatFormat& f, int res, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<ChipRay> out;
  for (int i = 0; i < n; ++i) {
    Vec3d o{u(rng), u(rng), u(rng)};
    o = o * ((i % 3 == 0 ? 0.4 : 1.6) * res / length(o)) + Vec3d{res / 2.0, res / 2.0, res / 2.0};
    Vec3d d = normalize(Vec3d{res / 2.0 + u(rng) * res / 2, res / 2.0 + u(rng) * res / 2, res / 2.0} - o);
    if (i % 7 == 0) d.y = 0;
    if (i % 5 == 0) d.x = std::ldexp(u(rng), -12);
    if (i % 11 == 0) d.z = std::ldexp(u(rng), -30);
    out.push_back({f.round(o), f.round(d)});
  }
  return out;
}

// The old definition: round the coordinate, then take its micro voxel.
int rounded_micro(const RayMath& m, const ChipRay& r, int64_t k, int a) { return m.micro_index(m.coord(r, k, a)); }

void expect_same_micro(const RayMath& m, const ChipRay& r, int64_t k, uint64_t& checked) {
  const int res = m.micro_res();
  for (int a = 0; a < 3; ++a) {
    const int want = rounded_micro(m, r, k, a);
    ASSERT_EQ(m.micro_index_at(r, k, a), want) << m.format().name() << " axis " << a << " k " << k;
    for (int f : {want - 1, want, want + 1, want + 2, 0, -3, res, res + 5})
      ASSERT_EQ(m.micro_at_least(r, k, a, f), want >= f) << m.format().name() << " f " << f << " k " << k;
    ++checked;
  }
  ASSERT_EQ(m.micro_voxel_at(r, k), m.micro_voxel(m.point(r, k)));
}

TEST(TraversalSpeed, MicroVoxelsFromThresholdsMatchRounding) {
  uint64_t checked = 0;
  for (const Case& c : cases()) {
    for (double step : {1.0, 0.37}) {
      const RayMath m(c.format, step, c.micro_res);
      for (const ChipRay& r : rays_for(c.format, c.micro_res, 40, 3)) {
        for (int64_t k = 0; k < int64_t(4 * c.micro_res / step); k += 1 + k / 97) {
          expect_same_micro(m, r, k, checked);
          if (HasFatalFailure()) return;
        }
      }
    }
  }
  EXPECT_GT(checked, 100000u);
}

TEST(TraversalSpeed, SumsOnAndAroundEveryThreshold) {
  // Origins on a grid a quarter of the format's spacing fine around every
  // integer f of the grid: the midpoints between f and its neighbour below
  // (ties of the rounding) and the values next to them. The direction is zero
  // (the sum is the origin), or so small that the double sum rounds back to
  // the origin and only its exact error tells the side.
  uint64_t checked = 0, ties = 0;
  for (const Case& c : cases()) {
    const RayMath m(c.format, 1.0, c.micro_res);
    const int p = c.format.significand_bits();
    for (int f = 1; f < c.micro_res; ++f) {
      const int e = int(std::floor(std::log2(double(f))));
      const double fine = std::ldexp(1.0, e - p - 2);
      for (int j = -12; j <= 12; ++j) {
        const double o = f + j * fine;
        for (double o2 : {o, std::nextafter(o, 0.0), std::nextafter(o, 1e9)}) {
          for (double d : {0.0, std::ldexp(1.0, -70), -std::ldexp(1.0, -70)}) {
            const ChipRay r{{o2, 0.5, 0.5}, {d, 0, 0}};
            expect_same_micro(m, r, 3, checked);
            if (HasFatalFailure()) return;
            ties += (c.format.round(o2) != c.format.round(std::nextafter(o2, 0.0)));
          }
        }
      }
    }
  }
  EXPECT_GT(checked, 100000u);
  EXPECT_GT(ties, 1000u);  // rounding boundaries were among the origins
}

// The cell exit search as it was, rounding every position it evaluates: a
// guess from the exit distance, checked at the guess and one neighbour, then
// bisection; `evals` counts every evaluation.
int64_t reference_exit(const RayMath& m, const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell,
                       uint64_t& evals) {
  int64_t best = k_end;
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) continue;
    const int first = c[a] * cell, last = first + cell - 1;
    auto outside = [&](int64_t k) {
      ++evals;
      const int mi = rounded_micro(m, r, k, a);
      return mi < first || mi > last;
    };
    auto bisect = [&](int64_t lo, int64_t hi) {
      while (lo < hi) {
        const int64_t mid = lo + (hi - lo) / 2;
        if (outside(mid))
          hi = mid;
        else
          lo = mid + 1;
      }
      return lo;
    };
    const double face = d > 0 ? double((c[a] + 1) * cell) : double(c[a] * cell);
    if ((d > 0 && face >= double(m.micro_res())) || (d < 0 && face <= 0.0)) continue;
    const int64_t lo = k0 + 1, hi = best;
    if (lo >= hi) break;
    const double guess = std::ceil((face - r.origin[a]) / (d * m.step()) - 0.5);
    const int64_t g = std::isfinite(guess) ? int64_t(std::clamp(guess, double(lo), double(hi - 1))) : hi - 1;
    int64_t e;
    if (outside(g))
      e = (g == lo || !outside(g - 1)) ? g : bisect(lo, g - 1);
    else
      e = (g + 1 >= hi || outside(g + 1)) ? g + 1 : bisect(g + 2, hi);
    best = std::min(best, e);
  }
  return best;
}

TEST(TraversalSpeed, CellExitsAndTheirCountsMatchTheRoundedSearch) {
  uint64_t exits = 0, total_evals = 0;
  for (const Case& c : cases()) {
    for (double step : {1.0, 0.37}) {
      const RayMath m(c.format, step, c.micro_res);
      const Vec3d lo{0, 0, 0}, hi{double(c.micro_res), double(c.micro_res), double(c.micro_res)};
      for (const ChipRay& r : rays_for(c.format, c.micro_res, 40, 9)) {
        const KInterval run = m.box_interval(r, lo, hi);
        for (int cell : {1, 2, 4, 32}) {
          // From each candidate of the run, and with the run cut short.
          for (int64_t k = run.begin; k < run.end; k += 1 + (k - run.begin) / 13) {
            const Vec3i cv = m.cell(m.point(r, k), cell);
            for (int64_t end : {run.end, std::min(run.end, k + 3)}) {
              uint64_t got_evals = 0, want_evals = 0;
              const int64_t want = reference_exit(m, r, k, end, cv, cell, want_evals);
              ASSERT_EQ(m.cell_exit(r, k, end, cv, cell, &got_evals), want)
                  << c.format.name() << " Rm " << c.micro_res << " cell " << cell << " k " << k;
              ASSERT_EQ(got_evals, want_evals) << c.format.name() << " cell " << cell << " k " << k;
              ++exits;
              total_evals += want_evals;
            }
          }
        }
      }
    }
  }
  EXPECT_GT(exits, 20000u);
  EXPECT_GT(total_evals, 2 * exits / 3);
}

TEST(TraversalSpeed, CellExitsWithKeptCrossingsMatchTheRoundedSearch) {
  // Rays walked as the FTU walks them, one memo of face crossings per ray
  // shared by cells of two sizes: each cell of `outer` micro voxels is left
  // at its exit, and inside it cells of `inner` are stepped through with the
  // outer exit as their end (the memo's k_limit stays the run's end), some
  // of them cut short.
  uint64_t exits = 0, total_evals = 0;
  for (const Case& c : cases()) {
    for (double step : {1.0, 0.37}) {
      const RayMath m(c.format, step, c.micro_res);
      const Vec3d lo{0, 0, 0}, hi{double(c.micro_res), double(c.micro_res), double(c.micro_res)};
      for (const ChipRay& r : rays_for(c.format, c.micro_res, 40, 21)) {
        const KInterval run = m.box_interval(r, lo, hi);
        for (auto [outer, inner] : {std::pair{4, 2}, std::pair{32, 4}, std::pair{2, 1}}) {
          RayMath::ExitMemo memo{};
          int n = 0;
          for (int64_t k = run.begin; k < run.end;) {
            uint64_t got_evals = 0, want_evals = 0;
            const Vec3i cv = m.cell(m.point(r, k), outer);
            const int64_t want = reference_exit(m, r, k, run.end, cv, outer, want_evals);
            ASSERT_EQ(m.cell_exit(r, k, run.end, cv, outer, &got_evals, memo, run.end), want)
                << c.format.name() << " Rm " << c.micro_res << " cell " << outer << " k " << k;
            ASSERT_EQ(got_evals, want_evals) << c.format.name() << " cell " << outer << " k " << k;
            ++exits;
            total_evals += want_evals;
            for (int64_t j = k; j < want;) {
              const int64_t end = (++n % 5 == 0) ? std::min(want, j + 2) : want;
              const Vec3i leaf = m.cell(m.point(r, j), inner);
              uint64_t got = 0, expected = 0;
              const int64_t e = reference_exit(m, r, j, end, leaf, inner, expected);
              ASSERT_EQ(m.cell_exit(r, j, end, leaf, inner, &got, memo, run.end), e)
                  << c.format.name() << " Rm " << c.micro_res << " cell " << inner << " k " << j;
              ASSERT_EQ(got, expected) << c.format.name() << " cell " << inner << " k " << j;
              ++exits;
              total_evals += expected;
              j = e;
              if (e == end && end < want) ++j;  // skip a candidate: the memo must not depend on the order
            }
            k = want;
          }
        }
      }
    }
  }
  EXPECT_GT(exits, 20000u);
  EXPECT_GT(total_evals, exits / 2);
}

TEST(TraversalSpeed, ThresholdsOfArbitraryValuesMatchRounding) {
  // find_threshold against round() itself on sums around the value: exact
  // products and sums near the threshold, ties included.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  uint64_t checked = 0;
  for (const Case& c : cases()) {
    const RayMath m(c.format, 1.0, c.micro_res);
    const FloatFormat& f = c.format;
    std::vector<double> values{0.0, 1.0, double(c.micro_res), 0.5, -1.0, f.max_finite(), f.min_positive()};
    for (int i = 0; i < 40; ++i) values.push_back(f.round(std::ldexp(u(rng), int(u(rng) * 3))));
    for (double v : values) {
      for (bool strict : {false, true}) {
        RayMath::Threshold th;
        const bool found = m.find_threshold(v, strict, th);
        auto passes = [&](double r) { return strict ? r > v : r >= v; };
        if (!found) {
          EXPECT_FALSE(passes(f.fma(1.0, f.max_finite(), 0.0))) << f.name() << " v " << v;
          continue;
        }
        // Sums prod + o: o on a fine grid around the threshold, prod tiny
        // (the double sum rounds back to o) or zero.
        const double step = std::max(std::fabs(th.mid) * 0x1p-30, 0x1p-1000);
        for (int j = -20; j <= 20; ++j) {
          const double o = th.mid + j * step;
          for (double o2 : {o, std::nextafter(o, -1e300), std::nextafter(o, 1e300)}) {
            if (!std::isfinite(o2)) continue;  // past the largest double (sums are finite)
            for (double d : {0.0, 0x1p-80, -0x1p-80}) {
              const double want = f.fma(d, 0.5, o2);  // the format's fused multiply-add
              const double prod = d * 0.5;
              ASSERT_EQ(RayMath::sum_at_least(prod, o2, prod + o2, th), passes(want))
                  << f.name() << " v " << v << " strict " << strict << " o " << o2 << " d " << d;
              ++checked;
            }
          }
        }
      }
    }
  }
  EXPECT_GT(checked, 100000u);
}

TEST(TraversalSpeed, PreparedBoxRunsAndCountsMatchTheRoundedSearch) {
  uint64_t rays = 0;
  for (const Case& c : cases()) {
    for (double step : {1.0, 0.37}) {
      const RayMath m(c.format, step, c.micro_res);
      const double R = c.micro_res;
      const Vec3d boxes[][2] = {{{0, 0, 0}, {R, R, R}}, {{3, 5, 0}, {R - 7, R, R / 2}}, {{2.5, 1.25, 4}, {9.75, R, R}}};
      for (const auto& b : boxes) {
        const Vec3d lo = c.format.round(b[0]), hi = c.format.round(b[1]);
        const RayMath::PreparedBox box = m.prepare_box(lo, hi);
        for (const ChipRay& r : rays_for(c.format, c.micro_res, 60, 21)) {
          uint64_t got_evals = 0, want_evals = 0;
          const KInterval want = m.box_interval(r, lo, hi, &want_evals);  // every position rounded
          const KInterval got = m.box_interval(r, box, &got_evals);
          ASSERT_EQ(got.begin, want.begin) << c.format.name();
          ASSERT_EQ(got.end, want.end) << c.format.name();
          ASSERT_EQ(got_evals, want_evals);
          ++rays;
        }
      }
    }
  }
  EXPECT_GT(rays, 2000u);
}

// The LFAU as three comparator stages, axis by axis (EN1, EN2, EN3).
LfauSelection reference_lfau(const std::array<Vec3i, kRaysPerPacket>& voxel, uint8_t active, const Vec3i& sign,
                             bool lag_first) {
  LfauSelection out;
  if (active == 0) return out;
  uint8_t cand = active;
  if (lag_first) {
    for (int axis = 0; axis < 3; ++axis) {
      int best = 0;
      bool first = true;
      for (int r = 0; r < kRaysPerPacket; ++r)
        if ((cand >> r & 1) && (first || voxel[size_t(r)][axis] * sign[axis] < best)) {
          best = voxel[size_t(r)][axis] * sign[axis];
          first = false;
        }
      uint8_t keep = 0;
      for (int r = 0; r < kRaysPerPacket; ++r)
        if ((cand >> r & 1) && voxel[size_t(r)][axis] * sign[axis] == best) keep |= uint8_t(1u << r);
      cand = keep;
    }
  }
  int lead = 0;
  while (!(cand >> lead & 1)) ++lead;
  out.voxel = voxel[size_t(lead)];
  for (int r = 0; r < kRaysPerPacket; ++r)
    if ((active >> r & 1) && voxel[size_t(r)] == out.voxel) out.selected_mask |= uint8_t(1u << r);
  return out;
}

TEST(TraversalSpeed, LfauSelectionMatchesTheStagedComparators) {
  std::mt19937 rng(8);
  int selections = 0;
  for (int range : {2, 5, 40, 3000000}) {  // few distinct voxels (ties) to indices too large to pack
    std::uniform_int_distribution<int> v(range > 1000 ? -range : 0, range);
    for (int i = 0; i < 4000; ++i) {
      std::array<Vec3i, kRaysPerPacket> voxel;
      for (Vec3i& x : voxel) x = {v(rng), v(rng), v(rng)};
      const Vec3i sign{rng() % 2 ? 1 : -1, rng() % 2 ? 1 : -1, rng() % 2 ? 1 : -1};
      const uint8_t active = uint8_t(rng() % 16);
      for (bool lag_first : {true, false}) {
        const LfauSelection got = lfau_select(voxel, active, sign, lag_first);
        const LfauSelection want = reference_lfau(voxel, active, sign, lag_first);
        ASSERT_EQ(got.selected_mask, want.selected_mask) << "range " << range << " i " << i;
        if (active) {
          ASSERT_EQ(got.voxel, want.voxel);
        }
        ++selections;
      }
    }
  }
  EXPECT_EQ(selections, 32000);
}

// ZORG's direction datapath as the formula reads, every product computed per
// pixel.
GeneratedRay reference_ray(const Camera& cam, const Box3f& box, int micro_res, const FloatFormat& rf,
                           const FloatFormat& tf, int x, int y) {
  double rot[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rot[i][j] = rf.round(cam.c2w[size_t(4 * i + j)]);
  const double u = rf.round(x + 0.5), v = rf.round(y + 0.5);
  const double d_cam[3] = {rf.div(rf.sub(u, rf.round(cam.cx)), rf.round(cam.fx)),
                           rf.neg(rf.div(rf.sub(v, rf.round(cam.cy)), rf.round(cam.fy))), -1.0};
  Vec3d w;
  for (int i = 0; i < 3; ++i)
    w[i] = rf.add(rf.add(rf.mul(rot[i][0], d_cam[0]), rf.mul(rot[i][1], d_cam[1])), rf.mul(rot[i][2], d_cam[2]));
  const double len = rf.sqrt(rf.add(rf.add(rf.mul(w.x, w.x), rf.mul(w.y, w.y)), rf.mul(w.z, w.z)));
  GeneratedRay g;
  const Vec3f size = box.size();
  const Vec3d o = cam.origin();
  for (int a = 0; a < 3; ++a) {
    g.world_dir[a] = len > 0 ? rf.div(w[a], len) : 0.0;
    g.ray.dir[a] = tf.round(rf.mul(g.world_dir[a], rf.round(double(size.x) / double(size[a]))));
    const double scale = rf.round(double(micro_res) / double(size[a]));
    g.ray.origin[a] = tf.round(rf.mul(rf.sub(rf.round(o[a]), rf.round(double(box.lo[a]))), scale));
  }
  return g;
}

// A 37x23 camera rotated about an oblique axis, its origin outside the box.
Camera oblique_camera() {
  Camera cam;
  cam.width = 37;
  cam.height = 23;
  cam.fx = 41.3;
  cam.fy = 40.9;
  cam.cx = 18.2;
  cam.cy = 11.7;
  const double c = std::cos(0.7), s = std::sin(0.7);
  cam.c2w = {c, 0, s, 2.1, s * s, c, -s * c, -1.3, -s * c, s, c * c, 3.7, 0, 0, 0, 1};
  return cam;
}

TEST(TraversalSpeed, RayGenerationMatchesThePerPixelFormula) {
  const ChipNumerics n;
  const Camera cam = oblique_camera();
  const Box3f box{{-1.5f, -1.f, -1.25f}, {1.5f, 1.f, 1.25f}};
  const RayGenerator gen(cam, box, 128, n.ray_float, n.traversal_float);
  int rays = 0;
  // Every pixel of the image, and some outside it (computed without the
  // per-column and per-row tables).
  for (int y = -3; y < cam.height + 4; ++y) {
    for (int x = -3; x < cam.width + 4; ++x) {
      const GeneratedRay got = gen.generate(x, y);
      const GeneratedRay want = reference_ray(cam, box, 128, n.ray_float, n.traversal_float, x, y);
      ASSERT_EQ(got.world_dir, want.world_dir) << x << ", " << y;
      ASSERT_EQ(got.ray.dir, want.ray.dir) << x << ", " << y;
      ASSERT_EQ(got.ray.origin, want.ray.origin) << x << ", " << y;
      ++rays;
    }
  }
  EXPECT_EQ(rays, (37 + 7) * (23 + 7));
}

// The packets' rays (four in SIMD lanes, one at a time where a pixel is
// outside the image or a value leaves the formats' normal range) against the
// per-pixel formula, on every SIMD target: an oblique camera, and one looking
// down an axis with its principal point on a pixel centre, whose rays there
// have exactly zero components (the one-at-a-time path). Every subset of a
// quad's lanes is valid somewhere, and quads reach past the image's edges.
TEST(TraversalSpeed, PacketRaysMatchThePerPixelFormulaOnEveryTarget) {
  const ChipNumerics n;
  const Box3f box{{-1.5f, -1.f, -1.25f}, {1.5f, 1.f, 1.25f}};
  const Camera oblique = oblique_camera();
  Camera straight = oblique;
  straight.cx = 10.5;  // pixel 10's centre: d_cam.x = 0
  straight.cy = 7.5;
  straight.c2w = {1, 0, 0, 0.2, 0, 1, 0, -0.1, 0, 0, 1, 4.0, 0, 0, 0, 1};
  uint64_t zero_components = 0;
  for (const Camera& cam : {oblique, straight}) {
    const RayGenerator gen(cam, box, 128, n.ray_float, n.traversal_float);
    for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
      hwy::SetSupportedTargetsForTest(target);
      uint32_t subset = 1;
      for (int qy = 0; 2 * qy < cam.height + 2; ++qy) {
        for (int qx = 0; 2 * qx < cam.width + 2; ++qx) {
          PixelQuad quad;
          for (int r = 0; r < kRaysPerPacket; ++r) {
            quad.x[size_t(r)] = uint16_t(2 * qx + (r & 1));
            quad.y[size_t(r)] = uint16_t(2 * qy + (r >> 1));
          }
          quad.valid_mask = uint8_t(subset);
          subset = subset % 15 + 1;
          const auto got = gen.generate(quad);
          for (int r = 0; r < kRaysPerPacket; ++r) {
            if (!(quad.valid_mask >> r & 1)) continue;
            const GeneratedRay want =
                reference_ray(cam, box, 128, n.ray_float, n.traversal_float, quad.x[size_t(r)], quad.y[size_t(r)]);
            const GeneratedRay& g = got[size_t(r)];
            ASSERT_EQ(g.world_dir, want.world_dir) << quad.x[size_t(r)] << ", " << quad.y[size_t(r)];
            ASSERT_EQ(g.ray.dir, want.ray.dir) << quad.x[size_t(r)] << ", " << quad.y[size_t(r)];
            ASSERT_EQ(g.ray.origin, want.ray.origin) << quad.x[size_t(r)] << ", " << quad.y[size_t(r)];
            zero_components += want.world_dir.x == 0.0 || want.world_dir.y == 0.0;
          }
        }
      }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
  EXPECT_GT(zero_components, 0u);
}

}  // namespace
}  // namespace edrnr::chip
