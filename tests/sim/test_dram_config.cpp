// DRAM presets and the YAML loader.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "sim/dram.h"
#include "sim/dram_config.h"

namespace edrnr::sim {
namespace {

const std::filesystem::path kPresetDir = std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "dram";

std::string preset_text(const std::string& name) {
  std::ifstream in(kPresetDir / (name + ".yaml"));
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Replaces the first occurrence of `from` (which must exist) with `to`.
std::string replace(std::string text, const std::string& from, const std::string& to) {
  size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

std::string error_of(const std::string& yaml) {
  try {
    parse_dram_config(yaml, "test.yaml");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(DramConfig, Ddr3_1600PresetCarriesDramsim3Values) {
  DramConfig c = load_dram_config(kPresetDir / "ddr3-1600-4gb-x16-64bit.yaml");
  // DRAMsim3 DDR3_4Gb_x16_1600: BL 8, 8 banks, 32768 x 1024, CL 11, CWL 8,
  // tRCD 11, tRP 11, tRAS 28, tRFC 208, tREFI 6240, tRRD 5, tWTR 6, tFAW 32,
  // tWR 12, tRTP 6, tCCD 4, tRTRS 1; VDD 1.35, IDD0 66, IDD2N 32, IDD3N 47,
  // IDD4R 235, IDD4W 171, IDD5 235.
  EXPECT_EQ(c.burst_length, 8u);
  EXPECT_EQ(c.banks, 8u);
  EXPECT_EQ(c.rows, 32768u);
  EXPECT_EQ(c.columns, 1024u);
  EXPECT_EQ(c.device_width_bits, 16u);
  EXPECT_DOUBLE_EQ(c.tCK_ns, 1.25);
  EXPECT_EQ(c.CL, 11u);
  EXPECT_EQ(c.CWL, 8u);
  EXPECT_EQ(c.tRCD, 11u);
  EXPECT_EQ(c.tRP, 11u);
  EXPECT_EQ(c.tRAS, 28u);
  EXPECT_EQ(c.tRC, 39u);
  EXPECT_EQ(c.tRFC, 208u);
  EXPECT_EQ(c.tREFI, 6240u);
  EXPECT_EQ(c.tRRD, 5u);
  EXPECT_EQ(c.tWTR, 6u);
  EXPECT_EQ(c.tFAW, 32u);
  EXPECT_EQ(c.tWR, 12u);
  EXPECT_EQ(c.tRTP, 6u);
  EXPECT_EQ(c.tCCD, 4u);
  EXPECT_EQ(c.tRTRS, 1u);
  EXPECT_DOUBLE_EQ(c.VDD_V, 1.35);
  EXPECT_DOUBLE_EQ(c.IDD0_mA, 66);
  EXPECT_DOUBLE_EQ(c.IDD2N_mA, 32);
  EXPECT_DOUBLE_EQ(c.IDD3N_mA, 47);
  EXPECT_DOUBLE_EQ(c.IDD4R_mA, 235);
  EXPECT_DOUBLE_EQ(c.IDD4W_mA, 171);
  EXPECT_DOUBLE_EQ(c.IDD5_mA, 235);
  EXPECT_EQ(c.devices_per_rank(), 4u);
  EXPECT_EQ(c.burst_bytes(), 64u);
  EXPECT_EQ(c.capacity_bytes(), uint64_t{2} << 30);  // four 4 Gb devices
  EXPECT_DOUBLE_EQ(c.peak_bandwidth_GBps(), 12.8);
}

TEST(DramConfig, EveryPresetLoadsWithItsDatasheetGeometry) {
  struct Expect {
    const char* name;
    uint64_t capacity_bytes;
    double peak_GBps;
    uint32_t burst_bytes;
  };
  const Expect expected[] = {
      {"ddr3-1600-4gb-x16-64bit", uint64_t{4} * (512 << 20), 2 * 8 / 1.25, 64},
      {"ddr3-1600-4gb-x16-16bit", uint64_t{512} << 20, 2 * 2 / 1.25, 16},
      {"ddr3-1333-1gb-x8-64bit", uint64_t{8} * (128 << 20), 2 * 8 / 1.5, 64},
      {"ddr3-1066-1gb-x16-16bit", uint64_t{128} << 20, 2 * 2 / 1.875, 16},
  };
  for (const Expect& e : expected) {
    DramConfig c = load_dram_config(kPresetDir / (std::string(e.name) + ".yaml"));
    EXPECT_EQ(c.capacity_bytes(), e.capacity_bytes) << e.name;
    EXPECT_DOUBLE_EQ(c.peak_bandwidth_GBps(), e.peak_GBps) << e.name;
    EXPECT_EQ(c.burst_bytes(), e.burst_bytes) << e.name;
    EXPECT_FALSE(c.source.empty()) << e.name;
    EXPECT_EQ(c.tRC, c.tRAS + c.tRP) << e.name;
  }
  // Every file in the folder is a valid preset.
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kPresetDir)) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    EXPECT_NO_THROW(load_dram_config(entry.path())) << entry.path();
  }
  EXPECT_GE(files, 4);
}

TEST(DramConfig, ReferenceActivateAndReadEnergyOfTheDdr3_1600Part) {
  // The reference notes give, for 4 devices on a 64-bit bus: ACT ~ 6.1 nJ and
  // read ~ 9.9 pJ/bit (core only).
  DramConfig c = load_dram_config(kPresetDir / "ddr3-1600-4gb-x16-64bit.yaml");
  StatsRegistry stats;
  DramSystem dram(c, stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  while (dram.idle() == false) dram.tick();
  DramEnergy e = dram.energy();
  EXPECT_NEAR(e.activate_pJ / 1000.0, 6.1, 0.05);
  EXPECT_NEAR(e.read_pJ / 512.0, 9.9, 0.05);
}

TEST(DramConfig, MissingUnknownAndMalformedKeysAreNamed) {
  std::string good = preset_text("ddr3-1600-4gb-x16-64bit");
  ASSERT_FALSE(good.empty());
  EXPECT_EQ(error_of(good), "");
  EXPECT_NE(error_of(replace(good, "  tRCD: 11", "")).find("missing key 'timing.tRCD'"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "  tRCD: 11", "  tRCD: 11\n  tFOO: 3")).find("unknown key 'timing.tFOO'"),
            std::string::npos);
  EXPECT_NE(error_of(good + "extra: 1\n").find("unknown key 'extra'"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "CL: 11", "CL: eleven")).find("timing.CL"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "CL: 11", "CL: -3")).find("timing.CL"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "VDD_V: 1.35", "VDD_V: high")).find("power.VDD_V"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "banks: 8", "banks: 6")).find("structure.banks"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "tRC: 39", "tRC: 30")).find("timing.tRC"), std::string::npos);
  EXPECT_NE(error_of(replace(good, "row:bank:rank:column:channel", "row:bank:column:channel")).find("rank"),
            std::string::npos);
  EXPECT_NE(error_of(replace(good, "row:bank:rank:column:channel", "row:bank:rank:column:chan")).find("'chan'"),
            std::string::npos);
  EXPECT_NE(error_of(replace(good, "refresh: true", "refresh: maybe")).find("controller.refresh"), std::string::npos);
  EXPECT_NE(error_of("timing: [1, 2\n").find("test.yaml"), std::string::npos);       // YAML syntax error
  EXPECT_EQ(error_of(replace(good, "  tRCD: 11", "")).rfind("test.yaml: ", 0), 0u);  // starts with the file
}

