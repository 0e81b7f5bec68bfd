#pragma once
// Helpers of the sweep tests: a temporary folder, SPEC files in it, the
// source tree's preset folders.
#include <fmt/format.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include "sweep/plan.h"

namespace edrnr::sweep::testing {

struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& name)
      : path(std::filesystem::temp_directory_path() / fmt::format("edrnr_sweep_{}_{}", name, ::getpid())) {
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    std::ofstream(path / name, std::ios::binary) << text;
    return path / name;
  }
};

inline SearchDirs source_dirs() {
  const std::filesystem::path root(EDRNR_SOURCE_DIR);
  return {{root / "configs" / "chip"}, {root / "configs" / "dram"}};
}

inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// A sweep of 2 x 2 points on a small procedural sphere at 32 x 32 pixels
// (fractions of a second each).
inline const char* kTinySpec = R"(base: edr_nr_40nm
vary:
  rp_rob.entries: [8, 16]
  simulator.clock_MHz: [100, 200]
models:
  - {procedural: sphere, res: 64, channels: 8}
views:
  width: 32
  orbit: [30]
)";

}  // namespace edrnr::sweep::testing
