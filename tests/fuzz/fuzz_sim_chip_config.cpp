// libFuzzer harness for the chip preset loader: the functional keys and the
// `simulator` section (timing, memory with its DRAM part, energy, operating
// points, SRAM budget), as `edrnr simulate --chip` reads them (scripts/fuzz.sh).
//
// Each input is parsed as YAML and then as a chip preset. YAML syntax errors
// are expected; otherwise only edrnr::Error may end the load (what
// load_sim_config turns into the user's message). A preset that loads must
// pass validate(), respect the limits, and write back to YAML that loads to
// the same config.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness copies the shipped chip
// presets into DIR as the seed corpus and exits.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "sim/sim_config.h"

namespace {

using namespace edrnr;
using namespace edrnr::sim;

const std::filesystem::path kChipDir = std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "chip";

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(kChipDir))
    if (e.path().extension() == ".yaml") {
      write_file_atomic(dir / e.path().filename(), read_file_text(e.path()));
      ++n;
    }
  write_file_atomic(dir / "small.yaml",
                    std::string("rp_buffer_capacity: 8\nrender:\n  step_micro: 2\nsimulator:\n"
                                "  clock_MHz: 100\n  memory:\n    dram: ddr3-1066-1gb-x16-16bit\n"));
  std::printf("wrote %d seed presets to %s\n", n + 1, dir.c_str());
}

[[noreturn]] void finding(const char* what, const std::string& detail) {
  std::fprintf(stderr, "%s: %s\n", what, detail.c_str());
  std::abort();
}

std::string yaml_text(const SimConfig& c) {
  std::ostringstream s;
  s << sim_config_to_yaml(c);
  return s.str();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  YAML::Node node;
  try {
    node = YAML::Load(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const YAML::Exception&) {
    return 0;  // load_sim_config reports it as "not valid YAML"
  }
  if (!node.IsMap()) return 0;  // load_sim_config refuses it with a message first
  const std::vector<std::filesystem::path> dram_dirs = {kChipDir / ".." / "dram"};
  SimConfig c;
  try {
    c = sim_config_from_yaml(node, "fuzz.yaml", kChipDir, dram_dirs);
  } catch (const Error&) {
    return 0;
  }
  try {
    validate(c);
    check_chip_limits(c.chip);
  } catch (const Error& e) {
    finding("a loaded preset fails validation", e.what());
  }
  if (!(c.clock_MHz >= limits::kMinClockMHz && c.clock_MHz <= limits::kMaxClockMHz))
    finding("clock outside the limits", std::to_string(c.clock_MHz));
  try {
    const std::string text = yaml_text(c);
    const SimConfig back = sim_config_from_yaml(YAML::Load(text), "fuzz round trip", kChipDir, dram_dirs);
    if (yaml_text(back) != text) finding("YAML round trip changed the preset", text);
  } catch (const Error& e) {
    finding("a loaded preset does not load back from its YAML", e.what());
  } catch (const YAML::Exception& e) {
    finding("a loaded preset writes YAML that does not parse", e.what());
  }
  return 0;
}
