// Golden statistics: every statistic (cycle counts, counters, energy) and the
// image of two small procedural frames, as the simulator produced them when
// these files were recorded. A change that speeds up the simulator must keep
// them bit-identical; a change that means to alter the modelled chip
// re-records them (EDRNR_UPDATE_GOLDEN=1 ctest -R Golden) in a commit of its
// own that says why.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "core/file_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

namespace edrnr::sim {
namespace {

namespace fs = std::filesystem;
const fs::path kSource = EDRNR_SOURCE_DIR;
const fs::path kGolden = kSource / "tests/sim/golden";

struct Case {
  const char* name;
  const char* scene;
  int micro_res;
  uint64_t seed;
  int width, height;
  double azimuth;
};

const Case kCases[] = {
    {"several_64_40x36", "several", 64, 7, 40, 36, 30.0},
    {"torus_32_24x24", "torus", 32, 3, 24, 24, 200.0},
};

// The image as hex-free JSON numbers would be bulky: its bytes as floats are
// compared exactly through their bit patterns, stored as a checksum-free list
// of uint32 words.
nlohmann::json image_json(const Image& img) {
  nlohmann::json words = nlohmann::json::array();
  for (float v : img.data) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    words.push_back(u);
  }
  return {{"width", img.width}, {"height", img.height}, {"channels", img.channels}, {"bits", words}};
}

nlohmann::json record(const Case& c) {
  ProceduralOptions o;
  o.micro_res = c.micro_res;
  o.seed = c.seed;
  const SceneModel m = make_procedural_model(c.scene, procedural_shapes(c.scene), o);
  const SimConfig cfg = load_sim_config(kSource / "configs/chip/edr_nr_40nm.yaml");
  const SimResult r = simulate_chip(m, orbit_camera(c.width, c.height, c.azimuth, 25.0, 4.0, 50.0), cfg);
  nlohmann::json stats = r.stats->to_json();
  for (auto it = stats.begin(); it != stats.end();)
    it = it.key().rfind("host.", 0) == 0 ? stats.erase(it) : std::next(it);
  return {{"stats", stats}, {"hit_rate_series", r.hit_rate_series}, {"image", image_json(r.image)}};
}

TEST(Golden, StatisticsAndImageAreBitIdentical) {
  const bool update = std::getenv("EDRNR_UPDATE_GOLDEN") != nullptr;
  for (const Case& c : kCases) {
    SCOPED_TRACE(c.name);
    const nlohmann::json now = record(c);
    const fs::path file = kGolden / (std::string(c.name) + ".json");
    if (update) {
      fs::create_directories(kGolden);
      write_file_atomic(file, now.dump(1) + "\n");
      continue;
    }
    ASSERT_TRUE(fs::exists(file)) << file << " (record it with EDRNR_UPDATE_GOLDEN=1)";
    const nlohmann::json was = nlohmann::json::parse(read_file_text(file));
    EXPECT_EQ(now["image"], was["image"]) << "the image changed";
    EXPECT_EQ(now["hit_rate_series"], was["hit_rate_series"]);
    // Name by name, so a failure says which statistic moved.
    for (const auto& [name, entry] : was["stats"].items()) {
      ASSERT_TRUE(now["stats"].contains(name)) << name << " is gone";
      EXPECT_EQ(now["stats"][name], entry) << name;
    }
    EXPECT_EQ(now["stats"].size(), was["stats"].size()) << "statistics were added or removed";
  }
}

}  // namespace
}  // namespace edrnr::sim
