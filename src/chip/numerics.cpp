#include "chip/numerics.h"

#include <fmt/format.h>

#include <array>
#include <optional>

#include "core/error.h"
#include "core/yaml_read.h"

namespace edrnr {

namespace {

// One integer width: its YAML key, its member, its valid range and its use.
struct IntField {
  const char* key;
  int ChipNumerics::*member;
  int min, max;
  const char* use;
};

constexpr std::array<IntField, 16> kIntFields{{
    {"feature_bits", &ChipNumerics::feature_bits, 1, 8, "unsigned feature codes (CFIU)"},
    {"weight_bits", &ChipNumerics::weight_bits, 2, 16, "signed MLP weights (TME)"},
    {"activation_bits", &ChipNumerics::activation_bits, 2, 16, "signed MLP layer inputs (TME)"},
    {"accumulator_bits", &ChipNumerics::accumulator_bits, 8, 48, "signed MAC accumulators, saturating (TME)"},
    {"requant_multiplier_bits", &ChipNumerics::requant_multiplier_bits, 2, 32,
     "unsigned requantization multipliers (TME, CFIU)"},
    {"mlp_output_bits", &ChipNumerics::mlp_output_bits, 8, 32, "signed raw density / colour (TME)"},
    {"mlp_output_frac_bits", &ChipNumerics::mlp_output_frac_bits, 0, 30, "fraction bits of the raw outputs"},
    {"interp_fraction_bits", &ChipNumerics::interp_fraction_bits, 1, 16,
     "unsigned position inside a micro voxel, per axis (OoO-SI, CFIU)"},
    {"interp_feature_bits", &ChipNumerics::interp_feature_bits, 8, 32, "signed interpolated features (CFIU)"},
    {"interp_feature_frac_bits", &ChipNumerics::interp_feature_frac_bits, 0, 30,
     "fraction bits of interpolated features"},
    {"direction_code_bits", &ChipNumerics::direction_code_bits, 4, 32, "signed view-direction encoding (TME input)"},
    {"direction_code_frac_bits", &ChipNumerics::direction_code_frac_bits, 1, 30,
     "fraction bits of the direction encoding"},
    {"lut_address_bits", &ChipNumerics::lut_address_bits, 4, 16, "activation LUT address (TME)"},
    {"alpha_bits", &ChipNumerics::alpha_bits, 2, 31, "unsigned opacity Q1.(n-1) (TME LUT, VRU)"},
    {"color_bits", &ChipNumerics::color_bits, 2, 31, "unsigned colour Q1.(n-1) (TME LUT, VRU)"},
    {"transmittance_bits", &ChipNumerics::transmittance_bits, 2, 31, "unsigned transmittance Q1.(n-1) (VRU)"},
}};

struct FloatField {
  const char* key;
  FloatFormat ChipNumerics::*member;
  const char* use;
};

constexpr std::array<FloatField, 2> kFloatFields{{
    {"ray_float", &ChipNumerics::ray_float, "ray generation, AABB test, entry search (ZORG, ABT, TSPS)"},
    {"traversal_float", &ChipNumerics::traversal_float, "traversal and sample positions (CTU, FTU, OoO-SI)"},
}};

template <class T>
T read_scalar(const YAML::Node& v, std::string_view where, std::string_view key, const char* expected) {
  return yaml_scalar<T>(v, std::string(where) + "." + std::string(key), expected);
}

std::optional<fx::Rounding> parse_rounding(std::string_view s) {
  for (fx::Rounding r : {fx::Rounding::Floor, fx::Rounding::HalfUp, fx::Rounding::HalfEven}) {
    if (s == rounding_name(r)) return r;
  }
  return std::nullopt;
}

FloatFormat float_from_yaml(const YAML::Node& node, const FloatFormat& defaults, std::string_view where) {
  if (!node.IsMap()) fail("{}: expected a map with exponent_bits, significand_bits, subnormals, specials", where);
  int exponent_bits = defaults.exponent_bits();
  int significand_bits = defaults.significand_bits();
  bool subnormals = defaults.subnormals();
  FloatSpecials specials = defaults.specials();
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (key == "exponent_bits") {
      exponent_bits = read_scalar<int>(kv.second, where, key, "an integer");
    } else if (key == "significand_bits") {
      significand_bits = read_scalar<int>(kv.second, where, key, "an integer");
    } else if (key == "subnormals") {
      subnormals = read_scalar<bool>(kv.second, where, key, "true or false");
    } else if (key == "specials") {
      const std::string s = read_scalar<std::string>(kv.second, where, key, "saturate or ieee");
      if (s == "saturate")
        specials = FloatSpecials::Saturate;
      else if (s == "ieee")
        specials = FloatSpecials::Ieee;
      else
        fail("{}.specials: '{}' is not saturate or ieee", where, s);
    } else {
      fail("{}: unknown key '{}' (known: exponent_bits, significand_bits, subnormals, specials)", where, key);
    }
  }
  try {
    return FloatFormat(exponent_bits, significand_bits, subnormals, specials);
  } catch (const Error& e) {
    fail("{}: {}", where, e.what());
  }
}

std::string known_keys() {
  std::string s;
  for (const IntField& f : kIntFields) s += fmt::format("{}, ", f.key);
  for (const FloatField& f : kFloatFields) s += fmt::format("{}, ", f.key);
  return s + "rounding";
}

}  // namespace

