#pragma once
// Each subcommand lives in its own cmd_*.cpp and registers itself with
//   static edrnr::cli::Registrar reg{order, register_fn};
// register_fn adds the subcommand and its options to `app`; the subcommand's
// callback runs it and throws edrnr::Error on bad input. `order` sets the
// position in --help (lower first).
#include <CLI/CLI.hpp>

#include <functional>
#include <vector>

namespace edrnr::cli {

using RegisterFn = void (*)(CLI::App& app);

struct Registrar {
  Registrar(int order, RegisterFn fn);
};

// All registered subcommands, sorted by order.
std::vector<RegisterFn> registered_commands();

}  // namespace edrnr::cli
