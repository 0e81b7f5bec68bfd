#pragma once
// Where the CLI looks for what ships with edrnr: chip and DRAM presets,
// scripts, bundled models and the Synthetic-NeRF data beside a checkout.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace edrnr::cli {

// The source tree this binary was built from (empty if unknown).
std::filesystem::path source_tree();
// The folder of the running executable (empty if unknown).
std::filesystem::path executable_dir();

// Where presets of `kind` ("chip", "dram") are looked for: ./configs/<kind>,
// beside the executable (build or install tree), and the source tree.
std::vector<std::filesystem::path> preset_dirs(const char* kind);

// A chip preset: a YAML file, or a name looked up as <dir>/<name>.yaml in
// preset_dirs("chip"). Throws Error naming the flag and every folder searched.
std::filesystem::path find_chip_preset_file(const std::string& name_or_path);

// A file shipped with edrnr at `relative` (e.g. "scripts/report_figures.py"):
// in the source tree, beside the executable, or in its share/edrnr folder.
std::optional<std::filesystem::path> find_shipped_file(const std::filesystem::path& relative);

}  // namespace edrnr::cli
