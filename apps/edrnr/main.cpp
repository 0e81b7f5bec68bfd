// edrnr: the EDR-NR neural rendering coprocessor, in software.
#include <algorithm>
#include <cstdio>
#include <exception>
#include <utility>

#include "commands.h"
#include "core/error.h"

namespace edrnr::cli {
namespace {
std::vector<std::pair<int, RegisterFn>>& registry() {
  static std::vector<std::pair<int, RegisterFn>> r;
  return r;
}
}  // namespace

Registrar::Registrar(int order, RegisterFn fn) { registry().emplace_back(order, fn); }

std::vector<RegisterFn> registered_commands() {
  auto r = registry();
  std::stable_sort(r.begin(), r.end(), [](auto& a, auto& b) { return a.first < b.first; });
  std::vector<RegisterFn> out;
  for (auto& [order, fn] : r) out.push_back(fn);
  return out;
}
}  // namespace edrnr::cli

int main(int argc, char** argv) {
  CLI::App app{"edrnr: an edge coprocessor for neural rendering with explicit data reuse, in software"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "edrnr 0.1.0");
  for (auto fn : edrnr::cli::registered_commands()) fn(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const edrnr::Error& e) {
    std::fprintf(stderr, "edrnr: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "edrnr: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
