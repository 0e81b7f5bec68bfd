#include "render/fast.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "model/mlp.h"
#include "render/fast_kernels.h"
#include "render/fast_march.h"
#include "render/traversal.h"

namespace edrnr {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kTile = 16;                 // tile edge, pixels
constexpr int kTileRays = kTile * kTile;  // rays per packet (a multiple of every SIMD width)
// The rays' start distances (tile_start_distances) are kept per square of
// this many pixels: a fine voxel of lego spans about 6 pixels at 800x800.
constexpr int kStartCell = 4;
constexpr int kFirstRoundSamples = 4;  // samples a ray hands over in the first round
// ... doubling each round up to this (16 at the step of half a micro voxel:
// 1 % less time than 8).
constexpr int kMaxRoundSamples = 16;
// A ray whose transmittance is already below kDimTransmittance is likely to
// end within a sample or two: it hands over at most kDimRoundSamples per
// round, so fewer samples past its end run through an MLP.
constexpr float kDimTransmittance = 0.9f;
constexpr int kDimRoundSamples = 2;

// Interleaves the bits of x and y (x in the even bits).
uint64_t morton(uint32_t x, uint32_t y) {
  uint64_t r = 0;
  for (int b = 0; b < 32; ++b) r |= (uint64_t((x >> b) & 1) << (2 * b)) | (uint64_t((y >> b) & 1) << (2 * b + 1));
  return r;
}

struct Tile {
  int x0, y0, x1, y1;
};

// Tiles of the image in Z order.
std::vector<Tile> z_order_tiles(int W, int H) {
  const int tx = (W + kTile - 1) / kTile, ty = (H + kTile - 1) / kTile;
  std::vector<std::pair<uint64_t, Tile>> keyed;
  for (int j = 0; j < ty; ++j)
    for (int i = 0; i < tx; ++i)
      keyed.push_back({morton(uint32_t(i), uint32_t(j)),
                       Tile{i * kTile, j * kTile, std::min(W, (i + 1) * kTile), std::min(H, (j + 1) * kTile)}});
  std::sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Tile> tiles;
  for (const auto& k : keyed) tiles.push_back(k.second);
  return tiles;
}

// Whether no pixel ray of the tile can meet `box`: the rays through its
// pixel centres lie in the cone spanned by its four corner rays, and the box
// lies wholly outside one of the cone's side planes, by a margin far above
// the rounding of a ray's direction. Conservative: false when unsure
// (degenerate tiles of one pixel row or column, the camera inside the box).
bool tile_misses_box(const Camera& cam, const Tile& t, const Box3d& box) {
  const Vec3d o = cam.origin();
  const double u[2] = {t.x0 + 0.5, t.x1 - 0.5}, v[2] = {t.y0 + 0.5, t.y1 - 0.5};
  Vec3d c[4];  // corner directions (not normalized), in order around the tile
  const int order[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int i = 0; i < 4; ++i) {
    const Vec3d dc{(u[order[i][0]] - cam.cx) / cam.fx, -(v[order[i][1]] - cam.cy) / cam.fy, -1.0};
    c[i] = {cam.c2w[0] * dc.x + cam.c2w[1] * dc.y + cam.c2w[2] * dc.z,
            cam.c2w[4] * dc.x + cam.c2w[5] * dc.y + cam.c2w[6] * dc.z,
            cam.c2w[8] * dc.x + cam.c2w[9] * dc.y + cam.c2w[10] * dc.z};
  }
  Vec3d p[8];
  double reach = 0;
  for (int i = 0; i < 8; ++i) {
    p[i] = Vec3d{(i & 1) ? box.hi.x : box.lo.x, (i & 2) ? box.hi.y : box.lo.y, (i & 4) ? box.hi.z : box.lo.z} - o;
    reach = std::max({reach, std::abs(p[i].x), std::abs(p[i].y), std::abs(p[i].z)});
  }
  for (int i = 0; i < 4; ++i) {
    const Vec3d& a = c[i];
    const Vec3d& b = c[(i + 1) % 4];
    Vec3d n{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
    const Vec3d& inner = c[(i + 2) % 4];
    const double side = n.x * inner.x + n.y * inner.y + n.z * inner.z;
    const double n_len = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
    if (!(std::abs(side) > 1e-9 * n_len * (std::abs(inner.x) + std::abs(inner.y) + std::abs(inner.z)))) continue;
    if (side < 0) n = Vec3d{-n.x, -n.y, -n.z};  // n points into the cone
    const double margin = 1e-6 * n_len * reach;
    bool outside = true;
    for (int k = 0; k < 8 && outside; ++k) outside = n.x * p[k].x + n.y * p[k].y + n.z * p[k].z < -margin;
    if (outside) return true;
  }
  return false;
}

// One thread's working set, reused from tile to tile.
struct TileWork {
  std::vector<FastMarcher> marchers;
  alignas(64) float dx[kTileRays], dy[kTileRays], dz[kTileRays];
  double t_start[kTileRays];  // where each ray may start marching (tile_start_distances)
  std::vector<float> dir;     // fast_direction_rows rows of kTileRays
  float T[kTileRays], rgb[kTileRays][3];
  bool open[kTileRays];       // may still have samples and T above the threshold
  bool exhausted[kTileRays];  // its march has ended
  bool hit_aabb[kTileRays];   // meets the object AABB
  int active[kTileRays];      // the open rays
  uint32_t begin[kTileRays], end[kTileRays];
  // The round's samples: ray r's at [begin[r], end[r]), each marched group's
  // rays' slots of `limit` records one after the other (with gaps after rays
  // that ended early) in [0, n_samples) (the vector only grows).
  std::vector<FastSample> samples;
  size_t n_samples = 0;
  int gathered[kTileRays];  // the round's rays in the order they were marched
  int n_gathered = 0;
  std::vector<FastSampleOut> outs;
  std::vector<uint32_t> order, count, first, used;
  // The round's samples grouped by MLP (order), field by field (FastBatch).
  std::vector<uint32_t> batch_ray, batch_vertex;
  std::vector<float> batch_fx, batch_fy, batch_fz;
};

struct ThreadTotals {
  RenderStats stats;
  FastProfile profile;
  uint64_t missing = 0;
};

double since(Clock::time_point& t) {
  const Clock::time_point now = Clock::now();
  const double s = std::chrono::duration<double>(now - t).count();
  t = now;
  return s;
}

class TileRenderer {
 public:
  // tables: the INT8 path's activations for sample_spacing(model, s.step_micro).
  TileRenderer(const FastModel& fm, const FastSkipGrid& skip, const Camera& camera, const RenderSettings& s,
               const FastActivationTables& tables, int threads, Image& image, bool profile)
      : fm_(fm), m_(*fm.model), skip_(skip), camera_(camera), s_(s), image_(image), profile_(profile), tables_(tables) {
    cells_x_ = (camera.width + kStartCell - 1) / kStartCell;
    start_ = tile_start_distances(m_, skip_, camera_, kStartCell, cells_x_,
                                  (camera.height + kStartCell - 1) / kStartCell, threads);
    delta_ = sample_spacing(m_, s.step_micro);
    transmittance_min_ =
        std::max(s.transmittance_min,
                 fm.arithmetic == FastArithmetic::Int8 ? s.fast_int8_transmittance_min : s.fast_transmittance_min);
    aabb_ = {m_.object_aabb.lo.cast<double>(), m_.object_aabb.hi.cast<double>()};
  }

  void render(const Tile& tile, TileWork& w, ThreadTotals& tot) const {
    Clock::time_point t = Clock::now();
    const int tw = tile.x1 - tile.x0;
    const int n = tw * (tile.y1 - tile.y0);
    if (tile_misses_box(camera_, tile, skip_.region)) {  // no ray meets the region (which holds the AABB)
      tot.stats.rays += uint64_t(n);
      for (int y = tile.y0; y < tile.y1; ++y) {
        float* px = image_.at(tile.x0, y);
        for (int x = 0; x < 3 * tw; x += 3)
          for (int c = 0; c < 3; ++c) px[x + c] = s_.background[c];
      }
      if (profile_) tot.profile.traversal_s += since(t);
      return;
    }
    // The rays' marchers and directions, set up in SIMD lanes. A ray that
    // meets the AABB has candidates in the region around it.
    w.marchers.resize(kTileRays);
    for (int r = 0, y = tile.y0; y < tile.y1; ++y) {  // each ray's start: its cell's
      const double* row = start_.data() + size_t(y / kStartCell) * size_t(cells_x_);
      for (int x = tile.x0; x < tile.x1; ++x) w.t_start[r++] = row[x / kStartCell];
    }
    fast_setup_rays(m_, skip_, camera_, delta_, aabb_, tile.x0, tile.y0, tw, n, w.t_start, w.marchers.data(), w.dx,
                    w.dy, w.dz, w.hit_aabb);
    int n_active = 0;  // w.active[0, n_active): the open rays, in increasing order
    for (int r = 0; r < kTileRays; ++r) {
      if (r >= n) {  // padding lanes of the direction encoding
        w.dx[r] = w.dy[r] = w.dz[r] = 0.f;
        continue;
      }
      ++tot.stats.rays;
      tot.stats.rays_hit_aabb += w.hit_aabb[r];
      const FastMarcher& fm = w.marchers[size_t(r)];
      w.T[r] = 1.f;
      w.rgb[r][0] = w.rgb[r][1] = w.rgb[r][2] = 0.f;
      w.open[r] = !fm.empty();  // a ray without candidates keeps the background
      w.exhausted[r] = false;
      if (w.open[r])
        w.active[n_active++] = r;
      else  // its lookups are all made (the others' are counted as they close)
        tot.stats.occupancy_checks += fm.occupancy_checks();
    }
    bool encoded = false;
    double traversal = 0, compositing = 0;
    FastKernelSeconds kernel;
    for (int round = 0, per_ray = kFirstRoundSamples;; ++round, per_ray = std::min(2 * per_ray, kMaxRoundSamples)) {
      // Traversal: each open ray's next samples, contiguous per ray.
      if (n_active == 0) break;
      w.n_samples = 0;
      w.n_gathered = 0;
      if (w.count.size() != m_.mlp_count()) {
        w.count.assign(m_.mlp_count(), 0);
        w.first.assign(m_.mlp_count(), 0);
      }
      w.used.clear();
      if (w.samples.size() < size_t(n_active) * size_t(per_ray)) w.samples.resize(size_t(n_active) * size_t(per_ray));
      // Rays already dimmed below kDimTransmittance ask for fewer samples.
      int group[2][kFastMarchGroup], g[2] = {0, 0};
      const int limit[2] = {per_ray, std::min(per_ray, kDimRoundSamples)};
      for (int a = 0; a < n_active; ++a) {
        const int r = w.active[a];
        w.begin[r] = w.end[r] = 0;
        const int c = w.T[r] < kDimTransmittance ? 1 : 0;
        group[c][g[c]++] = r;
        if (g[c] == kFastMarchGroup) {
          gather(w, group[c], g[c], limit[c], tot);
          g[c] = 0;
        }
      }
      for (int c = 0; c < 2; ++c)
        if (g[c] > 0) gather(w, group[c], g[c], limit[c], tot);
      if (profile_) traversal += since(t);
      if (!w.used.empty()) {
        if (!encoded && fm_.dir_dims > 0) {
          w.dir.resize(size_t(fast_direction_rows(fm_)) * kTileRays);
          fast_encode_directions(fm_, w.dx, w.dy, w.dz, kTileRays, w.dir.data(), kTileRays);
          encoded = true;
        }
        group_by_mlp(w);
        if (profile_) traversal += since(t);
        // Interpolation and MLPs, one coarse voxel's batch at a time.
        if (w.outs.size() < w.n_samples) w.outs.resize(w.n_samples);
        for (uint32_t u : w.used) {
          const size_t f = w.first[u];
          const FastBatch batch{w.batch_ray.data() + f, w.batch_vertex.data() + f, w.batch_fx.data() + f,
                                w.batch_fy.data() + f,  w.batch_fz.data() + f,     w.order.data() + f};
          fast_eval_batch(fm_, u, batch, w.count[u], w.dir.data(), kTileRays, delta_, w.outs.data(),
                          profile_ ? &kernel : nullptr, &tables_);
          tot.profile.mlp_samples += w.count[u];
          w.count[u] = 0;
        }
        if (profile_) t = Clock::now();
      }
      // Compositing, each ray in sample order; the rays that stay open.
      int still_open = 0;
      uint64_t composited = 0;
      for (int a = 0; a < n_active; ++a) {
        const int r = w.active[a];
        if (w.exhausted[r]) w.open[r] = false;
        float T = w.T[r];
        float rgb[3] = {w.rgb[r][0], w.rgb[r][1], w.rgb[r][2]};  // in registers: the stores cannot alias outs
        for (uint32_t i = w.begin[r]; i < w.end[r] && T >= transmittance_min_; ++i) {
          const FastSampleOut& o = w.outs[i];
          const float weight = T * o.alpha;
          for (int c = 0; c < 3; ++c) rgb[c] += weight * o.rgb[c];
          T *= o.trans;
          ++composited;
        }
        for (int c = 0; c < 3; ++c) w.rgb[r][c] = rgb[c];
        w.T[r] = T;
        if (T < transmittance_min_) w.open[r] = false;
        if (w.open[r])
          w.active[still_open++] = r;
        else  // it marches no more
          tot.stats.occupancy_checks += w.marchers[size_t(r)].occupancy_checks();
      }
      n_active = still_open;
      tot.stats.samples += composited;
      if (profile_) compositing += since(t);
    }
    for (int r = 0, y = tile.y0; y < tile.y1; ++y) {  // row by row: no division per pixel
      float* px = image_.at(tile.x0, y);
      for (int x = 0; x < tw; ++x, ++r)
        for (int c = 0; c < 3; ++c) px[3 * x + c] = w.rgb[r][c] + w.T[r] * s_.background[c];
    }
    if (profile_) {
      compositing += since(t);
      tot.profile.traversal_s += traversal;
      tot.profile.compositing_s += compositing;
      tot.profile.interpolation_s += kernel.interpolation;
      tot.profile.mlp_s += kernel.mlp;
    }
  }

 private:
  // Up to `limit` samples of each ray group[i], i < g (rays in increasing
  // order), marched together; marks the rays whose march ends exhausted.
  void gather(TileWork& w, const int* group, int g, int limit, ThreadTotals& tot) const {
    FastMarcher* marchers[kFastMarchGroup];
    uint32_t rays[kFastMarchGroup];
    for (int i = 0; i < g; ++i) {
      marchers[i] = &w.marchers[size_t(group[i])];
      rays[i] = uint32_t(group[i]);
    }
    int counts[kFastMarchGroup];
    bool ended[kFastMarchGroup];
    const size_t base = w.n_samples;  // the records go straight to the round's samples, `limit` slots per ray
    fast_march_records(marchers, rays, g, limit, w.samples.data() + base, counts, ended, &tot.missing);
    for (int i = 0; i < g; ++i) {
      const int r = group[i];
      if (ended[i]) w.exhausted[r] = true;
      w.begin[r] = uint32_t(base + size_t(i) * size_t(limit));
      w.end[r] = w.begin[r] + uint32_t(counts[i]);
      w.gathered[w.n_gathered++] = r;
    }
    // The samples per MLP, counted by runs of one MLP (a ray's samples
    // mostly share their coarse voxel): no chain of increments of one
    // counter through memory.
    uint32_t run_mlp = 0, run = 0;
    auto flush = [&] {
      if (run == 0) return;
      if (w.count[run_mlp] == 0) w.used.push_back(run_mlp);
      w.count[run_mlp] += run;
    };
    for (int i = 0; i < g; ++i) {
      const int r = group[i];
      const uint32_t b = w.begin[r], e = w.end[r];
      if (b == e) continue;
      // A ray meets each coarse voxel (a box) in one stretch, and each MLP
      // is one coarse voxel's (SceneModel::mlp_coarse_index), so when its
      // first and last samples share an MLP, all of them do.
      const uint32_t first = w.samples[b].mlp;
      if (first == w.samples[e - 1].mlp) {
        if (first != run_mlp) {
          flush();
          run_mlp = first;
          run = 0;
        }
        run += e - b;
        continue;
      }
      for (uint32_t j = b; j < e; ++j) {
        const uint32_t mlp = w.samples[j].mlp;
        if (mlp != run_mlp) {
          flush();
          run_mlp = mlp;
          run = 0;
        }
        ++run;
      }
    }
    flush();
    w.n_samples = base + size_t(g) * size_t(limit);
  }

  // Counting sort of the round's samples by MLP, whose counts gather() made
  // (w.count, and w.used: the MLPs met): w.order holds the samples of MLP u
  // at [first[u], first[u] + count[u]), and w.batch_* their fields there.
  void group_by_mlp(TileWork& w) const {
    const FastSample* samples = w.samples.data();
    uint32_t at = 0;
    for (uint32_t u : w.used) {
      w.first[u] = at;
      at += w.count[u];
      w.count[u] = 0;
    }
    if (w.order.size() < at) {
      w.order.resize(at);
      w.batch_ray.resize(at);
      w.batch_vertex.resize(at);
      w.batch_fx.resize(at);
      w.batch_fy.resize(at);
      w.batch_fz.resize(at);
    }
    // The samples in the order they were marched, each MLP's cursor kept
    // in a register while its run lasts.
    constexpr uint32_t kNone = UINT32_MAX;  // no MLP (indices are below the MLP count)
    uint32_t cur = kNone, pos = 0;
    for (int a = 0; a < w.n_gathered; ++a) {
      const int r = w.gathered[a];
      for (uint32_t i = w.begin[r]; i < w.end[r]; ++i) {
        const FastSample& rec = samples[i];
        const uint32_t u = rec.mlp;
        if (u != cur) {
          if (cur != kNone) w.count[cur] = pos - w.first[cur];
          cur = u;
          pos = w.first[u] + w.count[u];
        }
        w.order[pos] = i;
        w.batch_ray[pos] = rec.ray;
        w.batch_vertex[pos] = rec.vertex;
        w.batch_fx[pos] = rec.fx;
        w.batch_fy[pos] = rec.fy;
        w.batch_fz[pos] = rec.fz;
        ++pos;
      }
    }
    if (cur != kNone) w.count[cur] = pos - w.first[cur];
  }

  const FastModel& fm_;
  const SceneModel& m_;
  const FastSkipGrid& skip_;
  const Camera& camera_;
  const RenderSettings& s_;
  Image& image_;
  bool profile_;
  const FastActivationTables& tables_;  // the INT8 path's activations for delta_
  float delta_ = 0;
  float transmittance_min_ = 0;  // the rays' end (RenderSettings::fast_transmittance_min, _int8_)
  int cells_x_ = 0;
  std::vector<double> start_;  // per cell of kStartCell pixels, row by row: where its rays may start
  Box3d aabb_;
};

}  // namespace

FastRenderer::FastRenderer(const SceneModel& model, ModelForm form, FastPath path) {
  const ResolvedForm resolved = resolve_model_form(model, form);
  FastArithmetic a = FastArithmetic::Float;
  if (path == FastPath::Int8) {
    if (!(resolved.quantized_features && resolved.quantized_mlps))
      fail("the fast renderer's INT8 path needs the quantized form (INT4 features and INT8 MLPs)");
    a = FastArithmetic::Int8;
  } else if (path == FastPath::Auto && resolved.quantized_features && resolved.quantized_mlps) {
    a = FastArithmetic::Int8;
  }
  fm_ = pack_fast_model(model, resolved, a);
  skip_ = std::make_shared<const FastSkipGrid>(model);
}

std::shared_ptr<const FastActivationTables> FastRenderer::activation_tables(float delta) const {
  const std::lock_guard<std::mutex> lock(tables_->mutex);
  if (!tables_->tables || tables_->delta != delta) {
    tables_->tables = std::make_shared<const FastActivationTables>(fast_activation_tables(fm_, delta));
    tables_->delta = delta;
  }
  return tables_->tables;
}

Image FastRenderer::render(const Camera& camera, const RenderSettings& settings, RenderStats* stats,
                           FastProfile* profile) const {
  check_render_inputs(camera, settings);
  const int W = camera.width, H = camera.height;
  Image image(W, H, 3);
  const std::vector<Tile> tiles = z_order_tiles(W, H);
  const int threads = settings.threads > 0 ? settings.threads : omp_get_max_threads();
  const std::shared_ptr<const FastActivationTables> tables =
      activation_tables(sample_spacing(*fm_.model, settings.step_micro));
  const TileRenderer tr(fm_, *skip_, camera, settings, *tables, threads, image, profile != nullptr);
  ThreadTotals total;
#pragma omp parallel num_threads(threads)
  {
    TileWork work;
    ThreadTotals local;
#pragma omp for schedule(dynamic, 1)
    for (size_t i = 0; i < tiles.size(); ++i) tr.render(tiles[i], work, local);
#pragma omp critical
    {
      total.stats.rays += local.stats.rays;
      total.stats.rays_hit_aabb += local.stats.rays_hit_aabb;
      total.stats.samples += local.stats.samples;
      total.stats.occupancy_checks += local.stats.occupancy_checks;
      total.profile.traversal_s += local.profile.traversal_s;
      total.profile.interpolation_s += local.profile.interpolation_s;
      total.profile.mlp_s += local.profile.mlp_s;
      total.profile.compositing_s += local.profile.compositing_s;
      total.profile.mlp_samples += local.profile.mlp_samples;
      total.missing += local.missing;
    }
  }
  if (total.missing)
    fail("{} samples lie in occupied micro voxels without a feature block or MLP (the model breaks its invariants)",
         total.missing);
  if (stats) *stats = total.stats;
  if (profile) *profile = total.profile;
  return image;
}

void export_fast_stats(const RenderStats& stats, const FastProfile& profile, StatsRegistry& r, const std::string& p) {
  r.counter(p + ".rays", "rays", "rays cast, one per pixel") += stats.rays;
  r.counter(p + ".rays_hit_aabb", "rays", "rays that meet the object AABB") += stats.rays_hit_aabb;
  r.counter(p + ".samples", "samples", "samples composited") += stats.samples;
  r.counter(p + ".mlp_samples", "samples", "samples run through an MLP, including those past a ray's end") +=
      profile.mlp_samples;
  r.counter(p + ".occupancy_checks", "lookups", "distance-field and occupancy lookups") += stats.occupancy_checks;
  r.value(p + ".traversal_s", "s", "thread time: ray set-up, marching, grouping by coarse voxel") +=
      profile.traversal_s;
  r.value(p + ".interpolation_s", "s", "thread time: trilinear feature reads") += profile.interpolation_s;
  r.value(p + ".mlp_s", "s", "thread time: MLPs and activations") += profile.mlp_s;
  r.value(p + ".compositing_s", "s", "thread time: alpha blending and pixel writes") += profile.compositing_s;
}

Image render_fast(const SceneModel& model, const Camera& camera, const RenderSettings& settings, RenderStats* stats) {
  return FastRenderer(model, settings.form, FastPath::Auto).render(camera, settings, stats);
}

Image render_fast_float(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                        RenderStats* stats) {
  return FastRenderer(model, settings.form, FastPath::Float).render(camera, settings, stats);
}

}  // namespace edrnr
