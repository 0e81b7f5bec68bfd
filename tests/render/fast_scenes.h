#pragma once
// Scenes, cameras and the march comparison shared by the fast renderer's tests.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "model/procedural.h"
#include "render/cameras.h"
#include "render/fast_march.h"
#include "render/traversal.h"

namespace edrnr::fast_test {

// The procedural "several" scene at micro resolution res.
inline SceneModel several_model(int res, bool store_float = true) {
  ProceduralOptions o;
  o.micro_res = res;
  o.store_float = store_float;
  o.seed = 7;  // pseudo-random unused channels: every feature channel is read
  return make_procedural_model("several", procedural_shapes("several"), o);
}

// Views around the scene at several azimuths and elevations, odd sizes so
// that tiles are cut at the image edges.
inline std::vector<Camera> views(int w, int h) {
  return {orbit_camera(w, h, 0, 30, 4, 50), orbit_camera(w, h, 75, 10, 4.5, 45), orbit_camera(w, h, 200, 60, 4, 50),
          orbit_camera(w, h, 310, -20, 3.5, 60)};
}

// Marches every pixel ray of `cam` with both marchers and asserts the same
// samples; adds the samples seen to *total and raises *k_max to the largest
// candidate index.
inline void expect_reference_samples(const SceneModel& m, const FastSkipGrid& skip, const Camera& cam, float delta,
                                     size_t* total, int64_t* k_max) {
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Ray ray = cam.pixel_ray(x, y);
      const MicroRay mr = make_micro_ray(m, ray, delta);
      SampleMarcher ref(m, ray, mr, true);
      FastMarcher fast(m, skip, ray, mr);
      MarchSample a, b;
      for (;;) {
        const bool more = ref.next(a);
        ASSERT_EQ(fast.next(b), more) << "pixel " << x << "," << y;
        if (!more) break;
        ASSERT_EQ(a.k, b.k);
        ASSERT_EQ(a.voxel, b.voxel);
        ASSERT_EQ(a.p_micro, b.p_micro);
        *k_max = std::max(*k_max, a.k);
        ++*total;
      }
    }
}

// Many small solids, a micro voxel or a few across (spheres, thin plates,
// thin rods) at pseudo-random places: the micro gaps around them vary in every
// direction, as on trained scenes with fine detail.
inline SceneModel dust_model(int res) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const float micro = 3.f / float(res);  // micro voxel edge: the default scene box is 3 units wide
  std::vector<Shape> shapes;
  for (int i = 0; i < 60; ++i) {
    Shape s;
    s.center = Vec3f{u(rng), u(rng), u(rng)};
    s.sigma = 50.f;
    s.color = Vec3f{0.5f + 0.4f * u(rng), 0.5f, 0.5f};
    if (i % 3 == 0) {
      s.kind = ShapeKind::Sphere;
      s.radius = micro * (0.6f + 0.8f * (u(rng) + 1.f));
    } else {
      s.kind = ShapeKind::Box;
      const int thin = i % 3;  // plates (1) and rods (2)
      for (int a = 0; a < 3; ++a) s.half_size[a] = micro * (a < thin ? 0.4f : 3.f + 2.f * u(rng));
    }
    shapes.push_back(s);
  }
  ProceduralOptions o;
  o.micro_res = res;
  return make_procedural_model("dust", shapes, o);
}

}  // namespace edrnr::fast_test
