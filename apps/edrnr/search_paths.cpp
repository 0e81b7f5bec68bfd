#include "search_paths.h"

#include <algorithm>

#include "core/error.h"

namespace edrnr::cli {

namespace fs = std::filesystem;

fs::path source_tree() {
  const fs::path root = fs::path(__FILE__).parent_path().parent_path().parent_path();
  return root.is_absolute() ? root : fs::path();
}

fs::path executable_dir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

std::vector<fs::path> preset_dirs(const char* kind) {
  std::vector<fs::path> dirs = {fs::path("configs") / kind};
  if (const fs::path dir = executable_dir(); !dir.empty()) {
    dirs.push_back(dir / "configs" / kind);
    dirs.push_back(dir.parent_path() / "configs" / kind);
    dirs.push_back(dir.parent_path() / "share" / "edrnr" / "configs" / kind);
  }
  if (const fs::path root = source_tree(); !root.empty()) dirs.push_back(root / "configs" / kind);
  std::vector<fs::path> unique;
  for (const fs::path& d : dirs)
    if (std::find(unique.begin(), unique.end(), d.lexically_normal()) == unique.end())
      unique.push_back(d.lexically_normal());
  return unique;
}

fs::path find_chip_preset_file(const std::string& name) {
  std::error_code ec;
  if (fs::is_regular_file(name, ec)) return name;
  std::string searched;
  for (const fs::path& d : preset_dirs("chip")) {
    const fs::path p = d / (name + ".yaml");
    if (fs::is_regular_file(p, ec)) return p;
    searched += "\n  " + d.string();
  }
  fail("--chip '{}': no such file, and no preset {}.yaml in:{}", name, name, searched);
}

std::optional<fs::path> find_shipped_file(const fs::path& relative) {
  std::vector<fs::path> candidates;
  if (const fs::path root = source_tree(); !root.empty()) candidates.push_back(root / relative);
  if (const fs::path dir = executable_dir(); !dir.empty()) {
    candidates.push_back(dir / relative);
    candidates.push_back(dir.parent_path() / relative);
    candidates.push_back(dir.parent_path() / "share" / "edrnr" / relative);
  }
  std::error_code ec;
  for (const fs::path& p : candidates)
    if (fs::is_regular_file(p, ec)) return p;
  return std::nullopt;
}

}  // namespace edrnr::cli