const char* rounding_name(fx::Rounding r) {
  switch (r) {
    case fx::Rounding::Floor:
      return "floor";
    case fx::Rounding::HalfUp:
      return "half_up";
    case fx::Rounding::HalfEven:
      return "half_even";
  }
  return "?";
}

const char* specials_name(FloatSpecials s) { return s == FloatSpecials::Ieee ? "ieee" : "saturate"; }

void validate(const ChipNumerics& n) {
  for (const IntField& f : kIntFields) {
    const int v = n.*(f.member);
    if (v < f.min || v > f.max) fail("numerics.{}: {} is out of range ({}..{})", f.key, v, f.min, f.max);
  }
  if (n.accumulator_bits < n.weight_bits + n.activation_bits - 1) {
    fail("numerics.accumulator_bits: {} cannot hold one {}-bit x {}-bit product (needs >= {})", n.accumulator_bits,
         n.weight_bits, n.activation_bits, n.weight_bits + n.activation_bits - 1);
  }
  if (n.mlp_output_frac_bits > n.mlp_output_bits - 2) {
    fail("numerics.mlp_output_frac_bits: {} leaves no integer bits in {}-bit outputs", n.mlp_output_frac_bits,
         n.mlp_output_bits);
  }
  if (n.direction_code_frac_bits > n.direction_code_bits - 2) {
    fail("numerics.direction_code_frac_bits: {} leaves no room for +-1.0 in {}-bit direction codes",
         n.direction_code_frac_bits, n.direction_code_bits);
  }
  // The interpolated feature holds a signed feature code (feature_bits + 1
  // bits after the zero point) with its fraction bits.
  if (n.interp_feature_frac_bits + n.feature_bits + 1 > n.interp_feature_bits) {
    fail("numerics.interp_feature_bits: {} bits cannot hold a {}-bit feature with {} fraction bits (needs >= {})",
         n.interp_feature_bits, n.feature_bits, n.interp_feature_frac_bits,
         n.feature_bits + 1 + n.interp_feature_frac_bits);
  }
}

ChipNumerics numerics_from_yaml(const YAML::Node& node, std::string_view where) {
  ChipNumerics n;
  if (!node || node.IsNull()) return n;
  if (!node.IsMap()) fail("{}: expected a map of widths", where);
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    bool known = false;
    for (const IntField& f : kIntFields) {
      if (key == f.key) {
        n.*(f.member) = read_scalar<int>(kv.second, where, key, "an integer");
        known = true;
      }
    }
    for (const FloatField& f : kFloatFields) {
      if (key == f.key) {
        n.*(f.member) = float_from_yaml(kv.second, n.*(f.member), fmt::format("{}.{}", where, key));
        known = true;
      }
    }
    if (key == "rounding") {
      const std::string s = read_scalar<std::string>(kv.second, where, key, "floor, half_up or half_even");
      const auto r = parse_rounding(s);
      if (!r) fail("{}.rounding: '{}' is not floor, half_up or half_even", where, s);
      n.rounding = *r;
      known = true;
    }
    if (!known) fail("{}: unknown key '{}' (known: {})", where, key, known_keys());
  }
  try {
    validate(n);
  } catch (const Error& e) {
    std::string msg = e.what();
    if (msg.rfind("numerics.", 0) == 0) msg = msg.substr(9);
    fail("{}.{}", where, msg);
  }
  return n;
}

YAML::Node numerics_to_yaml(const ChipNumerics& n) {
  YAML::Node node;
  for (const IntField& f : kIntFields) node[f.key] = n.*(f.member);
  node["rounding"] = rounding_name(n.rounding);
  for (const FloatField& f : kFloatFields) {
    const FloatFormat& ff = n.*(f.member);
    YAML::Node fnode;
    fnode["exponent_bits"] = ff.exponent_bits();
    fnode["significand_bits"] = ff.significand_bits();
    fnode["subnormals"] = ff.subnormals();
    fnode["specials"] = specials_name(ff.specials());
    node[f.key] = fnode;
  }
  return node;
}

std::string numerics_table(const ChipNumerics& n) {
  std::string s = fmt::format("{:<26} {:>9}  {}\n", "width", "bits", "use");
  for (const IntField& f : kIntFields) s += fmt::format("{:<26} {:>9}  {}\n", f.key, n.*(f.member), f.use);
  s += fmt::format("{:<26} {:>9}  {}\n", "rounding", rounding_name(n.rounding), "every integer narrowing");
  for (const FloatField& f : kFloatFields) {
    const FloatFormat& ff = n.*(f.member);
    s += fmt::format("{:<26} {:>9}  {}: {}\n", f.key, ff.total_bits(), f.use, ff.name());
  }
  return s;
}

}  // namespace edrnr
