#include "train/trainer.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_io.h"
#include "model/mlp.h"
#include "render/traversal.h"
#include "train/adam.h"
#include "train/checkpoint_io.h"
#include "train/feature_grid.h"
#include "train/mlp_kernels.h"
#include "train/occupancy.h"
#include "train/rng.h"
#include "train/volume.h"

namespace edrnr::train {

const char* phase_name(Phase p) {
  switch (p) {
    case Phase::Main:
      return "main";
    case Phase::PerCv:
      return "per-CV";
    case Phase::Quantize:
      return "quantize";
    case Phase::Done:
      return "done";
  }
  return "?";
}

namespace {

constexpr int kItemSamples = 1024;  // samples per work item: one MLP gradient partial each
constexpr int kFirstRoundSamples = 16;
constexpr int kMaxRoundSamples = 256;

struct WorkItem {
  int32_t mlp = 0;
  int32_t begin = 0, end = 0;  // range in the grouped id list
  int32_t chunk0 = 0;          // index of its first chunk among all chunks of the list
};

// Groups ids by MLP (stable) and cuts each group into work items.
void build_items(const std::vector<int32_t>& ids, const std::vector<int32_t>& sample_mlp, int n_mlps,
                 std::vector<int32_t>& grouped, std::vector<WorkItem>& items) {
  std::vector<int32_t> start(size_t(n_mlps) + 1, 0);
  for (int32_t s : ids) ++start[size_t(sample_mlp[size_t(s)]) + 1];
  for (int m = 0; m < n_mlps; ++m) start[size_t(m) + 1] += start[size_t(m)];
  grouped.resize(ids.size());
  std::vector<int32_t> fill(start.begin(), start.end() - 1);
  for (int32_t s : ids) grouped[size_t(fill[size_t(sample_mlp[size_t(s)])]++)] = s;
  items.clear();
  int32_t chunks = 0;
  for (int m = 0; m < n_mlps; ++m)
    for (int32_t b = start[size_t(m)]; b < start[size_t(m) + 1]; b += kItemSamples) {
      WorkItem w;
      w.mlp = m;
      w.begin = b;
      w.end = std::min(b + kItemSamples, start[size_t(m) + 1]);
      w.chunk0 = chunks;
      chunks += (w.end - w.begin + kLanes - 1) / kLanes;
      items.push_back(w);
    }
}

int32_t total_chunks(const std::vector<WorkItem>& items) {
  if (items.empty()) return 0;
  const auto& w = items.back();
  return w.chunk0 + (w.end - w.begin + kLanes - 1) / kLanes;
}

inline float sigmoid(float z) { return 1.f / (1.f + std::exp(-z)); }

// Rays and samples of one step (reused between steps).
struct Batch {
  int n_rays = 0;
  std::vector<MicroRay> mray;     // each ray in micro-grid units (the renderer's sampling)
  std::vector<float> target;      // 3 per ray
  std::vector<float> background;  // 3 per ray
  std::vector<float> dir_enc;     // dir_dims per ray
  std::vector<int32_t> k_next, k_last;
  std::vector<float> trans;
  std::vector<uint8_t> alive;
  std::vector<int32_t> ray_first, ray_count;  // each ray's active samples in `order`
  std::vector<int32_t> order;                 // active sample ids, ray after ray, each in march order
  std::vector<float> pixel;                   // 3 per ray
  std::vector<double> ray_sq_err;

  size_t n_samples = 0;
  std::vector<float> pos;       // 3 per sample: micro-grid position
  std::vector<int16_t> micro;   // 3 per sample: micro voxel
  std::vector<int32_t> cand;    // candidate index k along the ray
  std::vector<int32_t> ray;     // owning ray
  std::vector<int32_t> mlp;     // MLP index
  std::vector<float> feat;      // F per sample
  std::vector<float> geo;       // G per sample; geo[0] is the raw density
  std::vector<uint8_t> active;  // before termination
  std::vector<float> rgb;       // 3 per sample
  std::vector<float> d_raw;     // 1 per sample
  std::vector<float> weight;    // 1 per sample: T alpha
  std::vector<float> d_z;       // 3 per sample: gradient before the sigmoid
  std::vector<float> d_feat;    // F per sample

  std::vector<int32_t> col_ids;
  std::vector<WorkItem> col_items;
  std::vector<float> col_acts;

  void reserve_samples(size_t n, int F, int G) {
    if (pos.size() >= 3 * n) return;
    size_t cap = std::max(n, pos.size() / 3 * 2);
    pos.resize(3 * cap);
    micro.resize(3 * cap);
    cand.resize(cap);
    ray.resize(cap);
    mlp.resize(cap);
    feat.resize(cap * size_t(F));
    geo.resize(cap * size_t(G));
    active.resize(cap);
    rgb.resize(3 * cap);
    d_raw.resize(cap);
    weight.resize(cap);
    d_z.resize(3 * cap);
    d_feat.resize(cap * size_t(F));
  }
};

enum Stage { kRays, kMarch, kDensity, kColor, kComposite, kBackward, kScatter, kAdam, kOccupancy, kPhase, kStages };
const char* const kStageNames[kStages] = {"rays",     "march",   "density", "colour",    "composite",
                                          "backward", "scatter", "adam",    "occupancy", "phase change"};

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

uint64_t dataset_fingerprint(const Dataset& d) {
  uint64_t h = mix64(d.frames.size());
  for (const auto& f : d.frames) {
    h = hash_combine(h, uint64_t(f.image.width) * 65536 + uint64_t(f.image.height));
    for (double v : f.camera.c2w) {
      uint64_t bits;
      std::memcpy(&bits, &v, 8);
      h = hash_combine(h, bits);
    }
    for (size_t i = 0; i < f.image.data.size(); i += 997) {
      uint32_t bits;
      std::memcpy(&bits, &f.image.data[i], 4);
      h = hash_combine(h, bits);
    }
  }
  return h;
}

}  // namespace

struct Trainer::State {
  const Dataset& data;
  TrainConfig cfg;
  MlpArch arch;
  MlpLayout layout;
  int F = 0, G = 0, DD = 0;
  SceneModel geometry;  // scene box and micro resolution only: the renderer's sampling helpers take a model
  float delta = 0;      // scene units between candidate samples
  std::vector<uint64_t> pixel_start;  // prefix sums of pixels per frame
  bool rgba = false;                  // images are premultiplied RGBA

  int64_t step = 0;
  int64_t iters = 0;
  bool iters_fixed = false;
  Phase phase = Phase::Main;
  int n_rays = 0;
  double mse_ema = -1;
  double psnr_float = 0, psnr_quantized = 0;
  int64_t occ_updates = 0;
  int64_t feature_adam_t = 0, mlp_adam_t = 0;
  int last_rays = 0;
  int64_t last_samples = 0;

  FeaturePyramid pyramid;
  BlockFeatures blocks;
  OccupancyGrid occ;
  std::vector<Int4Channel> feature_quant;  // quantization-aware phase

  int n_mlps = 1;
  std::vector<uint32_t> mlp_cv;    // CV of each MLP (after the freeze)
  std::vector<int32_t> cv_to_mlp;  // dense coarse grid -> MLP
  std::vector<float> mlp_params, mlp_m, mlp_v;
  std::vector<float> mlp_eff;       // fake-quantized weights in the quantization-aware phase
  std::vector<float> layer_in_max;  // per MLP x layer: largest |input| seen in the quantization-aware phase

  // Largest sample weight seen per micro voxel in the per-CV phase (for pruning).
  std::vector<float> max_weight;

  // Float snapshot when quantization-aware training begins.
  std::vector<float> float_blocks, float_mlps;

  mutable Batch batch;
  mutable double stage_s[kStages] = {};

  State(const Dataset& d, const TrainConfig& c) : data(d), cfg(c), arch(c.mlp_arch()), layout(arch), occ(c.micro_res) {
    cfg.validate();
    F = cfg.feature_channels();
    G = cfg.geo_features;
    DD = arch.dir_dims();
    geometry.scene_box = cfg.scene_box;
    geometry.micro_res = cfg.micro_res;
    delta = sample_spacing(geometry, cfg.step_micro);
    if (data.frames.empty()) fail("dataset {}: no frames to train on", data.root.string());
    pixel_start.push_back(0);
    rgba = data.frames[0].image.channels == 4;
    for (const auto& f : data.frames) {
      const int ch = rgba ? 4 : 3;
      if (f.image.width <= 0 || f.image.height <= 0 || f.image.channels != ch ||
          f.image.data.size() != size_t(f.image.width) * f.image.height * size_t(ch))
        fail("dataset {}: frame {} has no RGB image loaded (or not the same channels as the first frame)",
             data.root.string(), f.image_path.string());
      if (f.camera.width != f.image.width || f.camera.height != f.image.height)
        fail("dataset {}: frame {} image is {}x{} but its camera is {}x{}", data.root.string(), f.image_path.string(),
             f.image.width, f.image.height, f.camera.width, f.camera.height);
      pixel_start.push_back(pixel_start.back() + uint64_t(f.image.width) * uint64_t(f.image.height));
    }
    iters = cfg.iters;
  }

