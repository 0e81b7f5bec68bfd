// End-to-end runs of the `edrnr` subcommands on small procedural scenes:
// make-scene -> inspect -> render (reference and chip engines) -> eval, and
// the errors a user gets for bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_fixture.h"
#include "core/image.h"
#include "core/metrics.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

using Commands = CliTest;

TEST_F(Commands, MakeSceneInspectAndRenderWithBothEngines) {
  const std::string model = (dir_ / "several.edrnr").string();
  RunResult r = run("make-scene several --res 32 --quantized-only -o " + model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run("inspect " + model);
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(r.out.find("FAIL"), std::string::npos) << r.out;

  const std::string ref = (dir_ / "ref.png").string(), chip = (dir_ / "chip.png").string();
  r = run("render " + model + " --orbit 40 --width 48 --height 40 -o " + ref);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run("render " + model + " --orbit 40 --width 48 --height 40 --engine chip -o " + chip);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  Image a = read_png_rgba(ref), b = read_png_rgba(chip);
  ASSERT_EQ(a.width, 48);
  ASSERT_EQ(a.height, 40);
  ASSERT_EQ(b.width, 48);
  // The chip's fixed-point image matches the float golden on the same
  // quantized model (the product's quality bar is 40 dB).
  EXPECT_GE(psnr(a, b), 40.0);
  // Not a blank picture: the scene is in view, so some pixels are not background.
  float darkest = 1.f;
  for (float v : a.data) darkest = std::min(darkest, v);
  EXPECT_LT(darkest, 0.7f);
}

// A dataset rendered from a model evaluates against that model at the 8-bit
// rounding limit (uniform rounding error: 10 log10(12 * 255^2) = 58.9 dB) and
// far lower against a different model.
TEST_F(Commands, EvalScoresTheModelThatMadeTheDataset) {
  ProceduralOptions opt;
  opt.micro_res = 32;
  opt.feature_channels = 4;
  SceneModel truth = make_procedural_model("sphere", procedural_shapes("sphere"), opt);
  SceneModel other = make_procedural_model("box", procedural_shapes("box"), opt);
  const fs::path root = dir_ / "data";
  fs::create_directories(root / "test");
  const double fov_x = 0.69111120700836;
  nlohmann::json frames = nlohmann::json::array();
  for (int v = 0; v < 2; ++v) {
    Camera cam = orbit_camera(40, 40, 70.0 * v, 25.0, 4.0, fov_x * 180.0 / M_PI);
    RenderSettings s;
    s.form = ModelForm::Quantized;
    write_png(root / "test" / ("r_" + std::to_string(v) + ".png"), render_reference(truth, cam, s));
    nlohmann::json m = nlohmann::json::array();
    for (int i = 0; i < 4; ++i)
      m.push_back({cam.c2w[4 * i], cam.c2w[4 * i + 1], cam.c2w[4 * i + 2], cam.c2w[4 * i + 3]});
    frames.push_back({{"file_path", "./test/r_" + std::to_string(v)}, {"transform_matrix", m}});
  }
  write_file_atomic(root / "transforms_test.json",
                    nlohmann::json{{"camera_angle_x", fov_x}, {"frames", frames}}.dump(2));
  const fs::path good = save(truth, "truth.edrnr"), bad = save(other, "other.edrnr");

  RunResult r = run("eval " + good.string() + " " + root.string() + " --json " + (dir_ / "good.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(read_file_text(dir_ / "good.json"));
  EXPECT_GT(j["mean_psnr_db"].get<double>(), 50.0) << r.out;
  r = run("eval " + bad.string() + " " + root.string() + " --json " + (dir_ / "bad.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(read_file_text(dir_ / "bad.json"));
  EXPECT_LT(j["mean_psnr_db"].get<double>(), 30.0) << r.out;

  // The chip engine renders the same quantized model to within the chip's
  // quality bar (40 dB) of the reference renderer, and so of the images.
  r = run("eval " + good.string() + " " + root.string() + " --engine chip --json " + (dir_ / "chip.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(read_file_text(dir_ / "chip.json"));
  EXPECT_EQ(j["engine"], "chip");
  EXPECT_GE(j["mean_psnr_vs_reference_db"].get<double>(), 40.0) << r.out;
  EXPECT_GE(j["views"][1]["psnr_vs_reference_db"].get<double>(), 40.0) << r.out;
  EXPECT_GT(j["mean_psnr_db"].get<double>(), 38.0) << r.out;
  r = run("eval " + good.string() + " " + root.string() + " --engine gpu");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--engine 'gpu'"), std::string::npos) << r.err;
}

// `simulate` writes its four outputs; switching a scheduling technique off
// changes the timing, never the image.
TEST_F(Commands, SimulateWritesItsOutputsAndTechniquesChangeOnlyTiming) {
  const std::string model = (dir_ / "s.edrnr").string();
  ASSERT_EQ(run("make-scene several --res 32 --quantized-only -o " + model).exit_code, 0);
  const fs::path a = dir_ / "a", b = dir_ / "b";
  RunResult r = run("simulate " + model + " --width 24 -q -o " + a.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("FPS"), std::string::npos) << r.out;
  for (const char* f : {"image.png", "stats.json", "config.yaml", "trace.json"}) EXPECT_TRUE(fs::exists(a / f)) << f;
  r = run("simulate " + model + " --width 24 -q --disable reorder,zorder -o " + b.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_file_text(a / "image.png"), read_file_text(b / "image.png"));
  auto ja = nlohmann::json::parse(read_file_text(a / "stats.json"));
  auto jb = nlohmann::json::parse(read_file_text(b / "stats.json"));
  EXPECT_EQ(ja["energy"]["pixels"].get<int>(), 24 * 24);
  EXPECT_GT(ja["energy"]["cycles"].get<double>(), 0.0);
  EXPECT_NE(ja["energy"]["cycles"], jb["energy"]["cycles"]);

  r = run("simulate " + model + " --width 24 -q --disable bogus -o " + a.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bogus"), std::string::npos) << r.err;
}

// A preset whose buffers do not fit Table I's SRAM classes is refused before
// any simulation, naming the class, the overrun and its largest buffers;
// --allow-over-budget runs it and marks the outputs.
TEST_F(Commands, SimulateRefusesAPresetOverTheSramBudget) {
  const std::string model = (dir_ / "s.edrnr").string();
  ASSERT_EQ(run("make-scene several --res 32 --quantized-only -o " + model).exit_code, 0);
  RunResult r = run("simulate " + model + " --width 8 -q -o " + (dir_ / "a").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(read_file_text(dir_ / "a" / "stats.json"));
  const uint64_t others = j["sram_budget"]["classes"]["others"]["bytes"].get<uint64_t>();
  EXPECT_EQ(j["sram_budget"]["over_budget"], false);
  EXPECT_EQ(j["stats"]["sram.class.others_bytes"]["value"].get<uint64_t>(), others);
  // The same chip with an "others" budget one byte short of what its buffers need.
  const fs::path preset = dir_ / "tight.yaml";
  write_file_atomic(preset, "simulator:\n  sram_budget_bytes:\n    others: " + std::to_string(others - 1) + "\n");
  r = run("simulate " + model + " --width 8 -q --chip " + preset.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("'others'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("1 over its budget"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("rp_buffer"), std::string::npos) << r.err;  // the largest at Rm = 32
  EXPECT_FALSE(fs::exists(dir_ / "b"));
  r = run("simulate " + model + " --width 8 -q --allow-over-budget --chip " + preset.string() + " -o " +
          (dir_ / "b").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("over Table I's SRAM budget"), std::string::npos) << r.out;
  j = nlohmann::json::parse(read_file_text(dir_ / "b" / "stats.json"));
  EXPECT_EQ(j["sram_budget"]["over_budget"], true);
  // --sram lists every buffer.
  r = run("simulate " + model + " --width 8 -q --sram");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* b : {"rp_buffer", "rp_rob", "location_shifter", "computation_sram", "fine_bitmap", "tme_weights"})
    EXPECT_NE(r.out.find(b), std::string::npos) << b;
}

TEST_F(Commands, BadInputGetsAClearErrorAndNonZeroExit) {
  const std::string model = (dir_ / "s.edrnr").string();
  ASSERT_EQ(run("make-scene sphere --res 32 --quantized-only -o " + model).exit_code, 0);

  RunResult r = run("render " + model + " -o " + (dir_ / "x.png").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--orbit"), std::string::npos) << r.err;

  r = run("render " + (dir_ / "missing.edrnr").string() + " --orbit 3 -o " + (dir_ / "x.png").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.edrnr"), std::string::npos) << r.err;

  std::string bytes = read_file_text(model);
  write_file_atomic(dir_ / "cut.edrnr", bytes.substr(0, bytes.size() / 2));
  r = run("render " + (dir_ / "cut.edrnr").string() + " --orbit 3 -o " + (dir_ / "x.png").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("truncated"), std::string::npos) << r.err;

  r = run("render " + model + " --orbit 3 --engine gpu -o " + (dir_ / "x.png").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("reference, chip"), std::string::npos) << r.err;

  r = run("render " + model + " --orbit 3 --no-such-flag -o " + (dir_ / "x.png").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--no-such-flag"), std::string::npos) << r.err;

  r = run("eval " + model + " " + (dir_ / "nodata").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("transforms_test.json"), std::string::npos) << r.err;

  r = run("make-scene teapot -o " + (dir_ / "t.edrnr").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "t.edrnr"));
}

}  // namespace
}  // namespace edrnr
