#include "render/options.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/error.h"
#include "core/limits.h"

namespace edrnr {
namespace {

// Comma-separated finite numbers; false if any part is not one.
bool parse_numbers(const std::string& text, std::vector<float>& out) {
  out.clear();
  size_t start = 0;
  while (true) {
    const size_t comma = text.find(',', start);
    const std::string part = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    if (part.empty()) return false;
    char* end = nullptr;
    const double v = std::strtod(part.c_str(), &end);
    if (end != part.c_str() + part.size() || !std::isfinite(v)) return false;
    out.push_back(float(v));
    if (comma == std::string::npos) return true;
    start = comma + 1;
  }
}

}  // namespace

void parse_background(const std::string& text, const std::string& flag, float rgb[3]) {
  if (text == "white" || text == "black") {
    const float v = text == "white" ? 1.f : 0.f;
    rgb[0] = rgb[1] = rgb[2] = v;
    return;
  }
  std::vector<float> v;
  if (!parse_numbers(text, v) || v.size() != 3) fail("{} '{}': expected white, black or R,G,B", flag, text);
  for (int c = 0; c < 3; ++c) {
    if (!(v[size_t(c)] >= 0.f && v[size_t(c)] <= 1.f)) fail("{} '{}': components must lie in [0, 1]", flag, text);
    rgb[c] = v[size_t(c)];
  }
}

ModelForm parse_model_form(const std::string& text, const std::string& flag) {
  if (text == "auto") return ModelForm::Auto;
  if (text == "float") return ModelForm::Float;
  if (text == "quantized") return ModelForm::Quantized;
  fail("{} '{}': expected auto, float or quantized", flag, text);
}

const char* model_form_name(ModelForm form) {
  switch (form) {
    case ModelForm::Auto:
      return "auto";
    case ModelForm::Float:
      return "float";
    case ModelForm::Quantized:
      return "quantized";
  }
  return "?";
}

Vec3f parse_vec3(const std::string& text, const std::string& flag) {
  std::vector<float> v;
  if (!parse_numbers(text, v) || v.size() != 3) fail("{} '{}': expected three numbers X,Y,Z", flag, text);
  return {v[0], v[1], v[2]};
}

void check_step_micro(double step_micro, int micro_res, const std::string& what) {
  if (!(step_micro > 0.0) || !std::isfinite(step_micro))
    fail("{} {:.6g}: must be a positive number of micro voxels", what, step_micro);
  if (step_micro > limits::kMaxStepMicro)
    fail("{} {:.6g}: over the limit of {} micro voxels", what, step_micro, limits::kMaxStepMicro);
  if (micro_res <= 0) return;
  const double diagonal = std::sqrt(3.0) * double(micro_res);  // micro voxels
  const double samples = std::ceil(diagonal / step_micro);
  if (samples > double(limits::kMaxSamplesPerRay))
    fail(
        "{} {:.6g}: up to {:.3g} samples per ray at micro resolution {}, over the limit of {} (the smallest step "
        "here is {:.3g})",
        what, step_micro, samples, micro_res, limits::kMaxSamplesPerRay, diagonal / double(limits::kMaxSamplesPerRay));
}

double trained_step_micro(const SceneModel& model) {
  const auto meta = nlohmann::json::parse(model.metadata_json, nullptr, false);
  if (!meta.is_object()) return 0.0;
  const auto it = meta.find("step_micro");
  if (it == meta.end() || !it->is_number()) return 0.0;
  const double step = it->get<double>();
  return step > 0.0 && std::isfinite(step) ? step : 0.0;
}

void check_step_micro(double step_micro, const SceneModel& model, const std::string& what) {
  check_step_micro(step_micro, model.micro_res, what);
  const double trained = trained_step_micro(model);
  if (trained > 0.0 && float(trained) != float(step_micro))
    fmt::print(stderr,
               "edrnr: warning: {} {:.6g} micro voxels, but the model was trained at {:.6g}: it renders best at "
               "its training step\n",
               what, step_micro, trained);
}

}  // namespace edrnr
