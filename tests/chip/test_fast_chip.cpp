// The fast CPU renderer's INT8 path against the chip model's image on
// procedural scenes (the fast renderer lives in the render module, which
// cannot see the chip; this module sees both).
#include <gtest/gtest.h>

#include "chip/chip.h"
#include "core/metrics.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/fast.h"
#include "render/reference.h"

namespace edrnr {
namespace {

TEST(FastInt8, MatchesTheChipModel) {
  for (uint64_t seed : {7u}) {  // pseudo-random unused channels: all are read
    ProceduralOptions o;
    o.micro_res = 128;
    o.seed = seed;
    o.store_float = false;  // only the quantized form, as the bundled models
    const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
    const FastRenderer fast(m, ModelForm::Auto, FastPath::Auto);
    ASSERT_EQ(fast.arithmetic(), FastArithmetic::Int8);
    RenderSettings s;
    for (const Camera& cam : {orbit_camera(64, 48, 30, 25, 4, 50), orbit_camera(53, 53, 160, -15, 4.5, 45)}) {
      RenderStats cs, fs;
      const Image chip = render_chip_engine(m, cam, s, &cs);
      const Image img = fast.render(cam, s, &fs);
      const double db = psnr(img, chip);
      EXPECT_GE(db, 40.0) << "seed " << seed;
      EXPECT_GT(fs.samples, 1000u);
      // The same scene through the float reference: the INT8 path is a
      // quantized approximation of it, so close but not equal.
      const Image ref = render_reference(m, cam, s);
      EXPECT_GE(psnr(img, ref), 30.0);
      std::printf("seed %llu: INT8 path vs chip %.2f dB, vs reference %.2f dB; chip vs reference %.2f dB\n",
                  static_cast<unsigned long long>(seed), db, psnr(img, ref), psnr(chip, ref));
    }
  }
}

}  // namespace
}  // namespace edrnr
