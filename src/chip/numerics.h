#pragma once
// The chip's number formats in one place: every integer width and every
// custom floating-point format the chip model uses. docs/numerics.md gives
// the reason for each default and the unit that uses it.
//
// Conventions:
//   - "bits" is the total width, sign bit included for signed values.
//   - A quantity in [0, 1] (interpolation fraction excepted) kept in N bits
//     is unsigned fixed point with N-1 fraction bits, so 1.0 is exactly
//     2^(N-1) (unit_one(N)).
//   - Every narrowing of an integer (requantization, shifts) rounds with
//     `rounding` and saturates to the destination width.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>
#include <string_view>

#include "core/custom_float.h"
#include "core/fixed_point.h"

namespace edrnr {

struct ChipNumerics {
  // MLP (TME) and features (CFIU).
  int feature_bits = 4;              // unsigned INT4 feature codes, per-channel zero point
  int weight_bits = 8;               // signed INT8 MLP weights
  int activation_bits = 8;           // signed INT8 MLP layer inputs
  int accumulator_bits = 20;         // signed INT20 MAC accumulator, saturating
  int requant_multiplier_bits = 16;  // unsigned requantization multiplier (fx::Requant), per output neuron
  int mlp_output_bits = 16;          // signed INT16 outputs of the last layers (raw density, raw colour)
  int mlp_output_frac_bits = 8;      // fraction bits of those outputs (step 1/256)

  // Interpolation (CFIU).
  int interp_fraction_bits = 8;      // unsigned per-axis position of a sample inside its micro voxel, in [0, 1)
  int interp_feature_bits = 16;      // signed INT16 interpolated feature, in feature-code steps
  int interp_feature_frac_bits = 8;  // fraction bits of the interpolated feature

  // View direction encoding (TME input): [d, sin(2^k d), cos(2^k d)], all in [-1, 1].
  int direction_code_bits = 16;       // signed INT16 direction code
  int direction_code_frac_bits = 14;  // Q1.14: 1.0 = 16384

  // Activations and volume rendering (TME LUTs, VRU).
  int lut_address_bits = 10;    // entries of each activation LUT: 2^lut_address_bits
  int alpha_bits = 16;          // unsigned [0, 1] opacity, Q1.15
  int color_bits = 16;          // unsigned [0, 1] colour and accumulated colour, Q1.15
  int transmittance_bits = 16;  // unsigned [0, 1] transmittance, Q1.15

  fx::Rounding rounding = fx::Rounding::HalfUp;  // every integer narrowing

  // Custom floating point (ZORG ray generation, ABT, TSPS; CTU/FTU traversal).
  FloatFormat ray_float{8, 16, false, FloatSpecials::Saturate};
  FloatFormat traversal_float{8, 16, false, FloatSpecials::Saturate};

  bool operator==(const ChipNumerics& o) const = default;
};

// 1.0 in the unsigned Q1.(bits-1) convention.
constexpr int64_t unit_one(int bits) { return int64_t(1) << (bits - 1); }

// Throws edrnr::Error naming the field when a width is out of range or the
// widths are inconsistent (e.g. an accumulator narrower than one product).
void validate(const ChipNumerics& n);

// Reads a YAML map. Missing keys keep their defaults; an unknown key, a value
// of the wrong type or an out-of-range width throws edrnr::Error naming
// `where` and the key. Float formats are maps with keys exponent_bits,
// significand_bits, subnormals (bool), specials (saturate | ieee); rounding is
// floor | half_up | half_even.
ChipNumerics numerics_from_yaml(const YAML::Node& node, std::string_view where = "numerics");

// The fully resolved settings as YAML (numerics_from_yaml reads it back).
YAML::Node numerics_to_yaml(const ChipNumerics& n);

// A table for people: one line per width with its use.
std::string numerics_table(const ChipNumerics& n);

const char* rounding_name(fx::Rounding r);
const char* specials_name(FloatSpecials s);

}  // namespace edrnr
