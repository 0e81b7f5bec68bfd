#pragma once
// ZORG's direction datapath for the four rays of a packet in SIMD lanes
// (Highway, runtime dispatch): the same correctly rounded operations as
// RayGenerator::generate(x, y), each lane's custom-float rounding done on
// the bit pattern.
#include <cstdint>

namespace edrnr::chip {

// What a lane needs of a FloatFormat to round a value of its normal range:
// binary64 fraction bits dropped (53 - p), the least normal magnitude and
// the least magnitude that rounds past the largest finite value.
struct LaneRounding {
  int drop_bits = 0;
  double min_normal = 0;
  double overflow_threshold = 0;
};

// For lanes l < 4, with every value of the ray format (rf) and the products
// for the traversal format (tf):
//   w[a]      = rf((rf(col[a][l] + row[a][l])) + z[a])
//   len       = rf(sqrt(rf(rf(rf(w0 w0) + rf(w1 w1)) + rf(w2 w2))))
//   world[a]  = rf(w[a] / len)
//   dir[a][l] = tf(rf(world[a] dir_scale[a]))
// (arrays [axis][lane]). Returns false, leaving the outputs unspecified,
// when some rounded value of some lane is not in its format's normal range
// (a zero, a subnormal, an overflow): the caller computes that packet one
// ray at a time.
bool zorg_directions(const double* col, const double* row, const double* z, const double* dir_scale,
                     const LaneRounding& rf, const LaneRounding& tf, double* world, double* dir);

}  // namespace edrnr::chip