  void fresh_init() {
    pyramid = FeaturePyramid(cfg.micro_res, cfg.levels, cfg.seed, cfg.init_features);
    n_mlps = 1;
    mlp_params.assign(layout.param_count, 0.f);
    init_mlp_params(layout, cfg.seed, mlp_params.data());
    mlp_m.assign(mlp_params.size(), 0.f);
    mlp_v.assign(mlp_params.size(), 0.f);
    n_rays = int(std::clamp<int64_t>(cfg.batch_samples / 256, cfg.min_rays, cfg.max_rays));
  }

  int64_t freeze_step() const { return cfg.freeze_step(iters); }
  int64_t qat_step() const {
    return std::max(freeze_step(), int64_t(std::llround(double(iters) * (1.0 - cfg.qat_fraction))));
  }

  // Warm-up, then constant until cfg.plan_step, then exponential decay to
  // lr_final at the last step: steps before plan_step do not depend on iters,
  // so a --minutes run (whose step count is fixed by then) is replayed exactly
  // by --iters with the count it chose.
  float lr_factor(int64_t t) const {
    const int64_t hold = cfg.plan_step;
    const double e = double(std::max<int64_t>(0, t - hold)) / double(std::max<int64_t>(1, iters - hold));
    double f = std::pow(double(cfg.lr_final), std::min(1.0, e));
    if (cfg.lr_warmup > 0 && t < cfg.lr_warmup) f *= double(t + 1) / double(cfg.lr_warmup + 1);
    return float(f);
  }

  Vec3f micro_scale() const { return cfg.scene_box.size() / float(cfg.micro_res); }

  // --- rays ---------------------------------------------------------------

  void set_ray(Batch& b, int i, const Ray& r) {
    b.mray[size_t(i)] = make_micro_ray(geometry, r, delta);
    encode_direction(Vec3f{float(r.dir.x), float(r.dir.y), float(r.dir.z)}, cfg.dir_frequencies,
                     &b.dir_enc[size_t(i) * size_t(DD)]);
    // Candidate range inside the object AABB (the scene box until it is known).
    Box3d box{cfg.scene_box.lo.cast<double>(), cfg.scene_box.hi.cast<double>()};
    if (occ.aabb_known) {
      const Vec3d vs = micro_scale().cast<double>();
      box.lo = box.lo + vs * occ.aabb_lo.cast<double>();
      box.hi = cfg.scene_box.lo.cast<double>() + vs * (occ.aabb_hi + Vec3i{1, 1, 1}).cast<double>();
    }
    double t0, t1;
    int32_t k0 = 0, k1 = -1;
    if (intersect_box(r.origin, r.dir, box, t0, t1) && t1 > 0) {
      k0 = int32_t(std::max(0.0, std::ceil(t0 / double(delta) - 0.5) - 1));
      k1 = int32_t(std::floor(t1 / double(delta) - 0.5) + 1);
    }
    b.k_next[size_t(i)] = k0;
    b.k_last[size_t(i)] = k1;
    b.trans[size_t(i)] = 1.f;
    b.alive[size_t(i)] = k1 >= k0;
  }

  void resize_rays(Batch& b, int n) {
    b.n_rays = n;
    b.mray.resize(size_t(n));
    b.target.resize(3 * size_t(n));
    b.background.resize(3 * size_t(n));
    b.dir_enc.resize(size_t(n) * size_t(DD));
    b.k_next.resize(size_t(n));
    b.k_last.resize(size_t(n));
    b.trans.resize(size_t(n));
    b.alive.resize(size_t(n));
    b.ray_first.resize(size_t(n));
    b.ray_count.resize(size_t(n));
    b.pixel.resize(3 * size_t(n));
    b.ray_sq_err.resize(size_t(n));
  }

  void sample_training_rays(Batch& b, int n) {
    resize_rays(b, n);
    const uint64_t total = pixel_start.back();
    const uint64_t base = hash3(cfg.seed, uint64_t(RngStream::Rays), uint64_t(step));
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) {
      const uint64_t px = hash_combine(base, uint64_t(i)) % total;
      const size_t f = size_t(std::upper_bound(pixel_start.begin(), pixel_start.end(), px) - pixel_start.begin()) - 1;
      const Frame& fr = data.frames[f];
      const uint64_t local = px - pixel_start[f];
      const int x = int(local % uint64_t(fr.image.width)), y = int(local / uint64_t(fr.image.width));
      set_ray(b, i, fr.camera.pixel_ray(x, y));
      const float* t = fr.image.at(x, y);
      float* bg = &b.background[3 * size_t(i)];
      if (rgba) {
        // Premultiplied: target = rgb a + (1 - a) bg.
        const uint64_t h = mix64(hash_combine(base, uint64_t(i)));
        for (int c = 0; c < 3; ++c)
          bg[c] = cfg.random_background ? uniform01(hash_combine(h, uint64_t(c))) : cfg.background[c];
        for (int c = 0; c < 3; ++c) b.target[3 * size_t(i) + size_t(c)] = t[c] + (1.f - t[3]) * bg[c];
      } else {
        for (int c = 0; c < 3; ++c) {
          bg[c] = cfg.background[c];
          b.target[3 * size_t(i) + size_t(c)] = t[c];
        }
      }
    }
  }

  // --- sampling -------------------------------------------------------------

  // Position of candidate k of ray i in micro-grid units (exactly as the renderer computes it).
  Vec3f candidate(const Batch& b, int i, int32_t k) const { return b.mray[size_t(i)].point(k); }

  // How many of the candidates after the one at p (in micro voxel m) surely
  // lie in the same cell of cell^3 micro voxels: one fewer than the whole
  // steps to the cell's exit, a margin far above the rounding of the
  // candidates' points.
  int32_t candidates_left_in_cell(const MicroRay& r, const Vec3f& p, const Vec3i& m, int cell) const {
    float t_exit = INFINITY;
    for (int a = 0; a < 3; ++a) {
      const float lo = float((m[a] / cell) * cell), hi = lo + float(cell);
      if (r.dir[a] > 0.f) t_exit = std::min(t_exit, (hi - p[a]) / r.dir[a]);
      if (r.dir[a] < 0.f) t_exit = std::min(t_exit, (lo - p[a]) / r.dir[a]);
    }
    const float steps = std::floor(t_exit / delta);
    return steps > 1.f ? int32_t(std::min(steps, 1e6f)) - 1 : 0;
  }

  int32_t mlp_of_micro(int x, int y, int z) const {
    if (phase == Phase::Main) return 0;
    const int cr = cfg.micro_res / 32;
    return cv_to_mlp[linear_index(x >> 5, y >> 5, z >> 5, cr)];
  }

  const float* mlp_weights(int m) const {
    const auto& p = phase >= Phase::Quantize ? mlp_eff : mlp_params;
    return p.data() + size_t(m) * layout.param_count;
  }

  void interpolate(const Vec3f& p, const Vec3i& m, float* out) const {
    if (phase == Phase::Main)
      pyramid.interpolate(p, m, out);
    else
      blocks.interpolate(p, m, out);
  }

  void prefetch_features(const Vec3i& m) const {
    if (phase == Phase::Main)
      pyramid.prefetch(m);
    else
      blocks.prefetch(m);
  }

