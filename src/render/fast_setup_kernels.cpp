// Highway kernel of the fast renderer's ray set-up (render/fast_march.h:
// fast_setup_rays); compiled once per SIMD target (hwy/foreach_target.h) and
// picked at run time (HWY_DYNAMIC_DISPATCH).
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "render/fast_march.h"
#include "render/fast_march_grid.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/fast_setup_kernels.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
using fast_march_detail::FineIndex;
using fast_march_detail::Grid;
using fast_march_detail::ReachLo;
using fast_march_detail::VoxelOf;

// std::max and std::min of doubles, lane by lane with their exact semantics
// (the first operand unless the comparison says otherwise).
template <class V>
HWY_INLINE V StdMax(V a, V b) {
  return hn::IfThenElse(hn::Lt(a, b), b, a);
}
template <class V>
HWY_INLINE V StdMin(V a, V b) {
  return hn::IfThenElse(hn::Lt(b, a), b, a);
}

// What SetupRays does in lanes after the set-up, for one marcher: the
// march's steps (Advance) up to a candidate whose reach is below kFastJumpReach,
// whose vector test is then left to the march without a second lookup
// (dense).
void Approach(FastMarcher::State& st, const Grid& g) {
  while (st.k <= st.k_end) {
    Vec3i v;
    if (!VoxelOf(st.ray.point(st.k), g, v)) {
      ++st.k;
      continue;
    }
    const int e = g.reach[FineIndex(v, g.fine_res)];
    ++st.checks;
    if (e < kFastJumpReach) {
      st.dense = true;
      return;
    }
    st.k = st.skip_box(st.k, ReachLo(v, e), 4 + 2 * e);
  }
}

// A mask of 32-bit lanes as the mask of the 64-bit lanes of the same count.
template <class DD, class DI32, class M>
HWY_INLINE auto WidenMask(DD dd, DI32 di32, M m) {
  const hn::RebindToSigned<DD> di64;
  return hn::MaskFromVec(hn::BitCast(dd, hn::PromoteTo(di64, hn::VecFromMask(di32, m))));
}

// A ray the lanes leave alone (a zero or tiny direction component, or
// candidate indices from 2^51 on): FastMarcher::set_up and the march's
// first steps, its direction and its AABB count, in scalar code.
void SetUpAlone(const SceneModel& model, const FastSkipGrid& skip, const Camera& cam, float delta, const Box3d& aabb,
                int px, int py, const Grid& grid, FastMarcher& fm, float& dx, float& dy, float& dz, bool& hit_aabb) {
  const Ray ray = cam.pixel_ray(px, py);
  fm.set_up(model, skip, ray, make_micro_ray(model, ray, delta));
  const bool had_candidates = !fm.empty();
  Approach(fm.state(), grid);
  dx = float(ray.dir.x);
  dy = float(ray.dir.y);
  dz = float(ray.dir.z);
  double t_near, t_far;
  hit_aabb = had_candidates && intersect_box(ray.origin, ray.dir, aabb, t_near, t_far) && t_far >= 0;
}

