#include "subprocess.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>

namespace edrnr::cli {

int run_program(const std::vector<std::string>& argv) {
  if (argv.empty()) return 127;
  std::fflush(stdout);
  std::fflush(stderr);
  std::vector<std::string> args = argv;  // execvp wants mutable strings
  std::vector<char*> c_args;
  for (std::string& a : args) c_args.push_back(a.data());
  c_args.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return 127;
  if (pid == 0) {
    execvp(c_args[0], c_args.data());
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) return 127;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

}  // namespace edrnr::cli
