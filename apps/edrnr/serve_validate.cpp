#include "serve_validate.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>

namespace edrnr::serve {

void reject(int status, const std::string& field, const std::string& message) {
  throw RequestError(status, field, message);
}

std::string error_json(int status, const std::string& field, const std::string& message) {
  nlohmann::json j = {{"error", message}, {"status", status}};
  if (!field.empty()) j["field"] = field;
  // Names from the request may hold any bytes: replace what is not UTF-8.
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

namespace {

// A value quoted for a message: at most 40 characters, non-printable bytes as '?'.
std::string shown(std::string_view v) {
  std::string out;
  for (char c : v.substr(0, 40)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  if (v.size() > 40) out += "...";
  return "'" + out + "'";
}

}  // namespace

void check_params(const Params& params, const std::vector<std::string_view>& allowed) {
  if (params.size() > kMaxParams)
    reject(400, "", fmt::format("{} parameters: at most {} are accepted", params.size(), kMaxParams));
  std::set<std::string_view> seen;
  for (const auto& [name, value] : params) {
    bool known = false;
    for (std::string_view a : allowed) known = known || a == name;
    if (!known) {
      std::string list;
      for (std::string_view a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
      reject(400, name.substr(0, kMaxNameBytes),
             fmt::format("unknown parameter {} (accepted: {})", shown(name), list.empty() ? "none" : list));
    }
    if (!seen.insert(name).second) reject(400, name, fmt::format("parameter '{}' given more than once", name));
    if (value.size() > kMaxParamBytes)
      reject(400, name,
             fmt::format("parameter '{}': {} bytes, over the limit of {}", name, value.size(), kMaxParamBytes));
  }
}

bool is_safe_name(std::string_view name) {
  if (name.empty() || name.size() > kMaxNameBytes || name[0] == '.') return false;
  if (name.find("..") != std::string_view::npos) return false;
  for (char c : name)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
          c == '.'))
      return false;
  return true;
}

std::optional<std::string> find_param(const Params& params, const std::string& name) {
  auto it = params.find(name);
  if (it == params.end()) return std::nullopt;
  return it->second;
}

double number_param(const Params& params, const std::string& name, double lo, double hi,
                    std::optional<double> fallback) {
  const std::optional<std::string> text = find_param(params, name);
  if (!text) {
    if (fallback) return *fallback;
    reject(400, name, fmt::format("parameter '{}' is missing (a number between {} and {})", name, lo, hi));
  }
  double v = 0;
  const char* begin = text->data();
  const char* end = begin + text->size();
  auto [ptr, ec] = std::from_chars(begin, end, v);
  if (text->empty() || ec != std::errc() || ptr != end || !std::isfinite(v))
    reject(400, name, fmt::format("parameter '{}' = {}: not a number", name, shown(*text)));
  if (v < lo || v > hi)
    reject(400, name, fmt::format("parameter '{}' = {}: must be between {} and {} (limit)", name, *text, lo, hi));
  return v;
}

int int_param(const Params& params, const std::string& name, int lo, int hi, std::optional<int> fallback) {
  const std::optional<std::string> text = find_param(params, name);
  if (!text) {
    if (fallback) return *fallback;
    reject(400, name, fmt::format("parameter '{}' is missing (a whole number between {} and {})", name, lo, hi));
  }
  long long v = 0;
  const char* begin = text->data();
  const char* end = begin + text->size();
  auto [ptr, ec] = std::from_chars(begin, end, v);
  if (text->empty() || ec == std::errc::result_out_of_range)
    reject(400, name,
           fmt::format("parameter '{}' = {}: must be between {} and {} (limit)", name, shown(*text), lo, hi));
  if (ec != std::errc() || ptr != end)
    reject(400, name, fmt::format("parameter '{}' = {}: not a whole number", name, shown(*text)));
  if (v < lo || v > hi)
    reject(400, name, fmt::format("parameter '{}' = {}: must be between {} and {} (limit)", name, v, lo, hi));
  return int(v);
}

std::string name_param(const Params& params, const std::string& name, const std::vector<std::string>& known,
                       std::optional<std::string> fallback) {
  std::optional<std::string> text = find_param(params, name);
  if (!text) {
    if (fallback) return *fallback;
    reject(400, name, fmt::format("parameter '{}' is missing", name));
  }
  if (!is_safe_name(*text))
    reject(400, name,
           fmt::format("parameter '{}' = {}: a name is 1..{} characters of letters, digits, '_', '-' and '.', "
                       "not starting with '.'",
                       name, shown(*text), kMaxNameBytes));
  for (const std::string& k : known)
    if (k == *text) return *text;
  reject(404, name, fmt::format("{} {}: not found among the {} served", name, shown(*text), known.size()));
}

std::string choice_param(const Params& params, const std::string& name, const std::vector<std::string>& choices,
                         const std::string& fallback) {
  const std::optional<std::string> text = find_param(params, name);
  if (!text) return fallback;
  for (const std::string& c : choices)
    if (c == *text) return c;
  std::string list;
  for (const std::string& c : choices) list += (list.empty() ? "" : ", ") + c;
  reject(400, name, fmt::format("parameter '{}' = {}: must be one of {}", name, shown(*text), list));
}

bool bool_param(const Params& params, const std::string& name, bool fallback) {
  const std::optional<std::string> text = find_param(params, name);
  if (!text) return fallback;
  if (*text == "1" || *text == "true") return true;
  if (*text == "0" || *text == "false") return false;
  reject(400, name, fmt::format("parameter '{}' = {}: must be true or false", name, shown(*text)));
}

Params params_from_json_body(std::string_view body) {
  if (body.size() > kMaxBodyBytes)
    reject(413, "", fmt::format("request body of {} bytes: over the limit of {}", body.size(), kMaxBodyBytes));
  nlohmann::json j = nlohmann::json::parse(body, nullptr, false);
  if (j.is_discarded()) reject(400, "", "request body: not valid JSON");
  if (!j.is_object()) reject(400, "", "request body: must be a JSON object");
  if (j.size() > kMaxParams)
    reject(400, "", fmt::format("request body: {} fields, at most {} are accepted", j.size(), kMaxParams));
  Params out;
  for (const auto& [key, value] : j.items()) {
    if (value.is_string())
      out.emplace(key, value.get<std::string>());
    else if (value.is_boolean())
      out.emplace(key, value.get<bool>() ? "true" : "false");
    else if (value.is_number())
      out.emplace(key, value.dump());
    else
      reject(400, key.substr(0, kMaxNameBytes),
             fmt::format("field {}: must be a string, number or boolean", shown(key)));
  }
  return out;
}

bool is_client_id(std::string_view id) {
  if (id.size() < 8 || id.size() > 64) return false;
  for (char c : id)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-'))
      return false;
  return true;
}

uint64_t parse_job_id(std::string_view text) {
  uint64_t v = 0;
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || text.size() > 20 || ec != std::errc() || ptr != text.data() + text.size())
    reject(400, "job", fmt::format("job id {}: not a job number", shown(text)));
  return v;
}

}  // namespace edrnr::serve