  // Marches every ray in rounds; evaluates density for each new sample and
  // stops a ray once its transmittance falls below the threshold. Fills the
  // active samples (b.order, b.ray_first, b.ray_count).
  void march(Batch& b) const {
    b.n_samples = 0;
    const int n = b.n_rays;
    std::vector<int32_t> live;
    for (int i = 0; i < n; ++i)
      if (b.alive[size_t(i)]) live.push_back(i);
    std::vector<std::vector<int32_t>> seg_begin, seg_used;  // per round, per live ray index
    std::vector<std::vector<int32_t>> round_rays;
    std::vector<int32_t> count;
    std::vector<float> cand_pos;
    std::vector<int16_t> cand_micro;
    std::vector<int32_t> cand_k;
    for (int round = 0; !live.empty(); ++round) {
      const int K = std::min(kMaxRoundSamples, kFirstRoundSamples << std::min(round, 8));
      const size_t L = live.size();
      count.assign(L, 0);
      cand_pos.resize(L * size_t(K) * 3);
      cand_micro.resize(L * size_t(K) * 3);
      cand_k.resize(L * size_t(K));
#pragma omp parallel for schedule(dynamic, 64)
      for (size_t li = 0; li < L; ++li) {
        const int i = live[li];
        int32_t k = b.k_next[size_t(i)];
        const int32_t k_last = b.k_last[size_t(i)];
        int c = 0;
        for (; k <= k_last && c < K; ++k) {
          const Vec3f p = candidate(b, i, k);
          Vec3i m;
          if (!micro_voxel_of(p, cfg.micro_res, m)) continue;
          if (!occ.macro_occupied(m.x, m.y, m.z)) {
            k += candidates_left_in_cell(b.mray[size_t(i)], p, m, kMacroCell);
            continue;
          }
          if (!occ.fine_occupied(m.x, m.y, m.z)) {
            k += candidates_left_in_cell(b.mray[size_t(i)], p, m, 4);
            continue;
          }
          if (!occ.occupied(m.x, m.y, m.z)) continue;
          const size_t o = (li * size_t(K) + size_t(c)) * 3;
          for (int a = 0; a < 3; ++a) {
            cand_pos[o + size_t(a)] = p[a];
            cand_micro[o + size_t(a)] = int16_t(m[a]);
          }
          cand_k[li * size_t(K) + size_t(c)] = k;
          ++c;
        }
        b.k_next[size_t(i)] = k;
        count[li] = c;
      }
      // Append the round's samples, ray by ray.
      const size_t s0 = b.n_samples;
      std::vector<int32_t> begin(L);
      size_t total = 0;
      for (size_t li = 0; li < L; ++li) {
        begin[li] = int32_t(s0 + total);
        total += size_t(count[li]);
      }
      b.reserve_samples(s0 + total, F, G);
#pragma omp parallel for schedule(static)
      for (size_t li = 0; li < L; ++li) {
        for (int c = 0; c < count[li]; ++c) {
          const size_t s = size_t(begin[li]) + size_t(c);
          const size_t o = (li * size_t(K) + size_t(c)) * 3;
          for (int a = 0; a < 3; ++a) {
            b.pos[3 * s + size_t(a)] = cand_pos[o + size_t(a)];
            b.micro[3 * s + size_t(a)] = cand_micro[o + size_t(a)];
          }
          b.ray[s] = live[li];
          b.cand[s] = cand_k[li * size_t(K) + size_t(c)];
          b.mlp[s] = mlp_of_micro(b.micro[3 * s], b.micro[3 * s + 1], b.micro[3 * s + 2]);
          b.active[s] = 0;
        }
      }
      b.n_samples = s0 + total;
      const auto td = std::chrono::steady_clock::now();
      evaluate_density(b, s0, b.n_samples);
      stage_s[kDensity] += seconds_since(td);
      // Transmittance along each ray; termination.
      std::vector<int32_t> used(L, 0);
#pragma omp parallel for schedule(static)
      for (size_t li = 0; li < L; ++li) {
        const int i = live[li];
        const int c = count[li];
        std::vector<float> raw(static_cast<size_t>(c));
        for (int j = 0; j < c; ++j) raw[size_t(j)] = b.geo[(size_t(begin[li]) + size_t(j)) * size_t(G)];
        float T;
        const int u = march_transmittance(raw.data(), c, delta, cfg.transmittance_min, b.trans[size_t(i)], &T);
        b.trans[size_t(i)] = T;
        used[li] = u;
        for (int j = 0; j < u; ++j) b.active[size_t(begin[li]) + size_t(j)] = 1;
        if (T < cfg.transmittance_min || b.k_next[size_t(i)] > b.k_last[size_t(i)]) b.alive[size_t(i)] = 0;
      }
      seg_begin.push_back(begin);
      seg_used.push_back(used);
      round_rays.push_back(live);
      std::vector<int32_t> next;
      for (size_t li = 0; li < L; ++li)
        if (b.alive[size_t(live[li])]) next.push_back(live[li]);
      live.swap(next);
    }
    // Active samples ray after ray (rounds in order within a ray).
    std::fill(b.ray_count.begin(), b.ray_count.end(), 0);
    for (size_t r = 0; r < round_rays.size(); ++r)
      for (size_t li = 0; li < round_rays[r].size(); ++li) b.ray_count[size_t(round_rays[r][li])] += seg_used[r][li];
    int32_t acc = 0;
    for (int i = 0; i < n; ++i) {
      b.ray_first[size_t(i)] = acc;
      acc += b.ray_count[size_t(i)];
    }
    b.order.resize(size_t(acc));
    std::vector<int32_t> fill(b.ray_first);
    for (size_t r = 0; r < round_rays.size(); ++r)
      for (size_t li = 0; li < round_rays[r].size(); ++li) {
        const int i = round_rays[r][li];
        for (int j = 0; j < seg_used[r][li]; ++j) b.order[size_t(fill[size_t(i)]++)] = seg_begin[r][li] + j;
      }
  }

  // Features and density-net outputs of samples [s0, s1).
  void evaluate_density(Batch& b, size_t s0, size_t s1) const {
    std::vector<int32_t> ids(s1 - s0), grouped;
    for (size_t s = s0; s < s1; ++s) ids[s - s0] = int32_t(s);
    std::vector<WorkItem> items;
    build_items(ids, b.mlp, n_mlps, grouped, items);
    const int n_items = int(items.size());
#pragma omp parallel
    {
      std::vector<float> x0(size_t(F) * kLanes), acts(size_t(layout.density_act_floats) * kLanes);
#pragma omp for schedule(dynamic, 1)
      for (int it = 0; it < n_items; ++it) {
        const WorkItem& w = items[size_t(it)];
        const float* params = mlp_weights(w.mlp);
        for (int32_t c0 = w.begin; c0 < w.end; c0 += kLanes) {
          const int nl = std::min(kLanes, w.end - c0);
          std::fill(x0.begin(), x0.end(), 0.f);
          for (int l = 0; l < nl; ++l) {
            if (l + 4 < nl) {
              const size_t q = size_t(grouped[size_t(c0 + l + 4)]);
              prefetch_features({b.micro[3 * q], b.micro[3 * q + 1], b.micro[3 * q + 2]});
            }
            const size_t s = size_t(grouped[size_t(c0 + l)]);
            float* f = &b.feat[s * size_t(F)];
            interpolate({b.pos[3 * s], b.pos[3 * s + 1], b.pos[3 * s + 2]},
                        {b.micro[3 * s], b.micro[3 * s + 1], b.micro[3 * s + 2]}, f);
            for (int c = 0; c < F; ++c) x0[size_t(c) * kLanes + size_t(l)] = f[c];
          }
          net_forward(layout.density, params, x0.data(), acts.data());
          const float* out = acts.data() + size_t(layout.density_act_floats - G) * kLanes;
          for (int l = 0; l < nl; ++l) {
            const size_t s = size_t(grouped[size_t(c0 + l)]);
            for (int c = 0; c < G; ++c) b.geo[s * size_t(G) + size_t(c)] = out[size_t(c) * kLanes + size_t(l)];
          }
        }
      }
    }
  }

  void gather_color_input(const Batch& b, const std::vector<int32_t>& ids, int32_t c0, int nl, float* x0) const {
    const int in = G + DD;
    std::fill(x0, x0 + size_t(in) * kLanes, 0.f);
    for (int l = 0; l < nl; ++l) {
      const size_t s = size_t(ids[size_t(c0 + l)]);
      for (int c = 0; c < G; ++c) x0[size_t(c) * kLanes + size_t(l)] = b.geo[s * size_t(G) + size_t(c)];
      const float* d = &b.dir_enc[size_t(b.ray[s]) * size_t(DD)];
      for (int c = 0; c < DD; ++c) x0[size_t(G + c) * kLanes + size_t(l)] = d[c];
    }
  }

  // Colour of every active sample; colour-net activations kept per chunk.
  void evaluate_color(Batch& b) const {
    build_items(b.order, b.mlp, n_mlps, b.col_ids, b.col_items);
    const int n_items = int(b.col_items.size());
    const size_t act_chunk = size_t(layout.color_act_floats) * kLanes;
    b.col_acts.resize(size_t(total_chunks(b.col_items)) * act_chunk);
#pragma omp parallel
    {
      std::vector<float> x0(size_t(G + DD) * kLanes);
#pragma omp for schedule(dynamic, 1)
      for (int it = 0; it < n_items; ++it) {
        const WorkItem& w = b.col_items[size_t(it)];
        const float* params = mlp_weights(w.mlp);
        int32_t chunk = w.chunk0;
        for (int32_t c0 = w.begin; c0 < w.end; c0 += kLanes, ++chunk) {
          const int nl = std::min(kLanes, w.end - c0);
          gather_color_input(b, b.col_ids, c0, nl, x0.data());
          float* acts = &b.col_acts[size_t(chunk) * act_chunk];
          net_forward(layout.color, params, x0.data(), acts);
          const float* out = acts + size_t(layout.color_act_floats - 3) * kLanes;
          for (int l = 0; l < nl; ++l) {
            const size_t s = size_t(b.col_ids[size_t(c0 + l)]);
            for (int c = 0; c < 3; ++c) b.rgb[3 * s + size_t(c)] = sigmoid(out[size_t(c) * kLanes + size_t(l)]);
          }
        }
      }
    }
  }

