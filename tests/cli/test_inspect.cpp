// `edrnr inspect`: runs the built CLI on small hand-built models and checks
// its report, its JSON and its exit codes.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_fixture.h"
#include "core/file_io.h"
#include "model/model_io.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

using InspectCli = CliTest;

// Scene box [0, 32]^3 at micro_res 32 (micro voxel = 1 unit). Micro voxels (5,5,5),
// (20,9,9), (21,9,9): 3 micro, 2 leaf, 2 fine (so 2 blocks), 1 coarse voxel (1 MLP).
SceneModel hand_model(std::vector<int> density_widths = {2, 8, 4}, std::vector<int> color_widths = {7, 8, 3}) {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 2;
  m.scene_box = {{0.f, 0.f, 0.f}, {32.f, 32.f, 32.f}};
  m.object_aabb = {{5.f, 5.f, 5.f}, {22.f, 10.f, 10.f}};
  m.init_grids();
  m.occupancy[int(Tier::Micro)].set(5, 5, 5);
  m.occupancy[int(Tier::Micro)].set(20, 9, 9);
  m.occupancy[int(Tier::Micro)].set(21, 9, 9);
  m.rebuild_upper_tiers();
  m.block_fine_index = {linear_index(1, 1, 1, 8), linear_index(5, 2, 2, 8)};
  m.features_f32.assign(2 * kBlockVerts * 2, 0.5f);
  m.quantize_features();
  m.mlp_arch.dir_frequencies = 0;  // direction encoding = 3 values
  m.mlp_arch.density_widths = density_widths;
  m.mlp_arch.color_widths = color_widths;
  m.mlp_coarse_index = {0};
  MlpQ q;
  for (auto [widths, net] :
       {std::pair{&m.mlp_arch.density_widths, &q.density}, std::pair{&m.mlp_arch.color_widths, &q.color}})
    for (size_t l = 1; l < widths->size(); ++l) {
      size_t in = size_t((*widths)[l - 1]), out = size_t((*widths)[l]);
      net->push_back(DenseQ{int(in), int(out), std::vector<int8_t>(in * out, 1), std::vector<float>(out, 0.5f),
                            std::vector<float>(out, 0.f), 0.25f});
    }
  m.mlps_q8 = {q};
  m.metadata_json = R"({"scene": "hand", "views": 3})";
  m.finalize();
  return m;
}

