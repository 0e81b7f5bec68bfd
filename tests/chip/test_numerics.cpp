// The chip's width table: defaults, YAML round trip, clear errors.
#include <gtest/gtest.h>

#include <string>

#include "chip/numerics.h"
#include "core/error.h"
#include "core/file_io.h"

namespace edrnr {
namespace {

// The message of the Error thrown by reading `yaml`, or "" if none.
std::string error_of(const std::string& yaml) {
  try {
    numerics_from_yaml(YAML::Load(yaml));
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(ChipNumerics, DefaultsFollowThePaper) {
  const ChipNumerics n;
  EXPECT_EQ(n.feature_bits, 4);
  EXPECT_EQ(n.weight_bits, 8);
  EXPECT_EQ(n.activation_bits, 8);
  EXPECT_EQ(n.accumulator_bits, 20);
  EXPECT_EQ(n.interp_feature_bits, 16);
  EXPECT_EQ(n.direction_code_bits, 16);
  EXPECT_EQ(n.direction_code_frac_bits, 14);
  EXPECT_EQ(n.ray_float, FloatFormat(8, 16, false, FloatSpecials::Saturate));
  EXPECT_EQ(n.traversal_float.total_bits(), 24);
  EXPECT_EQ(n.rounding, fx::Rounding::HalfUp);
  EXPECT_NO_THROW(validate(n));
  EXPECT_EQ(unit_one(16), 32768);
  EXPECT_EQ(unit_one(8), 128);
}

TEST(ChipNumerics, AccumulatorHoldsTheWidestDefaultLayer) {
  // The widest default MLP layer has 32 inputs. Hidden-layer inputs are ReLU
  // outputs in [0, 127] and weights lie in [-128, 127], so
  // |sum| <= 32 * 127 * 128 = 520192 <= 2^19 - 1 = 524287: INT20 never
  // saturates on hidden layers.
  const ChipNumerics n;
  EXPECT_LE(int64_t(32) * fx::max_signed(n.activation_bits) * -fx::min_signed(n.weight_bits),
            fx::max_signed(n.accumulator_bits));
  // The interpolated feature holds +-15 codes with 8 fraction bits: |3840| < 2^15.
  EXPECT_LE(fx::max_unsigned(n.feature_bits) << n.interp_feature_frac_bits, fx::max_signed(n.interp_feature_bits));
}

TEST(ChipNumerics, YamlRoundTrip) {
  ChipNumerics n;
  EXPECT_EQ(numerics_from_yaml(numerics_to_yaml(n)), n);
  n.accumulator_bits = 24;
  n.rounding = fx::Rounding::HalfEven;
  n.traversal_float = FloatFormat(6, 20, true, FloatSpecials::Ieee);
  n.transmittance_bits = 20;
  const ChipNumerics back = numerics_from_yaml(numerics_to_yaml(n));
  EXPECT_EQ(back, n);
  EXPECT_EQ(back.traversal_float.significand_bits(), 20);
  EXPECT_EQ(back.rounding, fx::Rounding::HalfEven);
  // Through text as well.
  YAML::Emitter out;
  out << numerics_to_yaml(n);
  EXPECT_EQ(numerics_from_yaml(YAML::Load(out.c_str())), n);
}

TEST(ChipNumerics, PartialYamlKeepsDefaults) {
  const ChipNumerics n = numerics_from_yaml(YAML::Load("accumulator_bits: 24\nray_float: {significand_bits: 20}"));
  ChipNumerics expect;
  expect.accumulator_bits = 24;
  expect.ray_float = FloatFormat(8, 20, false, FloatSpecials::Saturate);
  EXPECT_EQ(n, expect);
  EXPECT_EQ(numerics_from_yaml(YAML::Load("")), ChipNumerics{});
  EXPECT_EQ(numerics_from_yaml(YAML::Node()), ChipNumerics{});
}

TEST(ChipNumerics, DefaultConfigFileMatchesDefaults) {
  const std::string text = read_file_text(std::string(EDRNR_SOURCE_DIR) + "/configs/numerics/default.yaml");
  EXPECT_EQ(numerics_from_yaml(YAML::Load(text), "configs/numerics/default.yaml"), ChipNumerics{});
}

TEST(ChipNumerics, ErrorsNameTheKey) {
  std::string e = error_of("acumulator_bits: 20");
  EXPECT_TRUE(contains(e, "unknown key 'acumulator_bits'")) << e;
  EXPECT_TRUE(contains(e, "accumulator_bits")) << e;  // lists the known keys
  e = error_of("accumulator_bits: abc");
  EXPECT_TRUE(contains(e, "numerics.accumulator_bits") && contains(e, "abc")) << e;
  e = error_of("accumulator_bits: 20.5");
  EXPECT_TRUE(contains(e, "numerics.accumulator_bits")) << e;
  e = error_of("feature_bits: 0");
  EXPECT_TRUE(contains(e, "numerics.feature_bits") && contains(e, "out of range")) << e;
  e = error_of("accumulator_bits: 12");
  EXPECT_TRUE(contains(e, "numerics.accumulator_bits") && contains(e, "15")) << e;
  e = error_of("interp_feature_bits: 10");
  EXPECT_TRUE(contains(e, "interp_feature_bits")) << e;
  e = error_of("mlp_output_frac_bits: 15");
  EXPECT_TRUE(contains(e, "mlp_output_frac_bits")) << e;
  e = error_of("direction_code_frac_bits: 15");
  EXPECT_TRUE(contains(e, "direction_code_frac_bits")) << e;
  e = error_of("rounding: nearest");
  EXPECT_TRUE(contains(e, "numerics.rounding") && contains(e, "nearest")) << e;
  e = error_of("ray_float: {exponent_bits: 9}");
  EXPECT_TRUE(contains(e, "numerics.ray_float") && contains(e, "exponent_bits")) << e;
  e = error_of("traversal_float: {significand_bits: 26}");
  EXPECT_TRUE(contains(e, "numerics.traversal_float") && contains(e, "significand_bits")) << e;
  e = error_of("ray_float: {specials: maybe}");
  EXPECT_TRUE(contains(e, "numerics.ray_float.specials") && contains(e, "maybe")) << e;
  e = error_of("ray_float: {mantissa_bits: 10}");
  EXPECT_TRUE(contains(e, "unknown key 'mantissa_bits'")) << e;
  e = error_of("ray_float: 24");
  EXPECT_TRUE(contains(e, "numerics.ray_float")) << e;
  e = error_of("[1, 2]");
  EXPECT_TRUE(contains(e, "numerics")) << e;
  try {
    numerics_from_yaml(YAML::Load("weight_bits: 99"), "chip.yaml: numerics");
    ADD_FAILURE() << "no error";
  } catch (const Error& err) {
    EXPECT_TRUE(contains(err.what(), "chip.yaml: numerics.weight_bits")) << err.what();
  }
}

TEST(ChipNumerics, TableListsEveryWidth) {
  const std::string t = numerics_table(ChipNumerics{});
  for (const char* key :
       {"feature_bits", "weight_bits", "accumulator_bits", "interp_feature_bits", "transmittance_bits",
        "direction_code_bits", "rounding", "half_up", "ray_float", "traversal_float", "e8p16"}) {
    EXPECT_TRUE(contains(t, key)) << key << "\n" << t;
  }
}

}  // namespace
}  // namespace edrnr
