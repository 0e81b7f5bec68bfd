// edrnr: the EDR-NR neural rendering coprocessor, in software.
#include <algorithm>
#include <cstdio>
#include <exception>
#include <new>
#include <string>
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
  // A first word that is neither a flag nor a command: name it (CLI11 would
  // only say that a subcommand is required).
  if (argc > 1 && argv[1][0] != '-') {
    const std::string word = argv[1];
    std::string names;
    bool known = false;
    for (const CLI::App* sub : app.get_subcommands({})) {
      known = known || sub->check_name(word);
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    if (!known) {
      std::fprintf(stderr, "edrnr: error: unknown command '%s' (commands: %s; edrnr --help describes them)\n",
                   word.c_str(), names.c_str());
      return 1;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const edrnr::Error& e) {
    std::fprintf(stderr, "edrnr: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr,
                 "edrnr: error: out of memory (an input larger than this machine can hold; "
                 "docs/reliability.md lists the limits edrnr checks)\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "edrnr: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