void SetupRays(const SceneModel& model, const FastSkipGrid& skip, const Camera& cam, float delta, const Box3d& aabb,
               int x0, int y0, int tw, int n, const double* t_start, FastMarcher* marchers, float* dx, float* dy,
               float* dz, bool* hit_aabb) {
  using DD = hn::ScalableTag<double>;
  using VD = hn::Vec<DD>;
  const DD dd;
  const hn::Rebind<float, DD> dfh;
  const hn::Rebind<int32_t, DD> di32;
  using VF = hn::Vec<decltype(dfh)>;
  using VI = hn::Vec<decltype(di32)>;
  const int32_t* reach = reinterpret_cast<const int32_t*>(skip.reach.data());  // 32-bit reads at byte offsets
  const float grid_hi = float(model.micro_res);
  Grid grid;
  grid.words = skip.fine_words.data();
  grid.reach = skip.reach.data();
  grid.micro_res = model.micro_res;
  grid.fine_res = skip.res;
  grid.hi = grid_hi;
  constexpr size_t kMax = HWY_MAX_BYTES / sizeof(double);
  const size_t L = hn::Lanes(dd);
  // Per camera and model: the ray origin, its micro-unit form and the
  // micro scale (make_micro_ray's operations), the boxes relative to it.
  const Vec3d o = cam.origin();
  const MicroRay m0 = make_micro_ray(model, Ray{o, Vec3d{0, 0, 1}}, delta);
  const Vec3d size = model.scene_box.size().cast<double>();
  const double R = double(model.micro_res);
  const double mscale[3] = {R / size.x, R / size.y, R / size.z};
  const double ddelta = double(delta);
  double rlo[3], rhi[3], alo[3], ahi[3];
  for (int a = 0; a < 3; ++a) {
    rlo[a] = skip.region.lo[a] - o[a];
    rhi[a] = skip.region.hi[a] - o[a];
    alo[a] = aabb.lo[a] - o[a];
    ahi[a] = aabb.hi[a] - o[a];
  }
  const VD one = hn::Set(dd, 1.0), zero = hn::Zero(dd);
  const VD c2w_z[3] = {hn::Set(dd, cam.c2w[2] * -1.0), hn::Set(dd, cam.c2w[6] * -1.0), hn::Set(dd, cam.c2w[10] * -1.0)};
  const VD half = hn::Set(dd, 0.5), vdelta = hn::Set(dd, ddelta);
  double om[3];  // the micro origin as doubles
  for (int a = 0; a < 3; ++a) om[a] = double(m0.origin[a]);
  alignas(64) double u[kMax], v[kMax], ts[kMax];
  // The march's terms per lane; zeroed once, as vectors where no lane can
  // have a sample leave them unwritten (and unread).
  alignas(64) double exit[3][kMax] = {}, scale[3][kMax] = {}, offset[3][kMax] = {}, kk[3][kMax] = {};
  alignas(64) double flags[3][kMax];  // per lane: valid (0), set_up takes it over (1), dense (2)
  alignas(64) float dm[3][kMax];
  for (int r0 = 0; r0 < n; r0 += int(L)) {
    // Lanes past the last ray repeat it. One division per vector: the
    // pixel of ray r0, then stepped along the row.
    int ry = r0 / tw, rx = r0 - ry * tw;
    // Whether no ray of the vector can have a sample (every start at +inf:
    // no occupied fine voxel projects onto their cells): then only the
    // direction and the AABB count are made, and the marchers left empty.
    bool none = t_start != nullptr;
    for (size_t l = 0; l < L; ++l) {
      const int r = std::min(r0 + int(l), n - 1);
      none = none && std::isinf(t_start[r]);
      u[l] = double(x0 + rx) + 0.5;
      v[l] = double(y0 + ry) + 0.5;
      ts[l] = t_start ? std::max(0.0, std::min(t_start[r], 1e300)) : 0.0;
      if (r + 1 < n && ++rx == tw) {
        rx = 0;
        ++ry;
      }
    }
    // Camera::ray_at: the camera-space direction, rotated, normalized.
    const VD cx = hn::Div(hn::Sub(hn::Load(dd, u), hn::Set(dd, cam.cx)), hn::Set(dd, cam.fx));
    const VD cy = hn::Div(hn::Neg(hn::Sub(hn::Load(dd, v), hn::Set(dd, cam.cy))), hn::Set(dd, cam.fy));
    VD d[3];
    for (int a = 0; a < 3; ++a)
      d[a] = hn::Add(hn::Add(hn::Mul(hn::Set(dd, cam.c2w[4 * a]), cx), hn::Mul(hn::Set(dd, cam.c2w[4 * a + 1]), cy)),
                     c2w_z[a]);
    const VD len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(d[0], d[0]), hn::Mul(d[1], d[1])), hn::Mul(d[2], d[2])));
    // Lanes that set_up handles: a zero or tiny component (intersect_box's
    // special case, or a micro component that rounds to 0).
    auto special = hn::FirstN(dd, 0);
    VD tn = hn::Set(dd, -INFINITY), tf = hn::Set(dd, INFINITY);
    VD an = tn, af = tf;
    VD dmd[3];
    VF fdir[3];
    VF fdir_unit[3];  // the unit direction as floats
    for (int a = 0; a < 3; ++a) {
      d[a] = hn::Div(d[a], len);
      fdir_unit[a] = hn::DemoteTo(dfh, d[a]);
      // make_micro_ray: the direction in micro units, rounded to float.
      const auto f = hn::DemoteTo(dfh, hn::Mul(d[a], hn::Set(dd, mscale[a])));
      hn::Store(f, dfh, dm[a]);
      fdir[a] = f;
      dmd[a] = hn::PromoteTo(dd, f);
      special = hn::Or(special, hn::Or(hn::Lt(hn::Abs(d[a]), hn::Set(dd, 0x1p-500)), hn::Eq(dmd[a], zero)));
      // intersect_box with the region and with the AABB.
      const VD ia = hn::Div(one, d[a]);
      VD t0 = hn::Mul(hn::Set(dd, rlo[a]), ia), t1 = hn::Mul(hn::Set(dd, rhi[a]), ia);
      auto swap = hn::Gt(t0, t1);
      tn = StdMax(tn, hn::IfThenElse(swap, t1, t0));
      tf = StdMin(tf, hn::IfThenElse(swap, t0, t1));
      t0 = hn::Mul(hn::Set(dd, alo[a]), ia);
      t1 = hn::Mul(hn::Set(dd, ahi[a]), ia);
      swap = hn::Gt(t0, t1);
      an = StdMax(an, hn::IfThenElse(swap, t1, t0));
      af = StdMin(af, hn::IfThenElse(swap, t0, t1));
    }
    // FastMarcher::set_up from its box test on, for lanes whose candidate
    // indices stay below 2^51 (where floor and ceil in doubles equal the
    // int64 arithmetic there); the others take set_up.
    const auto valid = hn::And(hn::And(hn::Le(tn, tf), hn::Ge(tf, zero)), hn::And(hn::IsFinite(tf), hn::IsFinite(tn)));
    const VD first = StdMin(hn::Sub(hn::Div(StdMax(tn, zero), vdelta), half), hn::Set(dd, 4e18));
    const VD last = StdMin(hn::Sub(hn::Div(tf, vdelta), half), hn::Set(dd, 4e18));
    special = hn::Or(special, hn::AndNot(hn::Lt(last, hn::Set(dd, 0x1p51)), valid));
    const VD k = StdMax(zero, hn::Sub(hn::Floor(first), one));
    const VD k_end = hn::Add(hn::Ceil(last), one);
    // Whether the march has candidates, before the start and the steps (the AABB count's condition).
    const auto has_candidates = hn::And(valid, hn::Le(k, k_end));
    // Where no lane can have a sample, the marchers are left empty (as for
    // lanes without candidates): none of the march's terms are needed.
    if (!none) {
      // The ray's start: the candidate before the one at or past t_start (the
      // candidates before it end a step or more before t_start).
      const VD k_start = StdMax(
          k, hn::Sub(hn::Floor(StdMin(hn::Sub(hn::Div(hn::Load(dd, ts), vdelta), half), hn::Set(dd, 4e18))), one));
      const VD t_max = hn::Mul(hn::Add(k_end, hn::Set(dd, 1.5)), vdelta);
      VD max_coord = hn::Set(dd, R);
      for (int a = 0; a < 3; ++a)
        max_coord = StdMax(max_coord, hn::Add(hn::Set(dd, std::abs(om[a])), hn::Mul(hn::Abs(dmd[a]), t_max)));
      const VD margin = hn::Mul(max_coord, hn::Set(dd, 1.0 / 524288.0));
      VD ex_v[3], sc_v[3], of_v[3];
      for (int a = 0; a < 3; ++a) {
        const auto up = hn::Gt(dmd[a], zero);
        sc_v[a] = hn::Div(one, hn::Mul(dmd[a], vdelta));
        ex_v[a] = hn::IfThenElseZero(up, one);
        const VD m = hn::IfThenElse(up, hn::Neg(margin), margin);
        of_v[a] = hn::Sub(hn::Mul(hn::Sub(m, hn::Set(dd, om[a])), sc_v[a]), half);
        hn::Store(ex_v[a], dd, exit[a]);
        hn::Store(sc_v[a], dd, scale[a]);
        hn::Store(of_v[a], dd, offset[a]);
      }
      // The march's first steps, in the lanes (Advance): from a fine voxel
      // whose reach is kFastJumpReach or more a jump past the empty box around it
      // (FastMarcher::State::skip_box), past a candidate outside the grid one
      // step, until a candidate with a shorter reach or the end. That
      // candidate's vector test is left to the march, marked dense so that it
      // does not look the reach up again.
      VD kv = k_start, checks = zero;
      auto dense = hn::FirstN(dd, 0);
      auto active = hn::AndNot(special, hn::And(valid, hn::Le(kv, k_end)));
      while (!hn::AllFalse(dd, active)) {
        const VF kf = hn::DemoteTo(dfh, kv);  // kv is an integer below 2^51: float(int64) rounds the same
        const VF t = hn::Mul(hn::Add(kf, hn::Set(dfh, 0.5f)), hn::Set(dfh, delta));
        VI vox[3];
        auto inside_f = hn::FirstN(dfh, hn::Lanes(dfh));
        for (int a = 0; a < 3; ++a) {
          const VF p = hn::Add(hn::Set(dfh, m0.origin[a]), hn::Mul(fdir[a], t));
          inside_f = hn::And(inside_f, hn::And(hn::Ge(p, hn::Zero(dfh)), hn::Le(p, hn::Set(dfh, grid_hi))));
          vox[a] = hn::Min(hn::ConvertTo(di32, p), hn::Set(di32, model.micro_res - 1));
        }
        const auto inside_i = hn::RebindMask(di32, inside_f);
        const VI fr = hn::Set(di32, skip.res);
        const VI fine =
            hn::Add(hn::ShiftRight<2>(vox[0]),
                    hn::Mul(fr, hn::Add(hn::ShiftRight<2>(vox[1]), hn::Mul(fr, hn::ShiftRight<2>(vox[2])))));
        const VI e = hn::And(hn::GatherOffset(di32, reach, hn::IfThenElseZero(inside_i, fine)), hn::Set(di32, 0xFF));
        const auto far_i = hn::And(inside_i, hn::Gt(e, hn::Set(di32, kFastJumpReach - 1)));
        // skip_box(k, lo, size): lo = 4 (v >> 2) - e per axis, size = 4 + 2 e.
        const VD size_d = hn::PromoteTo(dd, hn::Add(hn::Add(e, e), hn::Set(di32, 4)));
        VD xs[3];
        for (int a = 0; a < 3; ++a) {
          const VI lo = hn::Sub(hn::ShiftLeft<2>(hn::ShiftRight<2>(vox[a])), e);
          xs[a] = hn::Add(hn::Mul(hn::Add(hn::PromoteTo(dd, lo), hn::Mul(size_d, ex_v[a])), sc_v[a]), of_v[a]);
        }
        const VD xm = StdMin(xs[0], StdMin(xs[1], xs[2]));
        const VD floor_x = hn::Floor(StdMax(xm, hn::Set(dd, -4e18)));
        const VD jump =
            hn::IfThenElse(hn::Lt(xm, k_end), StdMax(hn::Add(kv, one), hn::Add(floor_x, one)), hn::Add(k_end, one));
        const auto inside = WidenMask(dd, di32, inside_i);
        const auto far = hn::And(active, WidenMask(dd, di32, far_i));
        const auto outside = hn::AndNot(inside, active);
        kv = hn::IfThenElse(far, jump, hn::IfThenElse(outside, hn::Add(kv, one), kv));
        const auto stop = hn::AndNot(far, hn::And(active, inside));
        checks = hn::Add(checks, hn::IfThenElseZero(hn::Or(far, stop), one));
        dense = hn::Or(dense, stop);
        active = hn::And(hn::Or(far, outside), hn::Le(kv, k_end));
      }
      hn::Store(checks, dd, kk[2]);
      hn::Store(hn::IfThenElseZero(dense, one), dd, flags[2]);
      hn::Store(kv, dd, kk[0]);
      hn::Store(k_end, dd, kk[1]);
    }
    hn::Store(none ? zero : hn::IfThenElseZero(valid, one), dd, flags[0]);
    hn::Store(hn::IfThenElseZero(special, one), dd, flags[1]);
    const int valid_lanes = std::min(int(L), n - r0);
    // The directions and the AABB hits of the vector's rays (the lanes set_up
    // takes over are written again below).
    const auto store = hn::FirstN(dfh, size_t(valid_lanes));
    hn::BlendedStore(fdir_unit[0], store, dfh, dx + r0);
    hn::BlendedStore(fdir_unit[1], store, dfh, dy + r0);
    hn::BlendedStore(fdir_unit[2], store, dfh, dz + r0);
    uint8_t hit_bits[8] = {0};
    hn::StoreMaskBits(dd, hn::And(has_candidates, hn::And(hn::Le(an, af), hn::Ge(af, zero))), hit_bits);
    for (int l = 0; l < valid_lanes; ++l) hit_aabb[r0 + l] = (hit_bits[l / 8] >> (l % 8)) & 1;
    for (int l = 0; l < valid_lanes; ++l) {
      const int r = r0 + l;
      FastMarcher& fm = marchers[r];
      if (flags[1][l] != 0) {
        SetUpAlone(model, skip, cam, delta, aabb, x0 + r % tw, y0 + r / tw, grid, fm, dx[r], dy[r], dz[r], hit_aabb[r]);
        continue;
      }
      if (flags[0][l] != 0 && kk[0][l] <= kk[1][l]) {
        MicroRay mr = m0;
        mr.dir = Vec3f{dm[0][l], dm[1][l], dm[2][l]};
        const double e[3] = {exit[0][l], exit[1][l], exit[2][l]};
        const double sc[3] = {scale[0][l], scale[1][l], scale[2][l]};
        const double of[3] = {offset[0][l], offset[1][l], offset[2][l]};
        fm.assign(model, skip, mr, int64_t(kk[0][l]), int64_t(kk[1][l]), e, sc, of);
        fm.state().checks = uint64_t(kk[2][l]);
        fm.state().dense = flags[2][l] != 0;
      } else {  // no candidates, or none left after the first steps (which counted their lookups)
        fm.clear(model, skip);
        if (flags[0][l] != 0) fm.state().checks = uint64_t(kk[2][l]);
      }
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(SetupRays);

void fast_setup_rays(const SceneModel& model, const FastSkipGrid& skip, const Camera& camera, float delta,
                     const Box3d& aabb, int x0, int y0, int tw, int n, const double* t_start, FastMarcher* marchers,
                     float* dx, float* dy, float* dz, bool* hit_aabb) {
  HWY_DYNAMIC_DISPATCH(SetupRays)
  (model, skip, camera, delta, aabb, x0, y0, tw, n, t_start, marchers, dx, dy, dz, hit_aabb);
}

namespace {

// What tile_start_distances does for occupied fine voxel (fx, fy, fz): the
// tiles its box (widened by one micro voxel) may cover get at most its
// distance from the camera.
void lower_starts(const SceneModel& model, const Camera& cam, int tile, int tiles_x, int tiles_y, int fx, int fy,
                  int fz, std::vector<double>& start) {
  const double inf = std::numeric_limits<double>::infinity();
  const Vec3d o = cam.origin();
  const Vec3d lo = model.scene_box.lo.cast<double>();
  const Vec3d micro = model.micro_voxel_size().cast<double>();
  // The fine voxel widened by one micro voxel, relative to the camera.
  const Vec3d b_lo =
      lo + micro * (Vec3d{double(fx), double(fy), double(fz)} * double(kMicroPerFine) - Vec3d{1, 1, 1}) - o;
  const Vec3d b_hi = b_lo + micro * double(kMicroPerFine + 2);
  double d2 = 0;  // squared distance from the camera to the box
  for (int a = 0; a < 3; ++a) {
    const double c = std::max({b_lo[a], -b_hi[a], 0.0});
    d2 += c * c;
  }
  const double dist = std::sqrt(d2);
  // The corners in camera space, projected (u = cx + fx X / -Z, v = cy - fy Y / -Z).
  double u_lo = inf, u_hi = -inf, v_lo = inf, v_hi = -inf;
  bool in_front = true;
  for (int c = 0; c < 8 && in_front; ++c) {
    const Vec3d w{(c & 1) ? b_hi.x : b_lo.x, (c & 2) ? b_hi.y : b_lo.y, (c & 4) ? b_hi.z : b_lo.z};
    double p[3];
    for (int j = 0; j < 3; ++j) p[j] = cam.c2w[j] * w.x + cam.c2w[4 + j] * w.y + cam.c2w[8 + j] * w.z;
    const double depth = -p[2];
    if (!(depth > 1e-9 * (std::abs(w.x) + std::abs(w.y) + std::abs(w.z) + 1e-300))) {
      in_front = false;
      break;
    }
    const double u = cam.cx + cam.fx * p[0] / depth, v = cam.cy - cam.fy * p[1] / depth;
    u_lo = std::min(u_lo, u);
    u_hi = std::max(u_hi, u);
    v_lo = std::min(v_lo, v);
    v_hi = std::max(v_hi, v);
  }
  // Every tile, unless the box lies wholly in front of the camera: then
  // the tiles of the pixels whose centre (i + 0.5) lies within a pixel
  // of its projection.
  int tx0 = 0, tx1 = tiles_x - 1, ty0 = 0, ty1 = tiles_y - 1;
  if (in_front && std::isfinite(u_lo + u_hi + v_lo + v_hi)) {
    const auto first = [](double x) { return int(std::clamp(std::ceil(x - 1.5), -1.0, 1e9)); };
    const auto last = [](double x) { return int(std::clamp(std::floor(x + 0.5), -1.0, 1e9)); };
    const int i0 = first(u_lo), i1 = last(u_hi), j0 = first(v_lo), j1 = last(v_hi);
    if (i1 < 0 || j1 < 0) return;
    tx0 = std::max(0, i0) / tile;
    tx1 = std::min(tiles_x - 1, i1 / tile);
    ty0 = std::max(0, j0) / tile;
    ty1 = std::min(tiles_y - 1, j1 / tile);
  }
  for (int ty = ty0; ty <= ty1; ++ty)
    for (int tx = tx0; tx <= tx1; ++tx) {
      double& s = start[size_t(ty) * size_t(tiles_x) + size_t(tx)];
      s = std::min(s, dist);
    }
}

}  // namespace

std::vector<double> tile_start_distances(const SceneModel& model, const FastSkipGrid& skip, const Camera& cam, int tile,
                                         int tiles_x, int tiles_y, int threads) {
  const double inf = std::numeric_limits<double>::infinity();
  const size_t cells = size_t(tiles_x) * size_t(tiles_y);
  std::vector<double> start(cells, inf);
  const int R = skip.res;
  // Each thread takes slabs of fine voxels into its own distances, merged
  // by their minimum (in any order: the same result).
#pragma omp parallel num_threads(std::max(1, threads))
  {
    std::vector<double> mine(cells, inf);
#pragma omp for schedule(dynamic, 1) nowait
    for (int fz = 0; fz < R; ++fz)
      for (int fy = 0; fy < R; ++fy)
        for (int fx = 0; fx < R; ++fx)
          if (skip.at(fx, fy, fz) == 0) lower_starts(model, cam, tile, tiles_x, tiles_y, fx, fy, fz, mine);
#pragma omp critical
    for (size_t i = 0; i < cells; ++i) start[i] = std::min(start[i], mine[i]);
  }
  return start;
}

}  // namespace edrnr
#endif
