// Trainer::State, occupancy and phase changes (train/trainer_state.h): the
// occupancy grid's refreshes and AABB in the main phase, the freeze into
// blocks and per-CV MLPs, pruning, and the start of quantization-aware training.
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "train/mlp_kernels.h"
#include "train/occupancy_kernels.h"
#include "train/rng.h"
#include "train/trainer_state.h"
#include "train/volume.h"

namespace edrnr::train {

// --- occupancy ------------------------------------------------------------

float Trainer::State::occupancy_threshold() const {
  const float t = -std::log(1.f - cfg.occupancy_alpha) / delta;
  const double mean = occ.mean_density();
  return occ_updates >= kSweepParts ? std::min(t, float(mean)) : t;
}

// The micro voxels a refresh evaluates: the whole grid until the AABB is
// known, then the AABB widened by kOccupancyMargin voxels (so that it can grow).
void Trainer::State::refresh_bounds(Vec3i& lo, Vec3i& hi) const {
  const int R = cfg.micro_res;
  lo = {0, 0, 0};
  hi = {R - 1, R - 1, R - 1};
  if (!occ.aabb_known) return;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max(0, occ.aabb_lo[a] - kOccupancyMargin);
    hi[a] = std::min(R - 1, occ.aabb_hi[a] + kOccupancyMargin);
  }
}

// Evaluates the density of every micro voxel of sweep part `part` inside the
// refresh bounds at a jittered point and folds it into the running maximum.
void Trainer::State::refresh_occupancy_part(int part, float decay) {
  const int R = cfg.micro_res;
  const uint64_t base = hash3(cfg.seed, uint64_t(RngStream::Occupancy), uint64_t(occ_updates));
  Vec3i lo, hi;
  refresh_bounds(lo, hi);
  const int px = part & 1, py = (part >> 1) & 1, pz = (part >> 2) & 1;
  // First coordinate >= lo with the part's parity, and the count along each axis.
  auto first = [](int l, int p) { return l + ((l & 1) != p ? 1 : 0); };
  const int x_first = first(lo.x, px), y_first = first(lo.y, py), z_first = first(lo.z, pz);
  const int ny = y_first <= hi.y ? (hi.y - y_first) / 2 + 1 : 0;
  const int nz = z_first <= hi.z ? (hi.z - z_first) / 2 + 1 : 0;
  const int rows = ny * nz;
  // The pyramid's levels as the row kernel reads them.
  std::vector<PyramidLevelView> levels;
  for (size_t li = 0; li < pyramid.levels().size(); ++li) {
    const PyramidLevel& L = pyramid.levels()[li];
    levels.push_back({L.value.data(), L.res, L.shift, pyramid.level_active(li)});
  }
  if (pyramid.channels() != F)
    fail("the occupancy refresh needs the pyramid's {} channels to be the density net's {} inputs", pyramid.channels(),
         F);
#pragma omp parallel
  {
    std::vector<float> x0(size_t(F) * kLanes), acts(size_t(layout.density_act_floats) * kLanes);
    float px[kLanes] = {}, py[kLanes] = {}, pz[kLanes] = {};  // the kernel ignores lanes from nl on
    const float* params = mlp_params.data();
#pragma omp for schedule(dynamic, 16)
    for (int row = 0; row < rows; ++row) {
      const int y = y_first + 2 * (row % ny), z = z_first + 2 * (row / ny);
      for (int xs = x_first; xs <= hi.x; xs += 2 * kLanes) {
        int nl = 0;
        for (int x = xs; x <= hi.x && nl < kLanes; x += 2, ++nl) {
          const size_t cell = size_t(linear_index(x, y, z, R));
          const uint64_t h = hash_combine(base, cell);
          px[nl] = float(x) + uniform01(h);
          py[nl] = float(y) + uniform01(mix64(h));
          pz[nl] = float(z) + uniform01(mix64(h + 1));
        }
        refresh_interpolate_row(levels.data(), int(levels.size()), xs, y, z, nl, px, py, pz, x0.data());
        net_forward(layout.density, params, x0.data(), acts.data(), 1);
        const float* raw = acts.data() + size_t(layout.density_act_floats - G) * kLanes;
        int l = 0;
        for (int x = xs; x <= hi.x && l < nl; x += 2, ++l) {
          const size_t cell = size_t(linear_index(x, y, z, R));
          const float sigma = sigma_of_raw(raw[size_t(l)]);
          float& d = occ.density[cell];
          d = d < 0.f ? sigma : std::max(d * decay, sigma);
        }
      }
    }
  }
}

