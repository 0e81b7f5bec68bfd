#pragma once
// Validation of what a browser sends to `edrnr serve`: query parameters and
// small JSON bodies. Every check throws RequestError carrying an HTTP status
// (4xx) and a message that names the field, the value and the limit; the
// server turns it into a JSON error response. Nothing here touches the
// network, so the rules are tested on their own (tests/web).
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace edrnr::serve {

// Query parameters as the HTTP layer delivers them (repeats allowed).
using Params = std::multimap<std::string, std::string>;

// A request the server refuses. status is 400 (malformed or out of range),
// 404 (no such model, dataset, preset or job), 409, 413, 429 or 503.
class RequestError : public std::runtime_error {
 public:
  RequestError(int status, std::string field, const std::string& message)
      : std::runtime_error(message), status_(status), field_(std::move(field)) {}
  int status() const { return status_; }
  const std::string& field() const { return field_; }

 private:
  int status_;
  std::string field_;
};

// Throws RequestError(status, field, message).
[[noreturn]] void reject(int status, const std::string& field, const std::string& message);

// The body of an error response: {"error": message, "field": field, "status": status}.
std::string error_json(int status, const std::string& field, const std::string& message);

// Limits on requests (docs/web.md lists them).
inline constexpr size_t kMaxParams = 24;                      // query parameters or JSON fields per request
inline constexpr size_t kMaxParamBytes = 128;                 // one parameter's value
inline constexpr size_t kMaxBodyBytes = 4096;                 // a POST body (JSON)
inline constexpr size_t kMaxNameBytes = 64;                   // model, dataset, preset and client names
inline constexpr int kMinRenderSide = 8;                      // pixels, width or height of a rendered view
inline constexpr int kMaxRenderSide = 1024;                   // pixels
inline constexpr int kMaxSimSide = 800;                       // pixels, width or height of a simulated view
inline constexpr double kMinRadius = 0.5, kMaxRadius = 20.0;  // orbit radius, scene units
inline constexpr double kMinFovDeg = 5.0, kMaxFovDeg = 120.0;
inline constexpr double kMaxElevationDeg = 89.0;  // |elevation|
inline constexpr double kMaxAzimuthDeg = 3600.0;  // |azimuth| (any angle mod 360 is reachable)

// Refuses a request with more than kMaxParams parameters, a name outside
// `allowed`, a repeated name, or a value longer than kMaxParamBytes.
void check_params(const Params& params, const std::vector<std::string_view>& allowed);

// A name that can only denote an entry of a served folder: 1..kMaxNameBytes of
// [A-Za-z0-9_.-], not starting with '.', no "..". (Lookups also require the
// name to be one the server listed.)
bool is_safe_name(std::string_view name);

// The value of `name`, or nullopt when absent.
std::optional<std::string> find_param(const Params& params, const std::string& name);

// A decimal number in [lo, hi] (finite; no trailing text). Absent: `fallback`,
// or a 400 naming the field when there is none.
double number_param(const Params& params, const std::string& name, double lo, double hi,
                    std::optional<double> fallback = std::nullopt);
// A whole number in [lo, hi].
int int_param(const Params& params, const std::string& name, int lo, int hi,
              std::optional<int> fallback = std::nullopt);
// A name (is_safe_name) that is one of `known`; 400 if malformed, 404 if unknown.
std::string name_param(const Params& params, const std::string& name, const std::vector<std::string>& known,
                       std::optional<std::string> fallback = std::nullopt);
// One of a fixed set of words ("rgba", "png"); 400 otherwise.
std::string choice_param(const Params& params, const std::string& name, const std::vector<std::string>& choices,
                         const std::string& fallback);
// "1"/"true" or "0"/"false"; absent: fallback.
bool bool_param(const Params& params, const std::string& name, bool fallback);

// A JSON object body of at most kMaxBodyBytes whose values are strings,
// numbers or booleans, as Params (numbers in their JSON spelling, booleans as
// "true"/"false"). 400 for anything else, 413 when too long.
Params params_from_json_body(std::string_view body);

// The client id a browser sends with a simulation request: 8..64 characters
// of [A-Za-z0-9_-].
bool is_client_id(std::string_view id);

// A job id as the server hands them out: 1..20 decimal digits; 400 otherwise.
uint64_t parse_job_id(std::string_view text);

}  // namespace edrnr::serve
