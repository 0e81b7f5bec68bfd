#pragma once
// The fast CPU renderer: the chip's data-reuse ideas applied to CPU caches
// and SIMD (docs/performance.md). Same model, same sampling rule and the same
// samples as the reference renderer (render/reference.h, render/traversal.h)
// up to the end of each ray; the order of the work changes:
//   - the image is cut into 16x16-pixel tiles visited in Z (Morton) order and
//     shared among threads (OpenMP, dynamic); a tile's 256 rays are a packet;
//   - a tile whose rays all miss the region around the object (a test of the
//     tile's view cone against the box) is filled with the background;
//   - per frame, the occupied fine voxels are projected onto the tiles: each
//     tile's rays start marching at the nearest distance of a voxel that
//     covers it (tile_start_distances, render/fast_march.h), and not at all
//     where none does;
//   - each ray of the packet marches inside the object AABB (FastMarcher,
//     render/fast_march.h: a distance field over the fine tier for empty
//     space, then SIMD vectors of consecutive candidates tested against the
//     fine voxels' micro masks) and hands over its next few samples (fewer
//     once its transmittance has dropped);
//   - the packet's samples are grouped by coarse voxel, and each group runs
//     through that CV's MLP as a small matrix product per layer over SIMD
//     vectors of samples (render/fast_kernels.h), features read from the
//     fine-voxel blocks in place;
//   - each ray composites its samples in order, stops at the transmittance
//     threshold, and asks for more samples only if it is still open.
// Rays end at the transmittance RenderSettings::fast_transmittance_min on
// the float path (1e-3 by default) and fast_int8_transmittance_min on the
// INT8 path (1e-2; the reference's 1e-4 with 0): every pixel within that of
// the image with the reference's samples per channel, for about 11 % (float)
// and a fifth (INT8) fewer samples.
// Every pixel is computed by one thread in a fixed order, so the image does
// not depend on the thread count.
//
// Two arithmetics (fast_model.h): Float, the reference's (per-sample sums in
// the reference's order; exp and sigmoid from Highway's vector math), and
// Int8, the chip's INT4 features and INT8 MLPs (not bit-exact with the chip
// model: float rounding of positions and weights, float compositing).
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "core/image.h"
#include "core/stats.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "render/fast_model.h"
#include "render/reference.h"

namespace edrnr {

struct FastSkipGrid;          // render/fast_march.h
struct FastActivationTables;  // render/fast_kernels.h

// Auto: Int8 when the form rendered (RenderSettings::form resolved) is the
// model's INT4 features and INT8 MLPs, Float otherwise.
enum class FastPath { Auto, Float, Int8 };

// Where the time went, in thread-seconds summed over all threads. Filled only
// when asked for: measuring costs a clock read per phase and chunk.
struct FastProfile {
  double traversal_s = 0;      // ray set-up, marching the tiers, grouping by CV
  double interpolation_s = 0;  // trilinear feature reads
  double mlp_s = 0;            // MLPs, density and colour activations
  double compositing_s = 0;    // alpha blending, pixel writes
  uint64_t mlp_samples = 0;    // samples run through an MLP (some past a ray's end, discarded)
  double total_s() const { return traversal_s + interpolation_s + mlp_s + compositing_s; }
};

class FastRenderer {
 public:
  // Packs the model (one pass over its MLPs; the features are read in place,
  // so `model` must outlive the renderer). `form` picks the stored forms read
  // as for the reference renderer. Throws Error for an unusable model or a
  // path the model lacks (Int8 without INT4 features and INT8 MLPs).
  FastRenderer(const SceneModel& model, ModelForm form, FastPath path);

  FastArithmetic arithmetic() const { return fm_.arithmetic; }
  const FastModel& packed() const { return fm_; }

  // Renders the camera's image (3 channels). settings.form is not read (the
  // constructor's form is). stats: rays, rays meeting the AABB, samples
  // composited, bitmap and distance lookups. settings.use_occupancy_tiers is
  // not read (the march always skips; the samples are the same). Throws Error for an empty camera,
  // invalid settings, or samples in occupied voxels without block or MLP.
  Image render(const Camera& camera, const RenderSettings& settings, RenderStats* stats = nullptr,
               FastProfile* profile = nullptr) const;

 private:
  // The INT8 path's activation tables for sample spacing delta: made on the
  // first frame at that spacing and kept (about 0.3 ms each time otherwise).
  std::shared_ptr<const FastActivationTables> activation_tables(float delta) const;

  struct TableCache {
    std::mutex mutex;
    std::shared_ptr<const FastActivationTables> tables;  // the last spacing's (empty on the float path)
    float delta = 0;                                     // that spacing
  };
  FastModel fm_;
  std::shared_ptr<const FastSkipGrid> skip_;
  std::shared_ptr<TableCache> tables_ = std::make_shared<TableCache>();
};

// Registers a render's counts and phase times under `prefix` (e.g.
// "fast.rays", "fast.traversal_s"), each with its unit and description.
void export_fast_stats(const RenderStats& stats, const FastProfile& profile, StatsRegistry& registry,
                       const std::string& prefix = "fast");

// The engines of `edrnr render --engine`: fast (FastPath::Auto) and
// fast-float (FastPath::Float), with the reference renderer's signature.
Image render_fast(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                  RenderStats* stats = nullptr);
Image render_fast_float(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                        RenderStats* stats = nullptr);

}  // namespace edrnr
