#pragma once
// Errors the user can act on. Every failure that reaches the command line is an
// edrnr::Error whose message names the file, field or flag that is wrong.
#include <fmt/format.h>

#include <stdexcept>
#include <string>
#include <utility>

namespace edrnr {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Throws edrnr::Error with a formatted message.
template <class... Args>
[[noreturn]] void fail(fmt::format_string<Args...> format, Args&&... args) {
  throw Error(fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace edrnr
