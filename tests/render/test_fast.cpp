// The fast CPU renderer against the reference renderer on procedural scenes.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <random>

#include "core/error.h"
#include "core/metrics.h"
#include "fast_scenes.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/fast.h"
#include "render/fast_march.h"
#include "render/options.h"
#include "render/reference.h"
#include "render/traversal.h"

namespace edrnr {
namespace {

using fast_test::expect_reference_samples;
using fast_test::several_model;
using fast_test::views;

TEST(Fast, FloatPathMatchesTheReference) {
  const SceneModel m = several_model(128);
  for (ModelForm form : {ModelForm::Float, ModelForm::Quantized}) {
    const FastRenderer fast(m, form, FastPath::Float);
    ASSERT_EQ(fast.arithmetic(), FastArithmetic::Float);
    RenderSettings s;
    s.form = form;
    s.fast_transmittance_min = 0.f;  // the reference's samples exactly
    for (const Camera& cam : views(61, 47)) {
      RenderStats rs, fs;
      const Image ref = render_reference(m, cam, s, &rs);
      const Image img = fast.render(cam, s, &fs);
      ASSERT_EQ(img.width, ref.width);
      ASSERT_EQ(img.height, ref.height);
      EXPECT_GE(psnr(img, ref), 50.0) << model_form_name(form);
      EXPECT_EQ(fs.rays, rs.rays);
      EXPECT_EQ(fs.rays_hit_aabb, rs.rays_hit_aabb);
      EXPECT_EQ(fs.samples, rs.samples);
      EXPECT_GT(fs.samples, 1000u);
    }
  }
}

// The fast march yields exactly the reference march's samples (same k, same
// point, same voxel), ray by ray, at several steps and from inside and outside
// the object.
TEST(Fast, MarchYieldsTheReferenceSamples) {
  for (int res : {64, 256}) {
    const SceneModel m = several_model(res, false);
    const FastSkipGrid skip(m);
    for (float step : {1.f, 0.43f, 2.5f}) {
      const float delta = sample_spacing(m, step);
      size_t total = 0;
      int64_t k_max = 0;
      for (const Camera& cam : {views(23, 19)[0], views(23, 19)[2], orbit_camera(17, 17, 40, 10, 0.3, 120)}) {
        SCOPED_TRACE(testing::Message() << "res " << res << ", step " << step);
        expect_reference_samples(m, skip, cam, delta, &total, &k_max);
        if (HasFatalFailure()) return;
      }
      EXPECT_GT(total, 200u) << res << " " << step;
    }
  }
}

// The march's first steps as fast_setup_rays is to make them, written out
// from the march's rules: from a candidate in a fine voxel whose reach e is
// kFastJumpReach or more, a jump past the empty box of the fine voxel
// widened by e micro voxels; past a candidate outside the grid, one step;
// up to a candidate with a shorter reach (whose vector test is next:
// dense), or the end. Each reach lookup is an occupancy check.
void approach(FastMarcher::State& st, const SceneModel& m, const FastSkipGrid& skip) {
  const float hi = float(m.micro_res);
  while (st.k <= st.k_end) {
    const Vec3f p = st.ray.point(st.k);
    if (!(p.x >= 0.f && p.x <= hi && p.y >= 0.f && p.y <= hi && p.z >= 0.f && p.z <= hi)) {
      ++st.k;
      continue;
    }
    const Vec3i f{std::min(int(p.x), m.micro_res - 1) / 4, std::min(int(p.y), m.micro_res - 1) / 4,
                  std::min(int(p.z), m.micro_res - 1) / 4};
    const int e = skip.reach[size_t(f.x) + size_t(skip.res) * (size_t(f.y) + size_t(skip.res) * size_t(f.z))];
    ++st.checks;
    if (e < kFastJumpReach) {
      st.dense = true;
      return;
    }
    st.k = st.skip_box(st.k, Vec3i{4 * f.x - e, 4 * f.y - e, 4 * f.z - e}, 4 + 2 * e);
  }
}

// tile_start_distances: no pixel ray of a tile has a sample before the
// tile's distance (none at all at +inf), checked against the reference march
// ray by ray; and marchers set up from it yield the reference's samples.
// Cameras around the object, inside it and far from it.
TEST(Fast, TileStartsComeBeforeEverySample) {
  const SceneModel m = several_model(64, false);
  const FastSkipGrid skip(m);
  const Box3d aabb{m.object_aabb.lo.cast<double>(), m.object_aabb.hi.cast<double>()};
  std::vector<Camera> cams = views(40, 36);
  cams.push_back(orbit_camera(17, 17, 40, 10, 0.3, 120));
  cams.push_back(orbit_camera(30, 30, 120, 25, 40, 8));
  const int tile = 8;
  const float delta = sample_spacing(m, 1.f);
  int unreached = 0, started = 0;
  size_t samples = 0;
  for (size_t c = 0; c < cams.size(); ++c) {
    const Camera& cam = cams[c];
    const int tx = (cam.width + tile - 1) / tile, ty = (cam.height + tile - 1) / tile;
    const std::vector<double> start = tile_start_distances(m, skip, cam, tile, tx, ty);
    ASSERT_EQ(start.size(), size_t(tx) * size_t(ty));
    ASSERT_EQ(tile_start_distances(m, skip, cam, tile, tx, ty, 3), start);  // the same on any thread count
    for (int j = 0; j < ty; ++j)
      for (int i = 0; i < tx; ++i) {
        const double t0 = start[size_t(j) * size_t(tx) + size_t(i)];
        unreached += std::isinf(t0);
        const int x0 = i * tile, y0 = j * tile, tw = std::min(tile, cam.width - x0);
        const int n = tw * std::min(tile, cam.height - y0);
        std::vector<FastMarcher> lanes(static_cast<size_t>(n));
        std::vector<float> dx(static_cast<size_t>(n)), dy(dx), dz(dx);
        std::vector<double> starts(static_cast<size_t>(n), t0);
        bool hit[tile * tile];
        fast_setup_rays(m, skip, cam, delta, aabb, x0, y0, tw, n, starts.data(), lanes.data(), dx.data(), dy.data(),
                        dz.data(), hit);
        for (int r = 0; r < n; ++r) {
          SCOPED_TRACE(testing::Message() << "camera " << c << " pixel " << x0 + r % tw << "," << y0 + r / tw);
          const Ray ray = cam.pixel_ray(x0 + r % tw, y0 + r / tw);
          const MicroRay mr = make_micro_ray(m, ray, delta);
          SampleMarcher ref(m, ray, mr, true);
          MarchSample a, b;
          bool first = true;
          for (;;) {
            const bool more = ref.next(a);
            ASSERT_EQ(lanes[size_t(r)].next(b), more);
            if (!more) break;
            ASSERT_EQ(a.k, b.k);
            if (first) {
              ASSERT_GE((double(a.k) + 0.5) * double(delta), t0);
              started += t0 > 0;
              first = false;
            }
            ++samples;
          }
        }
      }
  }
  EXPECT_GT(unreached, 10);  // tiles the object does not cover
  EXPECT_GT(started, 100);   // rays with samples in tiles with a start
  EXPECT_GT(samples, 1000u);
}

// The tile set-up in SIMD lanes leaves every marcher as the scalar set-up
// and the march's first steps do, bit for bit (those with no candidate
// left: empty, with the same occupancy checks), and gives the same
// directions and AABB hits; marched on, each yields the samples and
// occupancy checks of a marcher built by the constructor. Cameras around,
// inside and far from the object, and one looking along -z whose centre
// rays have zero direction components (the lanes the scalar code takes
// over). Tiles of 77 rays leave partial vectors.
TEST(Fast, RaySetupInLanesEqualsTheScalarSetUp) {
  const SceneModel m = several_model(64, false);
  const FastSkipGrid skip(m);
  const Box3d aabb{m.object_aabb.lo.cast<double>(), m.object_aabb.hi.cast<double>()};
  Camera axis;
  axis.width = 9;
  axis.height = 7;
  axis.fx = axis.fy = 6;
  axis.cx = 4.5;
  axis.cy = 3.5;
  axis.c2w = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3, 0, 0, 0, 1};
  std::vector<Camera> cams = views(23, 19);
  cams.push_back(orbit_camera(17, 17, 40, 10, 0.3, 120));
  cams.push_back(orbit_camera(21, 21, 30, 20, 1.5e7, 1.6e-5));
  cams.push_back(axis);
  int zero_components = 0, hits = 0, empties = 0, advanced = 0;
  size_t samples = 0;
  for (float step : {1.f, 0.43f}) {
    const float delta = sample_spacing(m, step);
    for (size_t c = 0; c < cams.size(); ++c) {
      const Camera& cam = cams[c];
      for (int y0 = 0; y0 < cam.height; y0 += 7)
        for (int x0 = 0; x0 < cam.width; x0 += 11) {
          const int tw = std::min(11, cam.width - x0), n = tw * std::min(7, cam.height - y0);
          std::vector<FastMarcher> lanes(static_cast<size_t>(n));
          std::vector<float> dx(static_cast<size_t>(n)), dy(dx), dz(dx);
          bool hit[77];
          fast_setup_rays(m, skip, cam, delta, aabb, x0, y0, tw, n, nullptr, lanes.data(), dx.data(), dy.data(),
                          dz.data(), hit);
          for (int r = 0; r < n; ++r) {
            SCOPED_TRACE(testing::Message()
                         << "camera " << c << " step " << step << " pixel " << x0 + r % tw << "," << y0 + r / tw);
            const Ray ray = cam.pixel_ray(x0 + r % tw, y0 + r / tw);
            zero_components += (ray.dir.x == 0) + (ray.dir.y == 0) + (ray.dir.z == 0);
            FastMarcher ref;
            ref.set_up(m, skip, ray, make_micro_ray(m, ray, delta));
            const bool had_candidates = !ref.empty();
            const int64_t k0 = ref.state().k;
            approach(ref.state(), m, skip);
            advanced += ref.state().k > k0;
            const FastMarcher::State& a = ref.state();
            const FastMarcher::State& b = lanes[size_t(r)].state();
            // A marcher with no candidate left only has to say so (and keep its count).
            ASSERT_EQ(lanes[size_t(r)].empty(), ref.empty());
            if (!ref.empty()) {
              ASSERT_EQ(a.k, b.k);
              ASSERT_EQ(a.k_end, b.k_end);
              ASSERT_EQ(a.ray.origin, b.ray.origin);
              ASSERT_EQ(a.ray.dir, b.ray.dir);
              ASSERT_EQ(a.ray.delta, b.ray.delta);
              for (int ax = 0; ax < 3; ++ax) {
                ASSERT_EQ(a.exit[ax], b.exit[ax]);
                ASSERT_EQ(a.scale[ax], b.scale[ax]);
                ASSERT_EQ(a.offset[ax], b.offset[ax]);
              }
              ASSERT_EQ(a.dense, b.dense);
            }
            ASSERT_EQ(a.checks, b.checks);
            ASSERT_EQ(b.model, &m);
            ASSERT_EQ(b.skip, &skip);
            ASSERT_EQ(b.pending, 0u);
            ASSERT_EQ(dx[size_t(r)], float(ray.dir.x));
            ASSERT_EQ(dy[size_t(r)], float(ray.dir.y));
            ASSERT_EQ(dz[size_t(r)], float(ray.dir.z));
            double tn, tf;
            const bool expect_hit = had_candidates && intersect_box(ray.origin, ray.dir, aabb, tn, tf) && tf >= 0;
            ASSERT_EQ(hit[r], expect_hit);
            hits += hit[r];
            empties += !had_candidates;
            FastMarcher whole(m, skip, ray, make_micro_ray(m, ray, delta));
            MarchSample x, y;
            for (;;) {
              const bool more = whole.next(x);
              ASSERT_EQ(lanes[size_t(r)].next(y), more);
              if (!more) break;
              ASSERT_EQ(x.k, y.k);
              ASSERT_EQ(x.voxel, y.voxel);
              ASSERT_EQ(x.p_micro, y.p_micro);
              ++samples;
            }
            ASSERT_EQ(whole.occupancy_checks(), lanes[size_t(r)].occupancy_checks());
          }
        }
    }
  }
  EXPECT_GT(zero_components, 0);
  EXPECT_GT(hits, 100);
  EXPECT_GT(empties, 100);
  EXPECT_GT(advanced, 100);
  EXPECT_GT(samples, 1000u);
}

// From a camera so far away that the candidate indices pass 2^30 (where the
// vector test gives way to one candidate at a time), the samples are still
// the reference's.
TEST(Fast, MarchFarFromTheObjectYieldsTheReferenceSamples) {
  const SceneModel m = several_model(256, false);
  const FastSkipGrid skip(m);
  const float delta = sample_spacing(m, 1.f);
  size_t total = 0;
  int64_t k_max = 0;
  for (const Camera& cam : {orbit_camera(21, 21, 30, 20, 1.5e7, 1.6e-5), orbit_camera(21, 21, 150, -10, 2e7, 1.2e-5)}) {
    expect_reference_samples(m, skip, cam, delta, &total, &k_max);
    if (HasFatalFailure()) return;
  }
  EXPECT_GT(total, 0u);
  EXPECT_GT(k_max, int64_t(1) << 30);
}

// The renderer's grouped march (four rays interleaved, a few samples per
// call, samples held over between calls) yields the reference samples too.
TEST(Fast, GroupedMarchYieldsTheReferenceSamples) {
  const SceneModel m = several_model(128, false);
  const FastSkipGrid skip(m);
  const float delta = sample_spacing(m, 1.f);
  const Camera cam = views(29, 23)[1];
  size_t total = 0;
  for (int limit : {1, 3, 8}) {
    for (int y = 0; y < cam.height; ++y)
      for (int x0 = 0; x0 < cam.width; x0 += kFastMarchGroup) {
        const int n = std::min(kFastMarchGroup, cam.width - x0);
        std::vector<FastMarcher> fast;
        std::vector<std::vector<MarchSample>> want(static_cast<size_t>(n)), got(static_cast<size_t>(n));
        for (int i = 0; i < n; ++i) {
          const Ray ray = cam.pixel_ray(x0 + i, y);
          const MicroRay mr = make_micro_ray(m, ray, delta);
          SampleMarcher ref(m, ray, mr, true);
          MarchSample a;
          while (ref.next(a)) want[size_t(i)].push_back(a);
          fast.emplace_back(m, skip, ray, mr);
        }
        std::vector<FastMarcher*> ptrs;
        for (FastMarcher& f : fast) ptrs.push_back(&f);
        std::vector<MarchSample> samples(size_t(kFastMarchGroup * limit));
        std::vector<int32_t> blocks(samples.size());
        int counts[kFastMarchGroup];
        bool ended[kFastMarchGroup] = {false, false, false, false};
        for (int call = 0; call < 10000; ++call) {
          fast_march_group(ptrs.data(), n, limit, samples.data(), blocks.data(), counts, ended);
          bool all = true;
          for (int i = 0; i < n; ++i) {
            ASSERT_LE(counts[i], limit);
            for (int j = 0; j < counts[i]; ++j) {
              const MarchSample& s = samples[size_t(i * limit + j)];
              const Vec3i& v = s.voxel;
              EXPECT_EQ(blocks[size_t(i * limit + j)],
                        m.fine_to_block[linear_index(v.x / 4, v.y / 4, v.z / 4, m.fine_res())]);
              got[size_t(i)].push_back(s);
            }
            all = all && (ended[i] || counts[i] == 0);
          }
          if (all) break;
        }
        for (int i = 0; i < n; ++i) {
          ASSERT_EQ(got[size_t(i)].size(), want[size_t(i)].size()) << limit << " " << x0 + i << "," << y;
          for (size_t j = 0; j < want[size_t(i)].size(); ++j) {
            EXPECT_EQ(got[size_t(i)][j].k, want[size_t(i)][j].k);
            EXPECT_EQ(got[size_t(i)][j].voxel, want[size_t(i)][j].voxel);
            EXPECT_EQ(got[size_t(i)][j].p_micro, want[size_t(i)][j].p_micro);
          }
          total += want[size_t(i)].size();
        }
      }
  }
  EXPECT_GT(total, 300u);
}

TEST(Fast, SkipGridHoldsChebyshevDistances) {
  const SceneModel m = several_model(64, false);
  const FastSkipGrid g(m);
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  const int r = m.fine_res();
  // Brute force at a spread of voxels.
  for (int z = 0; z < r; z += 3)
    for (int y = 1; y < r; y += 5)
      for (int x = 2; x < r; x += 7) {
        int best = FastSkipGrid::kMaxDistance;
        for (int c = 0; c < r * r * r; ++c) {
          const int cx = c % r, cy = (c / r) % r, cz = c / (r * r);
          if (fine.get(cx, cy, cz))
            best = std::min(best, std::max({std::abs(cx - x), std::abs(cy - y), std::abs(cz - z)}));
        }
        ASSERT_EQ(int(g.at(x, y, z)), best) << x << "," << y << "," << z;
      }
  // The micro masks of the fine voxels hold the micro bitmap, and each
  // fine voxel's cell its block and its coarse voxel's MLP (or -1 for both
  // when it is empty).
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  constexpr size_t kCell = FastSkipGrid::kCellWords;
  ASSERT_EQ(g.fine_words.size(), kCell * r * r * r);
  const int per_coarse = r / m.coarse_res();
  size_t with_block = 0;
  for (int z = 0; z < r; ++z)
    for (int y = 0; y < r; ++y)
      for (int x = 0; x < r; ++x) {
        const uint32_t* cell = g.fine_words.data() + kCell * linear_index(x, y, z, r);
        const bool empty = g.at(x, y, z) != 0;
        const int32_t block = empty ? -1 : m.fine_to_block[linear_index(x, y, z, r)];
        const int32_t mlp =
            empty ? -1 : m.coarse_to_mlp[linear_index(x / per_coarse, y / per_coarse, z / per_coarse, m.coarse_res())];
        ASSERT_EQ(int32_t(cell[FastSkipGrid::kCellBlock]), block) << x << "," << y << "," << z;
        ASSERT_EQ(int32_t(cell[FastSkipGrid::kCellMlp]), mlp) << x << "," << y << "," << z;
        with_block += block >= 0 && mlp >= 0;
      }
  EXPECT_GT(with_block, 10u);
  size_t occupied = 0;
  for (int z = 0; z < m.micro_res; ++z)
    for (int y = 0; y < m.micro_res; ++y)
      for (int x = 0; x < m.micro_res; ++x) {
        const size_t f = size_t(x / 4) + size_t(r) * (size_t(y / 4) + size_t(r) * size_t(z / 4));
        const uint32_t word = g.fine_words[kCell * f + size_t((z & 3) >> 1)];
        const bool bit = (word >> ((x & 3) + 4 * (y & 3) + 16 * (z & 1))) & 1u;
        ASSERT_EQ(bit, micro.get(x, y, z)) << x << "," << y << "," << z;
        occupied += bit;
      }
  EXPECT_GT(occupied, 100u);
}

TEST(Fast, FloatPathMatchesTheReferenceAtOtherSettings) {
  const SceneModel m = several_model(64);
  RenderSettings s;
  s.step_micro = 0.37f;
  s.transmittance_min = 0.05f;
  s.background[0] = 0.2f;
  s.background[1] = 0.f;
  s.background[2] = 0.9f;
  const FastRenderer fast(m, ModelForm::Auto, FastPath::Float);
  for (const Camera& cam : views(33, 70)) {
    RenderStats rs, fs;
    const Image ref = render_reference(m, cam, s, &rs);
    EXPECT_GE(psnr(fast.render(cam, s, &fs), ref), 50.0);
    EXPECT_EQ(fs.samples, rs.samples);
  }
}

// A small object in a large image: most tiles see none of it and are
// filled with the background without marching; the image and the counts
// still match the reference.
TEST(Fast, TilesAwayFromTheObjectMatchTheReference) {
  const SceneModel m = several_model(64);
  const FastRenderer fast(m, ModelForm::Auto, FastPath::Float);
  RenderSettings s;
  s.background[0] = 0.3f;
  s.fast_transmittance_min = 0.f;
  for (const Camera& cam : {orbit_camera(150, 130, 20, 25, 14, 40), orbit_camera(97, 160, 250, -35, 11, 50)}) {
    RenderStats rs, fs;
    const Image ref = render_reference(m, cam, s, &rs);
    const Image img = fast.render(cam, s, &fs);
    EXPECT_GE(psnr(img, ref), 50.0);
    EXPECT_EQ(fs.rays, rs.rays);
    EXPECT_EQ(fs.rays_hit_aabb, rs.rays_hit_aabb);
    EXPECT_EQ(fs.samples, rs.samples);
    EXPECT_GT(fs.samples, 100u);
    EXPECT_LT(fs.rays_hit_aabb * 4, fs.rays);  // the object covers a small part of the image
    EXPECT_EQ(img.at(0, 0)[0], s.background[0]);
  }
}

// By default rays end at a transmittance of 1e-3 instead of the reference's
// 1e-4: fewer samples, and every pixel within 1e-3 of the reference's (the
// weights left sum to less than that, each on a colour difference of at most
// 1), whatever the background; a reference threshold above it is kept.
TEST(Fast, EarlierEndStaysWithinItsBound) {
  const SceneModel m = several_model(128);
  const FastRenderer fast(m, ModelForm::Float, FastPath::Float);
  for (float bg : {1.f, 0.f}) {
    RenderSettings s;
    s.form = ModelForm::Float;
    for (float& c : s.background) c = bg;
    ASSERT_EQ(s.fast_transmittance_min, 1e-3f);
    for (const Camera& cam : views(61, 47)) {
      RenderStats rs, fs;
      const Image ref = render_reference(m, cam, s, &rs);
      const Image img = fast.render(cam, s, &fs);
      float worst = 0.f;
      for (size_t i = 0; i < img.data.size(); ++i) worst = std::max(worst, std::fabs(img.data[i] - ref.data[i]));
      EXPECT_LE(worst, 1e-3f + 1e-5f);  // the bound, plus the float arithmetic's order
      EXPECT_GT(worst, 1e-5f);          // the end moved
      EXPECT_LT(fs.samples, rs.samples);
      EXPECT_GT(fs.samples, rs.samples * 8 / 10);
    }
  }
  RenderSettings high;
  high.form = ModelForm::Float;
  high.transmittance_min = 0.05f;
  const Camera cam = views(40, 40)[0];
  RenderStats rs, fs;
  render_reference(m, cam, high, &rs);
  fast.render(cam, high, &fs);
  EXPECT_EQ(fs.samples, rs.samples);
  high.fast_transmittance_min = 2.f;
  EXPECT_THROW(fast.render(cam, high), Error);
}

// The INT8 path ends its rays at a transmittance of 1e-2: every pixel within
// 1e-2 of its own image with the reference's samples (threshold 0).
TEST(Fast, Int8PathsEarlierEndStaysWithinItsBound) {
  const SceneModel m = several_model(128, false);
  const FastRenderer fast(m, ModelForm::Auto, FastPath::Int8);
  ASSERT_EQ(fast.arithmetic(), FastArithmetic::Int8);
  RenderSettings s;
  ASSERT_EQ(s.fast_int8_transmittance_min, 1e-2f);
  RenderSettings all = s;
  all.fast_int8_transmittance_min = 0.f;
  for (const Camera& cam : views(61, 47)) {
    RenderStats as, fs;
    const Image ref = fast.render(cam, all, &as);
    const Image img = fast.render(cam, s, &fs);
    float worst = 0.f;
    for (size_t i = 0; i < img.data.size(); ++i) worst = std::max(worst, std::fabs(img.data[i] - ref.data[i]));
    EXPECT_LE(worst, 1e-2f + 1e-5f);
    EXPECT_GT(worst, 1e-4f);  // the end moved
    EXPECT_LT(fs.samples, as.samples);
  }
  // The float path's threshold does not act on it, nor the INT8 one on the float path.
  RenderSettings other = s;
  other.fast_transmittance_min = 0.f;
  const Camera cam = views(61, 47)[0];
  EXPECT_EQ(fast.render(cam, other).data, fast.render(cam, s).data);
  const FastRenderer flt(m, ModelForm::Auto, FastPath::Float);
  other = s;
  other.fast_int8_transmittance_min = 0.f;
  EXPECT_EQ(flt.render(cam, other).data, flt.render(cam, s).data);
  other.fast_int8_transmittance_min = -1.f;
  EXPECT_THROW(fast.render(cam, other), Error);
}

TEST(Fast, ImageDoesNotDependOnTheThreadCount) {
  const SceneModel m = several_model(64, false);
  for (FastPath path : {FastPath::Int8, FastPath::Float}) {
    const FastRenderer fast(m, ModelForm::Auto, path);
    RenderSettings s;
    const Camera cam = views(80, 80)[0];
    s.threads = 1;
    const Image a = fast.render(cam, s);
    s.threads = 3;
    const Image b = fast.render(cam, s);
    EXPECT_EQ(a.data, b.data);
  }
}

TEST(Fast, RaysThatMissGiveExactlyTheBackground) {
  const SceneModel m = several_model(32, false);
  // Looking away from the scene.
  Camera cam = orbit_camera(20, 20, 0, 0, 4, 40);
  for (int i = 0; i < 3; ++i) cam.c2w[4 * i + 2] = -cam.c2w[4 * i + 2];  // camera -Z now points away
  RenderSettings s;
  s.background[0] = 0.25f;
  s.background[1] = 0.5f;
  s.background[2] = 0.75f;
  RenderStats stats;
  const Image img = FastRenderer(m, ModelForm::Auto, FastPath::Auto).render(cam, s, &stats);
  for (size_t i = 0; i < img.data.size(); ++i) EXPECT_EQ(img.data[i], s.background[i % 3]);
  EXPECT_EQ(stats.rays, 400u);
  EXPECT_EQ(stats.samples, 0u);
}

// INT4 features are read two ways: 16 channels (two words per vertex) as
// runs of neighbouring corners, other multiples of 8 by gathers, other counts
// one value at a time. Each matches the reference.
TEST(Fast, QuantizedFeaturesOfAnyWidthMatchTheReference) {
  for (int channels : {8, 12, 16, 24}) {
    ProceduralOptions o;
    o.micro_res = 64;
    o.seed = 7;
    o.feature_channels = channels;
    const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
    ASSERT_EQ(m.feature_channels, channels);
    const FastRenderer fast(m, ModelForm::Quantized, FastPath::Float);
    RenderSettings s;
    s.form = ModelForm::Quantized;
    s.fast_transmittance_min = 0.f;
    for (const Camera& cam : views(37, 29)) {
      RenderStats rs, fs;
      const Image ref = render_reference(m, cam, s, &rs);
      EXPECT_GE(psnr(fast.render(cam, s, &fs), ref), 50.0) << channels << " channels";
      EXPECT_EQ(fs.samples, rs.samples);
      EXPECT_GT(fs.samples, 100u);
    }
  }
}

TEST(Fast, Int8PathIsCloseToTheReference) {
  // The INT8 path quantizes activations: close to the float image, not equal.
  const SceneModel m = several_model(128, false);
  const FastRenderer fast(m, ModelForm::Auto, FastPath::Auto);
  ASSERT_EQ(fast.arithmetic(), FastArithmetic::Int8);
  RenderSettings s;
  for (const Camera& cam : views(40, 40)) {
    const double db = psnr(fast.render(cam, s), render_reference(m, cam, s));
    EXPECT_GE(db, 35.0);
    EXPECT_LT(db, 200.0);
  }
}

TEST(Fast, BadInputIsRefused) {
  const SceneModel m = several_model(32);
  EXPECT_THROW(FastRenderer(m, ModelForm::Float, FastPath::Int8), Error);  // no INT8 arithmetic on float data
  const SceneModel q = several_model(32, false);
  EXPECT_THROW(FastRenderer(q, ModelForm::Float, FastPath::Float), Error);  // no float form stored
  const FastRenderer fast(m, ModelForm::Auto, FastPath::Auto);
  const Camera cam = views(8, 8)[0];
  RenderSettings s;
  s.threads = -1;
  EXPECT_THROW(fast.render(cam, s), Error);
  s = RenderSettings{};
  s.step_micro = 0.f;
  EXPECT_THROW(fast.render(cam, s), Error);
  s = RenderSettings{};
  s.transmittance_min = 2.f;
  EXPECT_THROW(fast.render(cam, s), Error);
  Camera empty = cam;
  empty.width = 0;
  EXPECT_THROW(fast.render(empty, RenderSettings{}), Error);
  SceneModel broken = m;
  broken.mlps_f32[0].density[0].w.pop_back();
  EXPECT_THROW(FastRenderer(broken, ModelForm::Float, FastPath::Float), Error);
  SceneModel unfinalized = m;
  unfinalized.coarse_to_mlp.clear();
  EXPECT_THROW(FastRenderer(unfinalized, ModelForm::Auto, FastPath::Auto), Error);
}

}  // namespace
}  // namespace edrnr