void Trainer::State::refresh_occupancy() {
  const float decay = std::pow(cfg.occupancy_decay, float(kSweepParts));
  refresh_occupancy_part(int(occ_updates % kSweepParts), decay);
  ++occ_updates;
  occ.rebuild(occupancy_threshold());
}

void Trainer::State::update_aabb() {
  occ.update_aabb(occupancy_threshold(), cfg.aabb_filter_sigma, cfg.aabb_keep);
  // Voxels beyond the refresh bounds are no longer evaluated: they count as empty.
  Vec3i lo, hi;
  refresh_bounds(lo, hi);
  const int R = cfg.micro_res;
#pragma omp parallel for schedule(static)
  for (int z = 0; z < R; ++z)
    for (int y = 0; y < R; ++y)
      for (int x = 0; x < R; ++x)
        if (x < lo.x || y < lo.y || z < lo.z || x > hi.x || y > hi.y || z > hi.z)
          occ.density[size_t(linear_index(x, y, z, R))] = 0.f;
  occ.rebuild(occupancy_threshold());
}

// --- phase changes ----------------------------------------------------------

void Trainer::State::freeze() {
  // The levels of the last main-phase step (also after a resume).
  pyramid.set_active_levels(active_levels(std::max<int64_t>(step - 1, 0)));
  // A full, fresh sweep so that every voxel reflects the final main-phase model.
  const float decay = std::pow(cfg.occupancy_decay, float(kSweepParts));
  for (int p = 0; p < kSweepParts; ++p) {
    refresh_occupancy_part(int(occ_updates % kSweepParts), decay);
    ++occ_updates;
  }
  if (!occ.update_aabb(occupancy_threshold(), cfg.aabb_filter_sigma, cfg.aabb_keep)) {
    // Nothing dense at all: keep the whole box so the model stays valid.
    occ.aabb_known = true;
    occ.aabb_lo = {0, 0, 0};
    occ.aabb_hi = {cfg.micro_res - 1, cfg.micro_res - 1, cfg.micro_res - 1};
  }
  occ.rebuild(occupancy_threshold());
  // Blocks for the occupied fine voxels, baked from the pyramid.
  SceneModel shape;
  shape.micro_res = cfg.micro_res;
  shape.init_grids();
  shape.occupancy[int(Tier::Micro)] = occ.micro;
  shape.rebuild_upper_tiers();
  const Bitmap3& fine = shape.occupancy[int(Tier::Fine)];
  std::vector<uint32_t> fine_index;
  for (size_t i = 0; i < fine.size(); ++i)
    if (fine.get(i)) fine_index.push_back(uint32_t(i));
  const int fr = cfg.micro_res / kMicroPerFine;
  // Before the blocks are allocated: an occupancy grid that has not emptied
  // yet (too few steps) would need a block for nearly every fine voxel.
  const uint64_t state_bytes = cfg.block_state_bytes(fine_index.size());
  if (state_bytes > cfg.max_state_bytes())
    fail(
        "at the freeze (step {}) the occupancy grid still holds {} of its {} fine voxels: their feature blocks need "
        "{:.2f} GiB of training state, over the limit max_state_gib = {} GiB; train for more steps (--iters) so "
        "that empty space is found, or raise max_state_gib in the config",
        step, fine_index.size(), fine.size(), double(state_bytes) / double(uint64_t{1} << 30), cfg.max_state_gib);
  std::vector<float> values(fine_index.size() * kBlockVerts * size_t(F));
  const int n_blocks = int(fine_index.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (int bi = 0; bi < n_blocks; ++bi) {
    const uint32_t fi = fine_index[size_t(bi)];
    const int fx = int(fi % uint32_t(fr)), fy = int((fi / uint32_t(fr)) % uint32_t(fr)),
              fz = int(fi / uint32_t(fr * fr));
    for (int v = 0; v < kBlockVerts; ++v) {
      const Vec3i q{4 * fx + v % 5, 4 * fy + (v / 5) % 5, 4 * fz + v / 25};
      const Vec3i m{std::min(q.x, cfg.micro_res - 1), std::min(q.y, cfg.micro_res - 1),
                    std::min(q.z, cfg.micro_res - 1)};
      pyramid.interpolate(q.cast<float>(), m, &values[(size_t(bi) * kBlockVerts + size_t(v)) * size_t(F)]);
    }
  }
  blocks = BlockFeatures(cfg.micro_res, F, std::move(fine_index), std::move(values));
  pyramid = FeaturePyramid();
  // One MLP per occupied coarse voxel, each a copy of the shared one.
  const Bitmap3& coarse = shape.occupancy[int(Tier::Coarse)];
  mlp_cv.clear();
  cv_to_mlp.assign(coarse.size(), -1);
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i)) {
      cv_to_mlp[i] = int32_t(mlp_cv.size());
      mlp_cv.push_back(uint32_t(i));
    }
  n_mlps = std::max<int>(1, int(mlp_cv.size()));
  std::vector<float> shared(mlp_params.begin(), mlp_params.begin() + ptrdiff_t(layout.param_count));
  mlp_params.clear();
  for (int m = 0; m < n_mlps; ++m) mlp_params.insert(mlp_params.end(), shared.begin(), shared.end());
  mlp_m.assign(mlp_params.size(), 0.f);
  mlp_v.assign(mlp_params.size(), 0.f);
  feature_adam_t = 0;
  mlp_adam_t = 0;
  if (cfg.prune_weight > 0.f || cfg.prune_cv_weight > 0.f || cfg.prune_part_fraction > 0.f)
    max_weight.assign(occ.density.size(), 0.f);
  phase = Phase::PerCv;
}

