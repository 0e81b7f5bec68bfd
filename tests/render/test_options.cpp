// The sample-spacing limit (issue #16: --step 1e-30 gave a blank image, 1e-9
// hung the renderer).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/error.h"
#include "core/limits.h"
#include "model/scene_model.h"
#include "render/options.h"

namespace edrnr {
namespace {

std::string error_of(double step, int micro_res) {
  try {
    check_step_micro(step, micro_res, "--step");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(RenderOptions, StepLimits) {
  EXPECT_EQ(error_of(1.0, 256), "");
  EXPECT_EQ(error_of(0.25, 1024), "");
  EXPECT_NE(error_of(0.0, 32).find("--step 0: must be a positive number of micro voxels"), std::string::npos);
  EXPECT_NE(error_of(-1.0, 32).find("must be a positive"), std::string::npos);
  EXPECT_NE(error_of(NAN, 32).find("must be a positive"), std::string::npos);
  EXPECT_NE(error_of(1e30, 32).find("--step 1e+30: over the limit of 1024 micro voxels"), std::string::npos);
  for (double tiny : {1e-30, 1e-17, 1e-9}) {
    const std::string m = error_of(tiny, 32);
    EXPECT_NE(m.find("samples per ray at micro resolution 32, over the limit of 65536"), std::string::npos) << m;
    EXPECT_NE(m.find("the smallest step here is 0.000846"), std::string::npos) << m;
    EXPECT_EQ(error_of(tiny, 0).find("samples per ray"), std::string::npos);  // no model yet: only the range
  }
  // The boundary: sqrt(3) * Rm / step samples at most.
  const double smallest = std::sqrt(3.0) * 256 / double(limits::kMaxSamplesPerRay);
  EXPECT_EQ(error_of(smallest * 1.001, 256), "");
  EXPECT_NE(error_of(smallest * 0.99, 256), "");
}

// The trainer records its step in the model's metadata; the renderers read it
// back to warn when they would sample at another one.
TEST(RenderOptions, TrainedStepIsReadFromTheMetadata) {
  SceneModel m;
  EXPECT_EQ(trained_step_micro(m), 0.0);  // "{}": none recorded
  m.metadata_json = R"({"producer": "edrnr train", "step_micro": 0.5})";
  EXPECT_EQ(trained_step_micro(m), 0.5);
  m.metadata_json = R"({"step_micro": 2})";
  EXPECT_EQ(trained_step_micro(m), 2.0);
  for (const char* bad : {R"({"step_micro": "0.5"})", R"({"step_micro": -1})", R"([0.5])", "not json"}) {
    m.metadata_json = bad;
    EXPECT_EQ(trained_step_micro(m), 0.0) << bad;
  }
  m.metadata_json = R"({"step_micro": 0.5})";
  m.micro_res = 32;
  EXPECT_NO_THROW(check_step_micro(1.0, m, "--step"));  // a warning, not an error
  EXPECT_THROW(check_step_micro(1e-9, m, "--step"), Error);
}

}  // namespace
}  // namespace edrnr