  // Pixels of every ray; with gradients, the loss gradient per sample. Returns
  // the summed squared error over rays and channels.
  double composite_rays(Batch& b, bool with_grad) const {
    const int n = b.n_rays;
    const float inv_n = 1.f / float(3 * n);
    // The distortion loss measures distances along the ray in scene-box edges.
    const float dist_scale = cfg.distortion_weight / float(n);
    const float interval = cfg.step_micro / float(cfg.micro_res);
#pragma omp parallel
    {
      std::vector<float> raw, rgb, d_raw, d_rgb, t;
#pragma omp for schedule(dynamic, 64)
      for (int i = 0; i < n; ++i) {
        const int32_t first = b.ray_first[size_t(i)], cnt = b.ray_count[size_t(i)];
        raw.resize(size_t(cnt));
        rgb.resize(3 * size_t(cnt));
        for (int j = 0; j < cnt; ++j) {
          const size_t s = size_t(b.order[size_t(first + j)]);
          raw[size_t(j)] = b.geo[s * size_t(G)];
          for (int c = 0; c < 3; ++c) rgb[3 * size_t(j) + size_t(c)] = b.rgb[3 * s + size_t(c)];
        }
        const float* bg = &b.background[3 * size_t(i)];
        const CompositeResult r = composite(raw.data(), rgb.data(), cnt, delta, bg);
        double se = 0;
        float d_pixel[3];
        for (int c = 0; c < 3; ++c) {
          b.pixel[3 * size_t(i) + size_t(c)] = r.rgb[c];
          const float e = r.rgb[c] - b.target[3 * size_t(i) + size_t(c)];
          se += double(e) * double(e);
          d_pixel[c] = 2.f * e * inv_n;
        }
        b.ray_sq_err[size_t(i)] = se;
        if (!with_grad || cnt == 0) continue;
        float T = 1.f;
        for (int j = 0; j < cnt; ++j) {
          const float tau = sigma_of_raw(raw[size_t(j)]) * delta;
          b.weight[size_t(b.order[size_t(first + j)])] = T * alpha_of_tau(tau);
          T *= std::exp(-tau);
        }
        d_raw.resize(size_t(cnt));
        d_rgb.resize(3 * size_t(cnt));
        composite_backward(raw.data(), rgb.data(), cnt, delta, bg, d_pixel, d_raw.data(), d_rgb.data());
        if (dist_scale > 0.f) {
          t.resize(size_t(cnt));
          for (int j = 0; j < cnt; ++j) t[size_t(j)] = float(b.cand[size_t(b.order[size_t(first + j)])]) * interval;
          distortion_backward(raw.data(), t.data(), cnt, delta, interval, dist_scale, d_raw.data());
        }
        for (int j = 0; j < cnt; ++j) {
          const size_t s = size_t(b.order[size_t(first + j)]);
          b.d_raw[s] = d_raw[size_t(j)];
          for (int c = 0; c < 3; ++c) {
            const float y = rgb[3 * size_t(j) + size_t(c)];
            b.d_z[3 * s + size_t(c)] = d_rgb[3 * size_t(j) + size_t(c)] * y * (1.f - y);
          }
        }
      }
    }
    double sum = 0;
    for (int i = 0; i < n; ++i) sum += b.ray_sq_err[size_t(i)];
    return sum;
  }

  // Backward through both nets for every active sample: MLP gradients (summed
  // into grad, n_mlps x params) and per-sample feature gradients.
  void backward_mlps(Batch& b, std::vector<float>& grad, bool calibrate) {
    const int n_items = int(b.col_items.size());
    const size_t P = layout.param_count;
    const size_t act_chunk = size_t(layout.color_act_floats) * kLanes;
    const int n_layers = int(layout.density.size() + layout.color.size());
    std::vector<float> partial(size_t(n_items) * P, 0.f);
    std::vector<float> item_max(calibrate ? size_t(n_items) * size_t(n_layers) : 0, 0.f);
#pragma omp parallel
    {
      const int cin = G + DD;
      std::vector<float> xc(size_t(cin) * kLanes), dz(3 * size_t(kLanes)), dxc(size_t(cin) * kLanes);
      std::vector<float> xd(size_t(F) * kLanes), actd(size_t(layout.density_act_floats) * kLanes);
      std::vector<float> dgeo(size_t(G) * kLanes), dfeat(size_t(F) * kLanes);
      std::vector<float> scratch(net_backward_scratch_floats(layout));
#pragma omp for schedule(dynamic, 1)
      for (int it = 0; it < n_items; ++it) {
        const WorkItem& w = b.col_items[size_t(it)];
        const float* params = mlp_weights(w.mlp);
        float* g = &partial[size_t(it) * P];
        int32_t chunk = w.chunk0;
        for (int32_t c0 = w.begin; c0 < w.end; c0 += kLanes, ++chunk) {
          const int nl = std::min(kLanes, w.end - c0);
          // Colour net.
          gather_color_input(b, b.col_ids, c0, nl, xc.data());
          std::fill(dz.begin(), dz.end(), 0.f);
          for (int l = 0; l < nl; ++l) {
            const size_t s = size_t(b.col_ids[size_t(c0 + l)]);
            for (int c = 0; c < 3; ++c) dz[size_t(c) * kLanes + size_t(l)] = b.d_z[3 * s + size_t(c)];
          }
          const float* acts = &b.col_acts[size_t(chunk) * act_chunk];
          net_backward(layout.color, params, xc.data(), acts, dz.data(), g, dxc.data(), scratch.data());
          // Density net (recomputed), fed by the colour net's input gradient and the raw-density gradient.
          std::fill(xd.begin(), xd.end(), 0.f);
          for (int l = 0; l < nl; ++l) {
            const size_t s = size_t(b.col_ids[size_t(c0 + l)]);
            for (int c = 0; c < F; ++c) xd[size_t(c) * kLanes + size_t(l)] = b.feat[s * size_t(F) + size_t(c)];
          }
          net_forward(layout.density, params, xd.data(), actd.data());
          std::copy(dxc.begin(), dxc.begin() + ptrdiff_t(size_t(G) * kLanes), dgeo.begin());
          for (int l = 0; l < nl; ++l) dgeo[size_t(l)] += b.d_raw[size_t(b.col_ids[size_t(c0 + l)])];
          for (int l = nl; l < kLanes; ++l)
            for (int c = 0; c < G; ++c) dgeo[size_t(c) * kLanes + size_t(l)] = 0.f;
          net_backward(layout.density, params, xd.data(), actd.data(), dgeo.data(), g, dfeat.data(), scratch.data());
          for (int l = 0; l < nl; ++l) {
            const size_t s = size_t(b.col_ids[size_t(c0 + l)]);
            for (int c = 0; c < F; ++c) b.d_feat[s * size_t(F) + size_t(c)] = dfeat[size_t(c) * kLanes + size_t(l)];
          }
          if (calibrate) {
            float* mx = &item_max[size_t(it) * size_t(n_layers)];
            const float* x = xd.data();
            size_t off = 0;
            for (size_t k = 0; k < layout.density.size(); ++k) {
              mx[k] = std::max(mx[k], block_max_abs(x, layout.density[k].in, nl));
              x = actd.data() + off;
              off += size_t(layout.density[k].out) * kLanes;
            }
            x = xc.data();
            off = 0;
            for (size_t k = 0; k < layout.color.size(); ++k) {
              const size_t j = layout.density.size() + k;
              mx[j] = std::max(mx[j], block_max_abs(x, layout.color[k].in, nl));
              x = acts + off;
              off += size_t(layout.color[k].out) * kLanes;
            }
          }
        }
      }
    }
    // Sum the partials of each MLP in item order.
    grad.assign(size_t(n_mlps) * P, 0.f);
    for (int it = 0; it < n_items; ++it) {
      float* dst = &grad[size_t(b.col_items[size_t(it)].mlp) * P];
      const float* src = &partial[size_t(it) * P];
      for (size_t k = 0; k < P; ++k) dst[k] += src[k];
    }
    if (calibrate)
      for (int it = 0; it < n_items; ++it)
        for (int k = 0; k < n_layers; ++k) {
          float& m = layer_in_max[size_t(b.col_items[size_t(it)].mlp) * size_t(n_layers) + size_t(k)];
          m = std::max(m, item_max[size_t(it) * size_t(n_layers) + size_t(k)]);
        }
  }