// Empties the micro voxels whose samples never weighed prune_weight in the
// per-CV phase (the inside of solids, faint fog), the coarse voxels below
// prune_cv_weight and the small parts apart from the object, drops the
// blocks and MLPs left without occupied voxels, and tightens the AABB.
void Trainer::State::prune() {
  const int R = cfg.micro_res;
  Bitmap3 kept(R);
  // The largest sample weight anywhere in each coarse voxel: a coarse voxel
  // whose samples all stayed below prune_cv_weight (a floater, which costs
  // the chip a whole MLP load) is emptied.
  constexpr int kCv = kMicroPerFine * kFinePerCoarse;  // micro voxels per coarse voxel edge
  const int cr = R / kCv;
  std::vector<float> cv_peak(size_t(cr) * cr * cr, 0.f);
  if (cfg.prune_cv_weight > 0.f)
    for (int z = 0; z < R; ++z)
      for (int y = 0; y < R; ++y)
        for (int x = 0; x < R; ++x) {
          const size_t i = kept.index(x, y, z);
          if (!occ.micro.get(i)) continue;
          float& peak = cv_peak[linear_index(x / kCv, y / kCv, z / kCv, cr)];
          peak = std::max(peak, max_weight[i]);
        }
  for (int z = 0; z < R; ++z)
    for (int y = 0; y < R; ++y)
      for (int x = 0; x < R; ++x) {
        const size_t i = kept.index(x, y, z);
        if (!occ.micro.get(i) || max_weight[i] < cfg.prune_weight) continue;
        if (cfg.prune_cv_weight > 0.f && cv_peak[linear_index(x / kCv, y / kCv, z / kCv, cr)] < cfg.prune_cv_weight)
          continue;
        kept.set(i);
      }
  // Small parts away from the object (floaters at the scene box's edge).
  drop_outlying_parts(kept, cfg.prune_part_fraction);
  Vec3i lo{R, R, R}, hi{-1, -1, -1};
  for (int z = 0; z < R; ++z)
    for (int y = 0; y < R; ++y)
      for (int x = 0; x < R; ++x)
        if (kept.get(x, y, z)) {
          lo = vmin(lo, Vec3i{x, y, z});
          hi = vmax(hi, Vec3i{x, y, z});
        }
  max_weight.clear();
  max_weight.shrink_to_fit();
  if (hi.x < 0) return;  // nothing would remain: keep the occupancy as it is
  occ.micro = std::move(kept);
  occ.aabb_lo = lo;
  occ.aabb_hi = hi;
  occ.rebuild_macro();
  // Blocks of fine voxels that still hold an occupied micro voxel.
  const size_t F_ = size_t(F);
  std::vector<uint32_t> fine_index;
  std::vector<float> values, m, v;
  const auto& old_index = blocks.fine_index();
  const int fr = R / kMicroPerFine;
  auto fine_xyz = [fr](uint32_t fi) {
    return Vec3i{int(fi % uint32_t(fr)), int((fi / uint32_t(fr)) % uint32_t(fr)), int(fi / uint32_t(fr * fr))};
  };
  for (size_t bi = 0; bi < old_index.size(); ++bi) {
    const uint32_t fi = old_index[bi];
    const Vec3i f = fine_xyz(fi);
    if (!occ.fine.get(f.x, f.y, f.z)) continue;
    fine_index.push_back(fi);
    const size_t o = bi * kBlockVerts * F_, len = kBlockVerts * F_;
    values.insert(values.end(), blocks.values().begin() + ptrdiff_t(o), blocks.values().begin() + ptrdiff_t(o + len));
    m.insert(m.end(), blocks.adam().m.begin() + ptrdiff_t(o), blocks.adam().m.begin() + ptrdiff_t(o + len));
    v.insert(v.end(), blocks.adam().v.begin() + ptrdiff_t(o), blocks.adam().v.begin() + ptrdiff_t(o + len));
  }
  blocks = BlockFeatures(R, F, std::move(fine_index), std::move(values));
  blocks.adam().m = std::move(m);
  blocks.adam().v = std::move(v);
  // MLPs of coarse voxels that still hold an occupied fine voxel.
  std::vector<uint8_t> cv_used(size_t(cr) * cr * cr, 0);
  for (uint32_t fi : blocks.fine_index()) {
    const Vec3i f = fine_xyz(fi);
    cv_used[linear_index(f.x / kFinePerCoarse, f.y / kFinePerCoarse, f.z / kFinePerCoarse, cr)] = 1;
  }
  const size_t P = layout.param_count;
  std::vector<uint32_t> new_cv;
  std::vector<float> params, pm, pv;
  for (size_t mi = 0; mi < mlp_cv.size(); ++mi) {
    if (!cv_used[mlp_cv[mi]]) continue;
    new_cv.push_back(mlp_cv[mi]);
    params.insert(params.end(), mlp_params.begin() + ptrdiff_t(mi * P), mlp_params.begin() + ptrdiff_t((mi + 1) * P));
    pm.insert(pm.end(), mlp_m.begin() + ptrdiff_t(mi * P), mlp_m.begin() + ptrdiff_t((mi + 1) * P));
    pv.insert(pv.end(), mlp_v.begin() + ptrdiff_t(mi * P), mlp_v.begin() + ptrdiff_t((mi + 1) * P));
  }
  mlp_cv = std::move(new_cv);
  mlp_params = std::move(params);
  mlp_m = std::move(pm);
  mlp_v = std::move(pv);
  cv_to_mlp.assign(size_t(cr) * cr * cr, -1);
  for (size_t mi = 0; mi < mlp_cv.size(); ++mi) cv_to_mlp[mlp_cv[mi]] = int32_t(mi);
  n_mlps = std::max<int>(1, int(mlp_cv.size()));
}

void Trainer::State::start_quantization() {
  if (mse_ema > 0) psnr_float = -10.0 * std::log10(mse_ema);
  take_ema();  // the per-CV phase's averages (ema_decay_per_cv)
  if (!max_weight.empty()) prune();
  equalize_mlps();
  float_blocks = blocks.values();
  float_mlps = mlp_params;
  feature_quant = blocks.fit_quantization();
  blocks.set_quantization(feature_quant);
  layer_in_max.assign(size_t(n_mlps) * (layout.density.size() + layout.color.size()), 0.f);
  phase = Phase::Quantize;
}

}  // namespace edrnr::train