TEST(DramConfig, ResolvedConfigRoundTripsThroughYaml) {
  DramConfig a = load_dram_config(kPresetDir / "ddr3-1066-1gb-x16-16bit.yaml");
  a.address_mapping = parse_address_mapping("channel:row:rank:bank:column");
  a.refresh = false;
  a.io_pJ_per_bit = 3.25;
  DramConfig b = parse_dram_config(dram_config_to_yaml(a), "round trip");
  EXPECT_EQ(b.name, a.name);
  EXPECT_EQ(b.source, a.source);
  EXPECT_EQ(b.rows, a.rows);
  EXPECT_EQ(b.tCK_ns, a.tCK_ns);
  EXPECT_EQ(b.tRTRS, a.tRTRS);
  EXPECT_EQ(b.tREFI, a.tREFI);
  EXPECT_EQ(b.IDD4W_mA, a.IDD4W_mA);
  EXPECT_EQ(b.io_pJ_per_bit, 3.25);
  EXPECT_EQ(b.refresh, false);
  EXPECT_EQ(address_mapping_to_string(b.address_mapping), "channel:row:rank:bank:column");
}

TEST(DramConfig, PresetLookupByNameOrPath) {
  std::vector<std::filesystem::path> dirs = {"/nonexistent/dir", kPresetDir};
  EXPECT_EQ(find_dram_preset("ddr3-1333-1gb-x8-64bit", dirs), kPresetDir / "ddr3-1333-1gb-x8-64bit.yaml");
  std::filesystem::path direct = kPresetDir / "ddr3-1066-1gb-x16-16bit.yaml";
  EXPECT_EQ(find_dram_preset(direct.string(), {}), direct);
  try {
    find_dram_preset("ddr5-9999", dirs);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("ddr5-9999"), std::string::npos);
    EXPECT_NE(m.find("ddr3-1600-4gb-x16-64bit"), std::string::npos);  // lists what exists
  }
  EXPECT_THROW(find_dram_preset("missing/file.yaml", dirs), Error);
}

// The clock period and every timing value have stated limits; a refusal
// names the field, the value and the range (issue #16: tCK_ns 1e-9 hung the
// simulator, 1e9 was reported as "must be positive").
TEST(DramConfig, TimingLimitsAreStatedAndEnforced) {
  std::string good = preset_text("ddr3-1600-4gb-x16-64bit");
  for (const char* bad : {"tCK_ns: 1e-9", "tCK_ns: 1e9", "tCK_ns: 0", "tCK_ns: -1.25", "tCK_ns: .nan"}) {
    const std::string m = error_of(replace(good, "tCK_ns: 1.25", bad));
    EXPECT_NE(m.find("timing.tCK_ns"), std::string::npos) << bad << ": " << m;
    EXPECT_NE(m.find("must be between 0.25 and 20 ns"), std::string::npos) << bad << ": " << m;
  }
  EXPECT_EQ(error_of(replace(good, "tCK_ns: 1.25", "tCK_ns: 0.25")), "");
  EXPECT_EQ(error_of(replace(good, "tCK_ns: 1.25", "tCK_ns: 20")), "");
  std::string m = error_of(replace(good, "tRFC: ", "tRFC: 3000000 #"));
  EXPECT_NE(m.find("timing.tRFC = 3000000 cycles is over the limit of 1048576"), std::string::npos) << m;
  m = error_of(replace(good, "queue_depth_bursts: ", "queue_depth_bursts: 100000 #"));
  EXPECT_NE(m.find("controller.queue_depth_bursts = 100000 is over the limit of 4096"), std::string::npos) << m;
}

}  // namespace
}  // namespace edrnr::sim
