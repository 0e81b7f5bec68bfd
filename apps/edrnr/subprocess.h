#pragma once
// Running another program from a subcommand (python3 for the figure scripts).
#include <string>
#include <vector>

namespace edrnr::cli {

// Runs argv[0] (a name looked up in PATH, or a path) with argv as its
// arguments, waits for it and returns its exit status: 127 when it could not be
// started, 128 when it did not exit normally. stdout and stderr are flushed
// first so the child's output follows ours in order.
int run_program(const std::vector<std::string>& argv);

}  // namespace edrnr::cli