  // Renders the batch's rays (forward only, or with all gradients).
  double forward(Batch& b) const {
    march(b);
    evaluate_color(b);
    return composite_rays(b, false);
  }

  // --- occupancy ------------------------------------------------------------

  float occupancy_threshold() const {
    const float t = -std::log(1.f - cfg.occupancy_alpha) / delta;
    const double mean = occ.mean_density();
    return occ_updates >= kSweepParts ? std::min(t, float(mean)) : t;
  }

  // The micro voxels a refresh evaluates: the whole grid until the AABB is
  // known, then the AABB widened by kOccupancyMargin voxels (so that it can grow).
  static constexpr int kOccupancyMargin = 8;
  void refresh_bounds(Vec3i& lo, Vec3i& hi) const {
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
  void refresh_occupancy_part(int part, float decay) {
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
#pragma omp parallel
    {
      std::vector<float> x0(size_t(F) * kLanes), acts(size_t(layout.density_act_floats) * kLanes),
          f(static_cast<size_t>(F));
      const float* params = mlp_params.data();
#pragma omp for schedule(dynamic, 16)
      for (int row = 0; row < rows; ++row) {
        const int y = y_first + 2 * (row % ny), z = z_first + 2 * (row / ny);
        for (int xs = x_first; xs <= hi.x; xs += 2 * kLanes) {
          std::fill(x0.begin(), x0.end(), 0.f);
          int nl = 0;
          for (int x = xs; x <= hi.x && nl < kLanes; x += 2, ++nl) {
            const size_t cell = size_t(linear_index(x, y, z, R));
            const uint64_t h = hash_combine(base, cell);
            const Vec3f p{float(x) + uniform01(h), float(y) + uniform01(mix64(h)), float(z) + uniform01(mix64(h + 1))};
            pyramid.interpolate(p, {x, y, z}, f.data());
            for (int c = 0; c < F; ++c) x0[size_t(c) * kLanes + size_t(nl)] = f[size_t(c)];
          }
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

  void refresh_occupancy() {
    const float decay = std::pow(cfg.occupancy_decay, float(kSweepParts));
    refresh_occupancy_part(int(occ_updates % kSweepParts), decay);
    ++occ_updates;
    occ.rebuild(occupancy_threshold());
  }

  void update_aabb() {
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

  void freeze() {
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
    if (cfg.prune_weight > 0.f) max_weight.assign(occ.density.size(), 0.f);
    phase = Phase::PerCv;
  }

  // Empties the micro voxels whose samples never weighed prune_weight in the
  // per-CV phase (the inside of solids, faint fog), drops the blocks and MLPs
  // left without occupied voxels, and tightens the AABB.
  void prune() {
    const int R = cfg.micro_res;
    Bitmap3 kept(R);
    Vec3i lo{R, R, R}, hi{-1, -1, -1};
    for (int z = 0; z < R; ++z)
      for (int y = 0; y < R; ++y)
        for (int x = 0; x < R; ++x) {
          const size_t i = kept.index(x, y, z);
          if (!occ.micro.get(i) || max_weight[i] < cfg.prune_weight) continue;
          kept.set(i);
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
    const int cr = R / 32;
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

  void start_quantization() {
    if (mse_ema > 0) psnr_float = -10.0 * std::log10(mse_ema);
    if (!max_weight.empty()) prune();
    equalize_mlps();
    float_blocks = blocks.values();
    float_mlps = mlp_params;
    feature_quant = blocks.fit_quantization();
    blocks.set_quantization(feature_quant);
    layer_in_max.assign(size_t(n_mlps) * (layout.density.size() + layout.color.size()), 0.f);
    phase = Phase::Quantize;
  }

  // --- the step -------------------------------------------------------------

  // The pyramid levels read and trained at main-phase step s (bit l: level l).
  uint32_t active_levels(int64_t s) const {
    uint32_t mask = 0;
    for (size_t l = 0; l < cfg.levels.size(); ++l)
      if (cfg.level_unlock_steps.empty() || s >= cfg.level_unlock_steps[l]) mask |= 1u << l;
    return mask;
  }

  void do_step() {
    if (phase == Phase::Done) return;
    using clock = std::chrono::steady_clock;
    auto t = clock::now();
    auto lap = [&](Stage st) {
      const auto now = clock::now();
      stage_s[st] += std::chrono::duration<double>(now - t).count();
      t = now;
    };
    if (phase == Phase::Main && step >= freeze_step()) freeze();
    if (phase == Phase::PerCv && step >= qat_step()) start_quantization();
    lap(kPhase);
    if (phase == Phase::Main) {
      pyramid.set_active_levels(active_levels(step));
      if (step % cfg.occupancy_every == 0) refresh_occupancy();
      if (step >= cfg.aabb_start && (step - cfg.aabb_start) % cfg.aabb_every == 0) update_aabb();
    }
    lap(kOccupancy);
    if (phase == Phase::Quantize) {
      if ((step - qat_step()) % cfg.quant_refit_every == 0 && step != qat_step()) {
        feature_quant = blocks.fit_quantization();
        blocks.set_quantization(feature_quant);
      }
      update_fake_quantized_mlps();
    }
    lap(kPhase);

    Batch& b = batch;
    sample_training_rays(b, n_rays);
    lap(kRays);
    const double density_before = stage_s[kDensity];
    march(b);
    lap(kMarch);
    stage_s[kMarch] -= stage_s[kDensity] - density_before;
    evaluate_color(b);
    lap(kColor);
    const double se = composite_rays(b, true);
    if (phase == Phase::PerCv && !max_weight.empty())
      for (int32_t s : b.order) {
        const size_t cell = size_t(linear_index(b.micro[3 * size_t(s)], b.micro[3 * size_t(s) + 1],
                                                b.micro[3 * size_t(s) + 2], cfg.micro_res));
        max_weight[cell] = std::max(max_weight[cell], b.weight[size_t(s)]);
      }
    lap(kComposite);
    std::vector<float> grad;
    backward_mlps(b, grad, phase == Phase::Quantize);
    if (phase != Phase::Main) add_mlp_tie_gradient(grad);
    lap(kBackward);

    // Feature gradients, slab by slab.
    std::vector<int32_t> active_ids;
    active_ids.reserve(b.order.size());
    for (size_t s = 0; s < b.n_samples; ++s)
      if (b.active[s]) active_ids.push_back(int32_t(s));
    GradientSlabs slabs;
    const float lr = lr_factor(step);
    if (phase == Phase::Main) {
      slabs.build(cfg.micro_res, pyramid.slab_micro(), active_ids, b.micro);
      pyramid.scatter_gradients(slabs, b.pos, b.micro, b.d_feat);
      pyramid.add_tv_gradient(cfg.tv_weight, cfg.tv_levels);
      lap(kScatter);
      ++feature_adam_t;
      pyramid.adam_step(AdamStep(adam_settings(), cfg.lr_features * lr, feature_adam_t));
    } else {
      slabs.build(cfg.micro_res, kMicroPerFine, active_ids, b.micro);
      blocks.scatter_gradients(slabs, b.pos, b.micro, b.d_feat);
      blocks.add_tv_gradient(cfg.block_tv_weight);
      lap(kScatter);
      ++feature_adam_t;
      blocks.adam_step(AdamStep(adam_settings(), cfg.lr_features * lr, feature_adam_t));
    }
    ++mlp_adam_t;
    const AdamStep mstep(adam_settings(), cfg.lr_mlp * lr, mlp_adam_t);
    const int64_t np = int64_t(mlp_params.size());
#pragma omp parallel for schedule(static)
    for (int64_t k = 0; k < np; ++k)
      mstep.update(mlp_params[size_t(k)], mlp_m[size_t(k)], mlp_v[size_t(k)], grad[size_t(k)]);
    lap(kAdam);

    // Running error and the next batch size.
    const double mse = se / (3.0 * b.n_rays);
    mse_ema = mse_ema < 0 ? mse : 0.95 * mse_ema + 0.05 * mse;
    last_rays = b.n_rays;
    last_samples = int64_t(b.n_samples);
    const double ratio = double(cfg.batch_samples) / double(std::max<size_t>(1, b.n_samples));
    n_rays = int(std::clamp<double>(std::round(b.n_rays * std::clamp(ratio, 0.5, 2.0)), cfg.min_rays, cfg.max_rays));
    ++step;
    if (step >= iters) {
      psnr_quantized = mse_ema > 0 ? -10.0 * std::log10(mse_ema) : 0;
      if (phase != Phase::Quantize) psnr_float = psnr_quantized;
      phase = Phase::Done;
      update_fake_quantized_mlps();  // render() then reads the weights export_model(true) writes
    }
  }

  // Pulls every per-CV MLP toward the mean of all of them (mlp_tie_weight):
  // an MLP seen by few samples stays near what the others agree on.
  void add_mlp_tie_gradient(std::vector<float>& grad) const {
    if (!(cfg.mlp_tie_weight > 0.f) || n_mlps < 2) return;
    const size_t P = layout.param_count;
    std::vector<double> mean(P, 0.0);
    for (int m = 0; m < n_mlps; ++m)
      for (size_t k = 0; k < P; ++k) mean[k] += mlp_params[size_t(m) * P + k];
    for (size_t k = 0; k < P; ++k) mean[k] /= double(n_mlps);
    for (int m = 0; m < n_mlps; ++m)
      for (size_t k = 0; k < P; ++k)
        grad[size_t(m) * P + k] += 2.f * cfg.mlp_tie_weight * float(double(mlp_params[size_t(m) * P + k]) - mean[k]);
  }

  // Cross-layer equalization of every MLP (the same functions; less INT8 error).
  void equalize_mlps() {
    const size_t P = layout.param_count;
    for (int m = 0; m < n_mlps; ++m)
      equalize_mlp(layout, cfg.mlp_equalize, &mlp_params[size_t(m) * P], &mlp_m[size_t(m) * P], &mlp_v[size_t(m) * P]);
  }

  void update_fake_quantized_mlps() {
    mlp_eff.resize(mlp_params.size());
    for (int m = 0; m < n_mlps; ++m)
      fake_quantize_mlp(layout, &mlp_params[size_t(m) * layout.param_count], &mlp_eff[size_t(m) * layout.param_count]);
  }

  AdamSettings adam_settings() const { return {cfg.adam_beta1, cfg.adam_beta2, cfg.adam_eps}; }

  // --- export ---------------------------------------------------------------

  SceneModel make_model(bool quantized) const {
    if (phase == Phase::Main || cv_to_mlp.empty()) fail("the model cannot be exported before the occupancy is frozen");
    SceneModel m;
    m.scene_box = cfg.scene_box;
    m.micro_res = cfg.micro_res;
    m.init_grids();
    m.occupancy[int(Tier::Micro)] = occ.micro;
    m.rebuild_upper_tiers();
    const Vec3f vs = m.micro_voxel_size();
    m.object_aabb.lo = m.scene_box.lo + vs * Vec3f{float(occ.aabb_lo.x), float(occ.aabb_lo.y), float(occ.aabb_lo.z)};
    m.object_aabb.hi =
        m.scene_box.lo + vs * Vec3f{float(occ.aabb_hi.x + 1), float(occ.aabb_hi.y + 1), float(occ.aabb_hi.z + 1)};
    m.feature_channels = F;
    m.block_fine_index = blocks.fine_index();
    m.mlp_arch = arch;
    m.mlp_coarse_index = mlp_cv;
    const bool have_snapshot = phase >= Phase::Quantize && !float_blocks.empty();
    if (quantized) {
      // Without a quantization-aware phase (qat_fraction 0) the ranges are fitted now.
      const auto q = phase >= Phase::Quantize && !feature_quant.empty() ? feature_quant : blocks.fit_quantization();
      const auto& v = blocks.values();
      const size_t n = v.size();
      m.features_q4.assign((n + 1) / 2, 0);
      m.feature_quant.scale.resize(size_t(F));
      m.feature_quant.zero_point.resize(size_t(F));
      for (int c = 0; c < F; ++c) {
        m.feature_quant.scale[size_t(c)] = q[size_t(c)].scale;
        m.feature_quant.zero_point[size_t(c)] = uint8_t(q[size_t(c)].zero_point);
      }
      for (size_t i = 0; i < n; ++i) {
        const int code = q[i % size_t(F)].quantize(v[i]);
        m.features_q4[i >> 1] |= uint8_t((i & 1) ? code << 4 : code);
      }
      const size_t n_layers = layout.density.size() + layout.color.size();
      std::vector<float> fallback(n_layers, 0.f);
      for (size_t k = 0; k < layer_in_max.size(); ++k)
        fallback[k % n_layers] = std::max(fallback[k % n_layers], layer_in_max[k]);
      // Without a quantization-aware phase the MLPs are equalized now (a copy).
      std::vector<float> equalized;
      const float* params = mlp_params.data();
      if (phase < Phase::Quantize && cfg.mlp_equalize > 0.f) {
        equalized = mlp_params;
        for (size_t mi = 0; mi < mlp_cv.size(); ++mi)
          equalize_mlp(layout, cfg.mlp_equalize, &equalized[mi * layout.param_count], nullptr, nullptr);
        params = equalized.data();
      }
      for (size_t mi = 0; mi < mlp_cv.size(); ++mi) {
        std::vector<float> mx(n_layers, 0.f);
        for (size_t k = 0; k < n_layers; ++k) {
          const size_t j = mi * n_layers + k;
          mx[k] = j < layer_in_max.size() && layer_in_max[j] > 0.f ? layer_in_max[j] : fallback[k];
        }
        m.mlps_q8.push_back(quantize_mlp(layout, &params[mi * layout.param_count], mx));
      }
    } else {
      m.features_f32 = have_snapshot ? float_blocks : blocks.values();
      const auto& p = have_snapshot ? float_mlps : mlp_params;
      for (size_t mi = 0; mi < mlp_cv.size(); ++mi)
        m.mlps_f32.push_back(unflatten_mlp(layout, &p[mi * layout.param_count]));
    }
    nlohmann::json meta;
    meta["producer"] = "edrnr train";
    meta["dataset"] = data.root.string();
    meta["split"] = data.split;
    meta["frames"] = data.frames.size();
    meta["form"] = quantized ? "quantized" : "float";
    meta["iters"] = iters;
    meta["seed"] = cfg.seed;
    meta["levels"] = cfg.levels;
    meta["train_psnr_float_db"] = std::round(psnr_float * 100) / 100;
    if (quantized) meta["train_psnr_quantized_db"] = std::round(psnr_quantized * 100) / 100;
    m.metadata_json = meta.dump();
    m.finalize();
    return m;
  }

  // --- checkpoints ------------------------------------------------------------

  std::vector<uint8_t> save() const {
    CheckpointWriter w;
    w.put_string("config", to_yaml(cfg));
    w.put_value("dataset_fingerprint", dataset_fingerprint(data));
    w.put_value("step", step);
    w.put_value("iters", iters);
    w.put_value("iters_fixed", uint8_t(iters_fixed));
    w.put_value("phase", int32_t(phase));
    w.put_value("n_rays", int32_t(n_rays));
    w.put_value("mse_ema", mse_ema);
    w.put_value("psnr_float", psnr_float);
    w.put_value("psnr_quantized", psnr_quantized);
    w.put_value("occ_updates", occ_updates);
    w.put_value("feature_adam_t", feature_adam_t);
    w.put_value("mlp_adam_t", mlp_adam_t);
    w.put("occ_density", occ.density);
    w.put("occ_micro", occ.micro.words());
    w.put_value("occ_aabb_known", uint8_t(occ.aabb_known));
    const int32_t aabb[6] = {occ.aabb_lo.x, occ.aabb_lo.y, occ.aabb_lo.z, occ.aabb_hi.x, occ.aabb_hi.y, occ.aabb_hi.z};
    w.put_bytes("occ_aabb", aabb, sizeof aabb);
    if (phase == Phase::Main) {
      for (size_t li = 0; li < pyramid.levels().size(); ++li) {
        const auto& L = pyramid.levels()[li];
        w.put(fmt::format("level{}_value", li), L.value);
        w.put(fmt::format("level{}_m", li), L.adam.m);
        w.put(fmt::format("level{}_v", li), L.adam.v);
      }
    } else {
      w.put("block_fine_index", blocks.fine_index());
      w.put("block_value", blocks.values());
      w.put("block_m", const_cast<BlockFeatures&>(blocks).adam().m);
      w.put("block_v", const_cast<BlockFeatures&>(blocks).adam().v);
      w.put("mlp_cv", mlp_cv);
    }
    std::vector<float> q;
    for (const auto& c : feature_quant) q.insert(q.end(), {c.scale, float(c.zero_point)});
    w.put("feature_quant", q);
    w.put("mlp_params", mlp_params);
    w.put("mlp_m", mlp_m);
    w.put("mlp_v", mlp_v);
    w.put("layer_in_max", layer_in_max);
    w.put("max_weight", max_weight);
    w.put("float_blocks", float_blocks);
    w.put("float_mlps", float_mlps);
    return w.finish();
  }

  void load(const CheckpointReader& r) {
    if (r.get_value<uint64_t>("dataset_fingerprint") != dataset_fingerprint(data))
      fail("{}: the checkpoint was made from a different dataset (or split, or downscale) than {}", r.source(),
           data.root.string());
    step = r.get_value<int64_t>("step");
    iters = r.get_value<int64_t>("iters");
    iters_fixed = r.get_value<uint8_t>("iters_fixed") != 0;
    phase = Phase(r.get_value<int32_t>("phase"));
    if (int(phase) < 0 || int(phase) > int(Phase::Done)) fail("{}: bad phase", r.source());
    n_rays = r.get_value<int32_t>("n_rays");
    mse_ema = r.get_value<double>("mse_ema");
    psnr_float = r.get_value<double>("psnr_float");
    psnr_quantized = r.get_value<double>("psnr_quantized");
    occ_updates = r.get_value<int64_t>("occ_updates");
    feature_adam_t = r.get_value<int64_t>("feature_adam_t");
    mlp_adam_t = r.get_value<int64_t>("mlp_adam_t");
    // Every value a later step indexes or sizes with is checked (a checkpoint
    // that passed its CRC may still have been made by another build, or edited).
    auto bad = [&](const char* what, auto value) {
      fail("{}: the checkpoint's {} ({}) is out of range (corrupt or from another edrnr)", r.source(), what, value);
    };
    if (iters < 1 || iters > (int64_t{1} << 40)) bad("step count", iters);
    if (step < 0 || step > iters) bad("step", step);
    if ((phase == Phase::Done) != (step == iters)) bad("phase", phase_name(phase));
    if (phase == Phase::Main && step > freeze_step()) bad("main-phase step", step);
    if (n_rays < cfg.min_rays || n_rays > cfg.max_rays) bad("ray count", n_rays);
    if (occ_updates < 0 || feature_adam_t < 0 || mlp_adam_t < 0) bad("update counters", occ_updates);
    if (!std::isfinite(mse_ema)) bad("running loss", mse_ema);
    auto expect_size = [&](const char* name, size_t got, size_t want) {
      if (got != want) fail("{}: section '{}' has {} items, expected {}", r.source(), name, got, want);
    };
    // Parameters, their Adam moments and snapshots: finite numbers only.
    auto floats = [&](const std::string& name) {
      std::vector<float> v = r.get<float>(name);
      for (size_t i = 0; i < v.size(); ++i)
        if (!std::isfinite(v[i]))
          fail("{}: section '{}' item {} is not a finite number (corrupt checkpoint)", r.source(), name, i);
      return v;
    };
    occ.density = r.get<float>("occ_density");
    expect_size("occ_density", occ.density.size(), size_t(cfg.micro_res) * cfg.micro_res * cfg.micro_res);
    auto words = r.get<uint64_t>("occ_micro");
    expect_size("occ_micro", words.size(), occ.micro.words().size());
    occ.micro.words() = std::move(words);
    occ.aabb_known = r.get_value<uint8_t>("occ_aabb_known") != 0;
    auto aabb = r.get<int32_t>("occ_aabb");
    expect_size("occ_aabb", aabb.size(), 6);
    occ.aabb_lo = {aabb[0], aabb[1], aabb[2]};
    occ.aabb_hi = {aabb[3], aabb[4], aabb[5]};
    for (int a = 0; a < 3; ++a)
      if (occ.aabb_known && (aabb[a] < 0 || aabb[a] > aabb[3 + a] || aabb[3 + a] >= cfg.micro_res))
        bad("object AABB", fmt::format("[{}, {}]", aabb[a], aabb[3 + a]));
    occ.rebuild_macro();
    if (phase == Phase::Main) {
      pyramid = FeaturePyramid(cfg.micro_res, cfg.levels, cfg.seed, 0.f);
      for (size_t li = 0; li < pyramid.levels().size(); ++li) {
        auto& L = pyramid.levels()[li];
        const size_t n = L.value.size();
        L.value = floats(fmt::format("level{}_value", li));
        L.adam.m = floats(fmt::format("level{}_m", li));
        L.adam.v = floats(fmt::format("level{}_v", li));
        expect_size("level values", L.value.size(), n);
        expect_size("level Adam m", L.adam.m.size(), n);
        expect_size("level Adam v", L.adam.v.size(), n);
      }
      n_mlps = 1;
    } else {
      auto fine_index = r.get<uint32_t>("block_fine_index");
      blocks = BlockFeatures(cfg.micro_res, F, std::move(fine_index), floats("block_value"));
      blocks.adam().m = floats("block_m");
      blocks.adam().v = floats("block_v");
      expect_size("block_m", blocks.adam().m.size(), blocks.values().size());
      expect_size("block_v", blocks.adam().v.size(), blocks.values().size());
      mlp_cv = r.get<uint32_t>("mlp_cv");
      const int cr = cfg.micro_res / 32;
      cv_to_mlp.assign(size_t(cr) * cr * cr, -1);
      for (size_t i = 0; i < mlp_cv.size(); ++i) {
        if (mlp_cv[i] >= cv_to_mlp.size()) fail("{}: MLP coarse index out of range", r.source());
        cv_to_mlp[mlp_cv[i]] = int32_t(i);
      }
      n_mlps = std::max<int>(1, int(mlp_cv.size()));
      // Every occupied micro voxel must have its feature block and its MLP
      // (training looks both up for each sample).
      const int R = cfg.micro_res, fr = R / kMicroPerFine;
      const auto& words = occ.micro.words();
      for (size_t w = 0; w < words.size(); ++w)
        for (uint64_t bits = words[w]; bits; bits &= bits - 1) {
          const size_t i = w * 64 + size_t(std::countr_zero(bits));
          const int x = int(i % size_t(R)), y = int(i / size_t(R) % size_t(R)), z = int(i / (size_t(R) * size_t(R)));
          const uint32_t fine = linear_index(x / kMicroPerFine, y / kMicroPerFine, z / kMicroPerFine, fr);
          if (blocks.block_of_fine(fine) < 0 || cv_to_mlp[size_t(linear_index(x >> 5, y >> 5, z >> 5, cr))] < 0)
            bad("occupied micro voxel without a feature block or MLP", fmt::format("{}, {}, {}", x, y, z));
        }
    }
    auto q = r.get<float>("feature_quant");
    if (!q.empty() && q.size() != 2 * size_t(F)) expect_size("feature_quant", q.size(), 2 * size_t(F));
    if (q.empty() && phase == Phase::Quantize) expect_size("feature_quant", q.size(), 2 * size_t(F));
    for (size_t i = 0; i + 1 < q.size(); i += 2)
      if (!(q[i] > 0.f) || !std::isfinite(q[i]) || !std::isfinite(1.f / q[i]) ||
          !(q[i + 1] >= 0.f && q[i + 1] <= 15.f) || q[i + 1] != std::floor(q[i + 1]))
        bad("INT4 channel", fmt::format("scale {}, zero point {}", q[i], q[i + 1]));
    feature_quant.clear();
    for (size_t i = 0; i + 1 < q.size(); i += 2) {
      Int4Channel c = int4_channel_for_range(0.f, 0.f);
      c.scale = q[i];
      c.inv_scale = 1.f / c.scale;
      c.zero_point = int(q[i + 1]);
      feature_quant.push_back(c);
    }
    if (phase == Phase::Quantize || phase == Phase::Done) blocks.set_quantization(feature_quant);
    mlp_params = floats("mlp_params");
    mlp_m = floats("mlp_m");
    mlp_v = floats("mlp_v");
    expect_size("mlp_params", mlp_params.size(), size_t(n_mlps) * layout.param_count);
    expect_size("mlp_m", mlp_m.size(), mlp_params.size());
    expect_size("mlp_v", mlp_v.size(), mlp_params.size());
    layer_in_max = floats("layer_in_max");
    const size_t n_layers = layout.density.size() + layout.color.size();
    if (phase == Phase::Quantize) expect_size("layer_in_max", layer_in_max.size(), size_t(n_mlps) * n_layers);
    if (!layer_in_max.empty()) expect_size("layer_in_max", layer_in_max.size(), size_t(n_mlps) * n_layers);
    if (phase >= Phase::Quantize) update_fake_quantized_mlps();
    max_weight = r.get<float>("max_weight");
    if (!max_weight.empty()) expect_size("max_weight", max_weight.size(), occ.density.size());
    float_blocks = floats("float_blocks");
    float_mlps = floats("float_mlps");
    if (!float_blocks.empty() || !float_mlps.empty()) {
      expect_size("float_blocks", float_blocks.size(), phase == Phase::Main ? 0 : blocks.values().size());
      expect_size("float_mlps", float_mlps.size(), mlp_params.size());
    }
  }
};

// ---------------------------------------------------------------------------

Trainer::Trainer(const Dataset& data, const TrainConfig& config) : s_(std::make_unique<State>(data, config)) {
  s_->fresh_init();
}

Trainer::Trainer(const Dataset& data, const std::vector<uint8_t>& checkpoint, const std::string& source) {
  CheckpointReader r(checkpoint, source);
  TrainConfig cfg = parse_train_config(r.get_string("config"), source + " (config)");
  s_ = std::make_unique<State>(data, cfg);
  s_->load(r);
}

Trainer::~Trainer() = default;

TrainConfig Trainer::checkpoint_config(const std::vector<uint8_t>& checkpoint, const std::string& source) {
  CheckpointReader r(checkpoint, source);
  return parse_train_config(r.get_string("config"), source + " (config)");
}

const TrainConfig& Trainer::config() const { return s_->cfg; }
bool Trainer::done() const { return s_->phase == Phase::Done; }
void Trainer::step() { s_->do_step(); }
std::vector<uint8_t> Trainer::checkpoint() const { return s_->save(); }
SceneModel Trainer::export_model(bool quantized) const { return s_->make_model(quantized); }

void Trainer::set_iters(int64_t iters) {
  if (s_->phase != Phase::Main || iters <= s_->step) fail("set_iters: too late to change the number of steps");
  s_->iters = iters;
  s_->iters_fixed = true;
}

TrainStats Trainer::stats() const {
  TrainStats t;
  t.step = s_->step;
  t.iters = s_->iters;
  t.phase = s_->phase;
  t.rays = s_->last_rays;
  t.samples = s_->last_samples;
  t.loss = std::max(0.0, s_->mse_ema);
  t.psnr = s_->mse_ema > 0 ? -10.0 * std::log10(s_->mse_ema) : 0.0;
  t.psnr_float = s_->psnr_float;
  t.psnr_quantized = s_->psnr_quantized;
  t.blocks = s_->phase == Phase::Main ? 0 : s_->blocks.block_count();
  t.mlps = s_->phase == Phase::Main ? 0 : s_->mlp_cv.size();
  for (int i = 0; i < kStages; ++i) t.stage_seconds.emplace_back(kStageNames[i], s_->stage_s[i]);
  return t;
}

Image Trainer::render(const Camera& camera) const {
  State& s = *s_;
  Image img(camera.width, camera.height, 3);
  const int64_t n = int64_t(camera.width) * camera.height;
  constexpr int kRaysPerBatch = 4096;
  Batch b;
  for (int64_t first = 0; first < n; first += kRaysPerBatch) {
    const int cnt = int(std::min<int64_t>(kRaysPerBatch, n - first));
    s.resize_rays(b, cnt);
    for (int i = 0; i < cnt; ++i) {
      const int64_t p = first + i;
      s.set_ray(b, i, camera.pixel_ray(int(p % camera.width), int(p / camera.width)));
      for (int c = 0; c < 3; ++c) {
        b.target[3 * size_t(i) + size_t(c)] = 0.f;
        b.background[3 * size_t(i) + size_t(c)] = s.cfg.background[c];
      }
    }
    s.forward(b);
    for (int i = 0; i < cnt; ++i) {
      const int64_t p = first + i;
      float* px = img.at(int(p % camera.width), int(p / camera.width));
      for (int c = 0; c < 3; ++c) px[c] = b.pixel[3 * size_t(i) + size_t(c)];
    }
  }
  return img;
}

bool Trainer::run(const TrainOptions& options) {
  State& s = *s_;
  if (options.threads > 0) omp_set_num_threads(options.threads);
  using clock = std::chrono::steady_clock;
  const auto t_start = clock::now();
  auto t_checkpoint = t_start;
  auto t_print = t_start;
  double steps_per_s = 0;
  int64_t rate_step = s.step;
  auto rate_time = t_start;
  // --minutes: the time at each step of this run, to fix the step count at
  // plan_step (or once a quarter of the budget is spent) from the speed over
  // the last 40 % of the steps since the run started.
  std::vector<double> step_seconds;
  auto log = [&](const std::string& m) {
    if (options.log) options.log(m);
  };
  auto write_checkpoint = [&]() {
    if (options.checkpoint_path.empty()) return;
    write_file_atomic(options.checkpoint_path, s.save());
    log(fmt::format("checkpoint at step {} written to {}", s.step, options.checkpoint_path.string()));
  };
  // A periodic checkpoint is a safety net: failing to write one (a full disk)
  // must not end the run it protects. The previous checkpoint stays intact.
  auto try_periodic_checkpoint = [&]() {
    try {
      write_checkpoint();
    } catch (const Error& e) {
      const std::string m = fmt::format("checkpoint at step {} not written ({}); training goes on", s.step, e.what());
      if (options.warn)
        options.warn(m);
      else
        std::fprintf(stderr, "edrnr: warning: %s\n", m.c_str());
    }
  };
  Phase last_phase = s.phase;
  bool line_open = false;
  while (s.phase != Phase::Done) {
    if (options.stop_after >= 0 && s.step >= options.stop_after) break;
    if (options.interrupt && options.interrupt->load()) break;
    // --minutes: fix the number of steps from the measured speed.
    if (s.cfg.minutes > 0 && !s.iters_fixed && s.phase == Phase::Main) {
      const double elapsed = std::chrono::duration<double>(clock::now() - t_start).count();
      step_seconds.push_back(elapsed);
      const int64_t done = int64_t(step_seconds.size()) - 1;  // steps timed in this run
      if (done >= 10 && (s.step >= s.cfg.plan_step || elapsed >= 0.25 * s.cfg.minutes * 60.0)) {
        const int64_t from = done * 6 / 10;
        const double per_step = (elapsed - step_seconds[size_t(from)]) / double(done - from);
        const double left = s.cfg.minutes * 60.0 - elapsed;
        // Keep a tenth of the budget for the freeze, the slower final phases and the export.
        int64_t n = s.step + std::max<int64_t>(1, int64_t(0.9 * left / std::max(per_step, 1e-6)));
        // The main phase must not have ended already: a replay with --iters n
        // changes phase at the same step.
        const double main_share = 1.0 - double(s.cfg.per_cv_fraction) - double(s.cfg.qat_fraction);
        n = std::max<int64_t>(n, int64_t(std::ceil(double(s.step + 1) / main_share)) + 1);
        set_iters(n);
        log(fmt::format("{:.3f} s per step over steps {}..{}: training for {} steps", per_step, s.step - (done - from),
                        s.step, s.iters));
      }
    }
    s.do_step();
    if (s.phase != last_phase) {
      if (line_open) std::fputc('\n', stderr), line_open = false;
      log(fmt::format("step {}: {} phase ({} blocks, {} MLPs)", s.step, phase_name(s.phase),
                      s.phase == Phase::Main ? 0 : s.blocks.block_count(), s.mlp_cv.size()));
      last_phase = s.phase;
    }
    const auto now = clock::now();
    if (std::chrono::duration<double>(now - rate_time).count() >= 2.0) {
      steps_per_s = double(s.step - rate_step) / std::chrono::duration<double>(now - rate_time).count();
      rate_step = s.step;
      rate_time = now;
    }
    if (!options.progress && options.progress_log_seconds > 0 &&
        std::chrono::duration<double>(now - t_print).count() >= options.progress_log_seconds) {
      t_print = now;
      const TrainStats st = stats();
      const double eta = steps_per_s > 0 ? double(st.iters - st.step) / steps_per_s : 0;
      log(fmt::format("step {}/{}  {:.2f} steps/s  ETA {}:{:02d}  loss {:.5f}  PSNR {:.2f} dB  {}", st.step, st.iters,
                      steps_per_s, int(eta) / 60, int(eta) % 60, st.loss, st.psnr, phase_name(st.phase)));
    }
    if (options.progress && std::chrono::duration<double>(now - t_print).count() >= 0.5) {
      t_print = now;
      const TrainStats st = stats();
      const double eta = steps_per_s > 0 ? double(st.iters - st.step) / steps_per_s : 0;
      std::fprintf(stderr, "\r  step %lld/%lld  %.2f steps/s  ETA %d:%02d  loss %.5f  PSNR %.2f dB  %s  %d rays  ",
                   (long long)st.step, (long long)st.iters, steps_per_s, int(eta) / 60, int(eta) % 60, st.loss, st.psnr,
                   phase_name(st.phase), st.rays);
      std::fflush(stderr);
      line_open = true;
    }
    if (std::chrono::duration<double>(now - t_checkpoint).count() >= options.checkpoint_minutes * 60.0 &&
        s.phase != Phase::Done) {
      if (line_open) std::fputc('\n', stderr), line_open = false;
      try_periodic_checkpoint();
      t_checkpoint = clock::now();
    }
  }
  if (line_open) std::fputc('\n', stderr);
  if (s.phase != Phase::Done) {
    write_checkpoint();
    return false;
  }
  return true;
}

}  // namespace edrnr::train
