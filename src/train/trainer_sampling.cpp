// Trainer::State, rays and sampling (train/trainer_state.h): the training rays
// of a step, the march along them, both nets forward, compositing with the
// loss gradient, and backward through the nets.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "model/mlp.h"
#include "render/traversal.h"
#include "train/mlp_kernels.h"
#include "train/rng.h"
#include "train/trainer_state.h"
#include "train/volume.h"

namespace edrnr::train {

using trainer_detail::Batch;
using trainer_detail::kDensity;
using trainer_detail::WorkItem;

namespace {

constexpr int kItemSamples = 1024;  // samples per work item: one MLP gradient partial each
constexpr int kFirstRoundSamples = 16;
constexpr int kMaxRoundSamples = 256;

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

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

// --- rays ---------------------------------------------------------------

void Trainer::State::set_ray(Batch& b, int i, const Ray& r) {
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

void Trainer::State::resize_rays(Batch& b, int n) {
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
  b.ray_cell.resize(cfg.error_map_share > 0.f ? size_t(n) : 0);
  b.ray_weight.resize(cfg.error_map_share > 0.f && cfg.error_map_unbiased ? size_t(n) : 0);
}

void Trainer::State::init_error_map() {
  err_map = ErrorMap();
  if (!(cfg.error_map_share > 0.f)) return;
  std::vector<int> w, h;
  for (const Frame& f : data.frames) {
    w.push_back(f.image.width);
    h.push_back(f.image.height);
  }
  // Every cell starts at the largest squared error of a pixel (1 per
  // channel): unseen cells are drawn as often as the worst seen ones.
  err_map = ErrorMap(w, h, cfg.error_map_cell, 1.f);
}

void Trainer::State::update_error_map(const Batch& b) {
  if (err_map.empty()) return;
  for (int i = 0; i < b.n_rays; ++i) err_map.update(b.ray_cell[size_t(i)], float(b.ray_sq_err[size_t(i)] / 3.0));
}

void Trainer::State::sample_training_rays(Batch& b, int n) {
  resize_rays(b, n);
  const uint64_t total = pixel_start.back();
  const uint64_t base = hash3(cfg.seed, uint64_t(RngStream::Rays), uint64_t(step));
  // With the error map, a share of the rays through pixels drawn from it.
  const bool mapped = !err_map.empty();
  if (mapped) err_map.rebuild();
  const double share = cfg.error_map_share;
  // Ray i's pixel: its frame, x and y (and with the map, its cell).
  const auto pixel_of = [&](int i, size_t& f, int& x, int& y, uint32_t& cell) {
    const uint64_t h = hash_combine(base, uint64_t(i));
    if (mapped && err_map.total() > 0 && double(uniform01(hash_combine(h, 5))) < share) {
      const MapPixel p = err_map.draw(double(uniform01(hash_combine(h, 6))), mix64(hash_combine(h, 7)));
      f = p.frame;
      x = p.x;
      y = p.y;
      cell = p.cell;
      return;
    }
    const uint64_t px = h % total;
    f = size_t(std::upper_bound(pixel_start.begin(), pixel_start.end(), px) - pixel_start.begin()) - 1;
    const uint64_t local = px - pixel_start[f];
    const uint64_t w = uint64_t(data.frames[f].image.width);
    x = int(local % w);
    y = int(local / w);
    if (mapped) cell = err_map.cell_of(uint32_t(f), x, y);
  };
  // The pixels lie anywhere in the images (a gigabyte for 100 RGBA frames of
  // 800 x 800): each is fetched this many rays ahead.
  constexpr int kAhead = 8;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kAhead < n) {
      size_t fa;
      int xa, ya;
      uint32_t cell_ahead = 0;
      pixel_of(i + kAhead, fa, xa, ya, cell_ahead);
      __builtin_prefetch(data.frames[fa].image.at(xa, ya));
    }
    uint32_t cell = 0;
    size_t f;
    int x, y;
    pixel_of(i, f, x, y, cell);
    if (mapped) {
      b.ray_cell[size_t(i)] = cell;
      if (!b.ray_weight.empty()) {
        // The pixel's uniform probability over its probability in the mixture.
        const double p_uniform = 1.0 / double(total);
        const double p_mix =
            err_map.total() > 0 ? (1.0 - share) * p_uniform + share * err_map.probability(cell) : p_uniform;
        b.ray_weight[size_t(i)] = float(p_uniform / p_mix);
      }
    }
    const Frame& fr = data.frames[f];
    const uint64_t h = mix64(hash_combine(base, uint64_t(i)));
    Ray ray = cfg.pixel_jitter  // a point of the pixel's square, drawn apart from the background's colour
                  ? fr.camera.ray_at(double(x) + double(uniform01(hash_combine(h, 3))),
                                     double(y) + double(uniform01(hash_combine(h, 4))))
                  : fr.camera.pixel_ray(x, y);
    if (cfg.depth_jitter > 0.f) {
      // The samples sit at (k + 1/2) delta from the origin: moving the origin
      // along the ray moves them all by the same distance.
      const double u = double(uniform01(hash_combine(h, 8))) - 0.5;
      ray.origin = ray.origin + ray.dir * (u * double(cfg.depth_jitter) * double(delta));
    }
    set_ray(b, i, ray);
    const float* t = fr.image.at(x, y);
    float* bg = &b.background[3 * size_t(i)];
    if (rgba) {
      // Premultiplied: target = rgb a + (1 - a) bg.
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

int32_t Trainer::State::mlp_of_micro(int x, int y, int z) const {
  if (phase == Phase::Main) return 0;
  const int cr = cfg.micro_res / 32;
  return cv_to_mlp[linear_index(x >> 5, y >> 5, z >> 5, cr)];
}

const float* Trainer::State::mlp_weights(int m) const {
  const auto& p = phase >= Phase::Quantize ? mlp_eff : mlp_params;
  return p.data() + size_t(m) * layout.param_count;
}

const float* Trainer::State::act_steps_of(int m) const {
  if (act_steps.empty()) return nullptr;
  return act_steps.data() + size_t(m) * (layout.density.size() + layout.color.size());
}

const float* Trainer::State::color_steps(int m) const {
  const float* steps = act_steps_of(m);
  return steps ? steps + layout.density.size() : nullptr;
}

void Trainer::State::interpolate(const Vec3f& p, const Vec3i& m, float* out) const {
  if (phase == Phase::Main)
    pyramid.interpolate(p, m, out);
  else
    blocks.interpolate(p, m, out);
}

void Trainer::State::prefetch_features(const Vec3i& m) const {
  if (phase == Phase::Main)
    pyramid.prefetch(m);
  else
    blocks.prefetch(m);
}

const FastSkipGrid& Trainer::State::march_grid() const {
  if (march_grid_generation_ != occ.generation) {
    march_grid_ = FastSkipGrid(occ.fine, occ.micro);
    march_grid_generation_ = occ.generation;
  }
  return march_grid_;
}

// Marches every ray in rounds; evaluates density for each new sample and
// stops a ray once its transmittance falls below the threshold. Fills the
// active samples (b.order, b.ray_first, b.ray_count). The samples of a ray
// are its candidates k_next..k_last in occupied micro voxels, found by the
// fast renderer's vector march (render/fast_march.h) over the occupancy.
void Trainer::State::march(Batch& b) const {
  b.n_samples = 0;
  const int n = b.n_rays;
  const FastSkipGrid& grid = march_grid();
  std::vector<int32_t> live;
  for (int i = 0; i < n; ++i)
    if (b.alive[size_t(i)]) live.push_back(i);
  b.marchers.resize(size_t(n));
#pragma omp parallel for schedule(static)
  for (size_t li = 0; li < live.size(); ++li) {
    const size_t i = size_t(live[li]);
    b.marchers[i].set_up_range(grid, b.mray[i], b.k_next[i], b.k_last[i]);
  }
  std::vector<std::vector<int32_t>> seg_begin, seg_used;  // per round, per live ray index
  std::vector<std::vector<int32_t>> round_rays;
  std::vector<int32_t> count;
  for (int round = 0; !live.empty(); ++round) {
    const int K = std::min(kMaxRoundSamples, kFirstRoundSamples << std::min(round, 8));
    const size_t L = live.size();
    count.assign(L, 0);
    b.found.resize(L * size_t(K));
    b.ended.assign(L, 0);
    const int groups = int((L + kFastMarchGroup - 1) / kFastMarchGroup);
#pragma omp parallel
    {
      std::vector<int32_t> blocks(size_t(kFastMarchGroup) * size_t(K));
#pragma omp for schedule(dynamic, 16)
      for (int g = 0; g < groups; ++g) {
        const size_t l0 = size_t(g) * kFastMarchGroup;
        const int m = int(std::min<size_t>(kFastMarchGroup, L - l0));
        FastMarcher* group[kFastMarchGroup];
        int counts[kFastMarchGroup];
        bool ended[kFastMarchGroup];
        for (int j = 0; j < m; ++j) group[j] = &b.marchers[size_t(live[l0 + size_t(j)])];
        fast_march_group(group, m, K, &b.found[l0 * size_t(K)], blocks.data(), counts, ended);
        for (int j = 0; j < m; ++j) {
          count[l0 + size_t(j)] = counts[j];
          b.ended[l0 + size_t(j)] = ended[j];
        }
      }
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
        const MarchSample& f = b.found[li * size_t(K) + size_t(c)];
        for (int a = 0; a < 3; ++a) {
          b.pos[3 * s + size_t(a)] = f.p_micro[a];
          b.micro[3 * s + size_t(a)] = int16_t(f.voxel[a]);
        }
        b.ray[s] = live[li];
        b.cand[s] = int32_t(f.k);
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
      if (T < cfg.transmittance_min || b.ended[li]) b.alive[size_t(i)] = 0;
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
void Trainer::State::evaluate_density(Batch& b, size_t s0, size_t s1) const {
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
        const float* steps = act_steps_of(w.mlp);
        if (steps) quantize_block(x0.data(), F, steps[0], -kActivationMax - 1.f, kActivationMax);
        net_forward(layout.density, params, x0.data(), acts.data(), -1, steps);
        const float* out = acts.data() + size_t(layout.density_act_floats - G) * kLanes;
        for (int l = 0; l < nl; ++l) {
          const size_t s = size_t(grouped[size_t(c0 + l)]);
          for (int c = 0; c < G; ++c) b.geo[s * size_t(G) + size_t(c)] = out[size_t(c) * kLanes + size_t(l)];
        }
      }
    }
  }
}

void Trainer::State::gather_color_input(const Batch& b, const std::vector<int32_t>& ids, int32_t c0, int nl, float* x0,
                                        const float* steps) const {
  const int in = G + DD;
  std::fill(x0, x0 + size_t(in) * kLanes, 0.f);
  for (int l = 0; l < nl; ++l) {
    const size_t s = size_t(ids[size_t(c0 + l)]);
    for (int c = 0; c < G; ++c) x0[size_t(c) * kLanes + size_t(l)] = b.geo[s * size_t(G) + size_t(c)];
    const float* d = &b.dir_enc[size_t(b.ray[s]) * size_t(DD)];
    for (int c = 0; c < DD; ++c) x0[size_t(G + c) * kLanes + size_t(l)] = d[c];
  }
  if (steps) {  // the density outputs at the colour net's step, the direction codes at their own
    quantize_block(x0, G, steps[0], -kActivationMax - 1.f, kActivationMax);
    quantize_block(x0 + size_t(G) * kLanes, DD, kDirectionStep, -kActivationMax, kActivationMax);
  }
}

// Colour of every active sample; colour-net activations kept per chunk.
void Trainer::State::evaluate_color(Batch& b) const {
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
        const float* steps = color_steps(w.mlp);
        gather_color_input(b, b.col_ids, c0, nl, x0.data(), steps);
        float* acts = &b.col_acts[size_t(chunk) * act_chunk];
        net_forward(layout.color, params, x0.data(), acts, -1, steps);
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
double Trainer::State::composite_rays(Batch& b, bool with_grad) const {
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
      const float wi = b.ray_weight.empty() ? 1.f : b.ray_weight[size_t(i)];
      double se = 0;
      float d_pixel[3];
      for (int c = 0; c < 3; ++c) {
        b.pixel[3 * size_t(i) + size_t(c)] = r.rgb[c];
        const float e = r.rgb[c] - b.target[3 * size_t(i) + size_t(c)];
        se += double(e) * double(e);
        d_pixel[c] = 2.f * e * inv_n * wi;
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
        distortion_backward(raw.data(), t.data(), cnt, delta, interval, dist_scale * wi, d_raw.data());
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
void Trainer::State::backward_mlps(Batch& b, std::vector<float>& grad, bool calibrate) {
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
        const float* dsteps = act_steps_of(w.mlp);
        gather_color_input(b, b.col_ids, c0, nl, xc.data(), color_steps(w.mlp));
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
        if (dsteps) quantize_block(xd.data(), F, dsteps[0], -kActivationMax - 1.f, kActivationMax);
        net_forward(layout.density, params, xd.data(), actd.data(), -1, dsteps);
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
double Trainer::State::forward(Batch& b) const {
  march(b);
  evaluate_color(b);
  return composite_rays(b, false);
}

}  // namespace edrnr::train