TEST_F(InspectCli, TextReportOfAValidModel) {
  fs::path p = save(hand_model(), "ok.edrnr");
  RunResult r = run("inspect " + p.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("PASS  leaf tier is the OR of the micro tier"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("PASS  no occupied micro voxel lies outside the object AABB"), std::string::npos);
  EXPECT_EQ(r.out.find("FAIL"), std::string::npos);
  // INT8 MLP: 2x8 + 8x4 + 7x8 + 8x3 = 128 weights, 23 outputs x 8 bytes.
  EXPECT_NE(r.out.find("328 bytes per MLP; fits the 8448-byte MLP cache"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("density 2-8-4, colour 7-8-3"), std::string::npos);
  EXPECT_NE(r.out.find("scene: \"hand\""), std::string::npos);
}

TEST_F(InspectCli, JsonReport) {
  fs::path p = save(hand_model(), "ok.edrnr");
  RunResult r = run("inspect --json " + p.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["file_bytes"], fs::file_size(p));
  EXPECT_EQ(j["format_version"], 1);
  EXPECT_EQ(j["micro_res"], 32);
  const int expect_res[4] = {1, 8, 16, 32}, expect_occupied[4] = {1, 2, 2, 3};
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(j["tiers"][t]["resolution"], expect_res[t]);
    EXPECT_EQ(j["tiers"][t]["voxels"], expect_res[t] * expect_res[t] * expect_res[t]);
    EXPECT_EQ(j["tiers"][t]["occupied"], expect_occupied[t]);
  }
  EXPECT_DOUBLE_EQ(j["tiers"][3]["occupied_percent"].get<double>(), 100.0 * 3 / 32768);
  EXPECT_EQ(j["features"]["blocks"], 2);
  EXPECT_EQ(j["features"]["int4"], true);
  EXPECT_EQ(j["features"]["float"], true);
  EXPECT_EQ(j["features"]["float_bytes"], 2 * 125 * 2 * 4);
  EXPECT_EQ(j["mlps"]["count"], 1);
  EXPECT_EQ(j["mlps"]["q8_bytes_per_mlp"], 328);
  EXPECT_EQ(j["mlps"]["fits_mlp_cache"], true);
  EXPECT_EQ(j["metadata"]["views"], 3);
  // Coarse 1 bit -> 1 B, fine 8^3 bits -> 64 B, 2 fine voxels x 8 B, 2 blocks x 125 B (125 x 2 nibbles), 1 MLP x 328 B
  // (312 + 4 x (2 + 2) input multipliers).
  const auto& fp = j["dram_footprint_bytes"];
  EXPECT_EQ(fp["coarse_bitmap"], 1);
  EXPECT_EQ(fp["fine_bitmap"], 64);
  EXPECT_EQ(fp["micro_grid_bitmap"], 16);
  EXPECT_EQ(fp["features"], 250);
  EXPECT_EQ(fp["mlp_weights"], 328);
  EXPECT_EQ(fp["total"], 659);
  EXPECT_EQ(j["checks"].size(), 8u);
  EXPECT_EQ(j["ok"], true);
}

// The bundled models (assets/lego.edrnr, what the demo simulates, and
// mic and chair) are trained models the chip can run: every structural check
// passes, they are quantized with the chip's default 1216-byte MLP (six fit
// the MLP cache), each stays within the 20 MB the repository allows, and the
// preset's buffers fit Table I's SRAM budget for them (simulate does not
// refuse them).
TEST_F(InspectCli, BundledModelsAreChipModels) {
  for (const char* scene : {"lego", "mic", "chair"}) {
    SCOPED_TRACE(scene);
    const fs::path p = fs::path(EDRNR_SOURCE_DIR) / "assets" / (std::string(scene) + ".edrnr");
    ASSERT_TRUE(fs::exists(p)) << p;
    EXPECT_LE(fs::file_size(p), 20u * 1000 * 1000);
    RunResult r = run("inspect --json " + p.string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["ok"], true);
    EXPECT_EQ(j["micro_res"], 256);
    EXPECT_EQ(j["features"]["int4"], true);
    EXPECT_GT(j["features"]["blocks"].get<int>(), 0);
    EXPECT_EQ(j["mlps"]["count"], j["tiers"][0]["occupied"]);
    EXPECT_EQ(j["mlps"]["fits_mlp_cache"], true);
    EXPECT_EQ(j["mlps"]["q8_bytes_per_mlp"], 1216);
    EXPECT_EQ(j["metadata"]["producer"], "edrnr train");
    r = run("simulate " + p.string() + " --width 16 --orbit 30 -q --sram");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.out.find("OVER"), std::string::npos) << r.out;
  }
}

TEST_F(InspectCli, MlpTooLargeForTheCache) {
  // 2x64 + 64x64 + 67x64 + 64x3 = 8704 weights alone: more than 8448 bytes.
  fs::path p = save(hand_model({2, 64, 64}, {67, 64, 3}), "big.edrnr");
  RunResult r = run("inspect " + p.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("DOES NOT fit the 8448-byte MLP cache"), std::string::npos) << r.out;
  r = run("inspect --json " + p.string());
  EXPECT_EQ(nlohmann::json::parse(r.out)["mlps"]["fits_mlp_cache"], false);
}

TEST_F(InspectCli, FailingChecksExitNonZero) {
  SceneModel m = hand_model();
  m.occupancy[int(Tier::Leaf)].set(0, 0, 0);  // a leaf voxel with no micro voxel below it
  fs::path p = save(m, "bad.edrnr");
  RunResult r = run("inspect " + p.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("FAIL  leaf tier is the OR of the micro tier: 1 of 4096 leaf voxels differ"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("PASS  fine tier is the OR of the leaf tier"), std::string::npos);
  EXPECT_NE(r.err.find("1 of 8 model checks failed"), std::string::npos) << r.err;
  r = run("inspect --json " + p.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(nlohmann::json::parse(r.out)["ok"], false);
  r = run("inspect --no-check " + p.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("skipped (--no-check)"), std::string::npos);
}

TEST_F(InspectCli, BadInputNamesTheFile) {
  fs::path p = dir_ / "text.edrnr";
  write_file_atomic(p, std::string("this is not a model"));
  RunResult r = run("inspect " + p.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(p.string() + ": not an edrnr model"), std::string::npos) << r.err;
  r = run("inspect " + (dir_ / "missing.edrnr").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.edrnr"), std::string::npos) << r.err;
  r = run("inspect");
  EXPECT_NE(r.exit_code, 0);
}

}  // namespace
}  // namespace edrnr
