// The 64-bit paths of multiply_shift and the compile-time-rounding
// requantize<M> against exact 128-bit division.
#include <gtest/gtest.h>

#include <limits>
#include <random>

#include "core/fixed_point.h"

namespace edrnr::fx {
namespace {

// x / 2^s rounded with `mode`, by floor division of 128-bit integers.
int64_t ref_shift_round(__int128 x, int s, Rounding mode) {
  const __int128 d = __int128(1) << s;
  __int128 q = x / d, r = x - q * d;
  if (r < 0) {
    q -= 1;
    r += d;
  }
  if (mode == Rounding::HalfUp && 2 * r >= d) q += 1;
  if (mode == Rounding::HalfEven && (2 * r > d || (2 * r == d && q % 2 != 0))) q += 1;
  // Saturated to int64_t, as multiply_shift does.
  if (q > std::numeric_limits<int64_t>::max()) return std::numeric_limits<int64_t>::max();
  if (q < std::numeric_limits<int64_t>::min()) return std::numeric_limits<int64_t>::min();
  return int64_t(q);
}

template <Rounding M>
void check_requantize(uint64_t seed) {
  std::mt19937_64 rng(seed);
  for (int i = 0; i < 50000; ++i) {
    // Mostly operands of 32 bits or less (the 64-bit path), some wider.
    const int xb = int(rng() % 40), mb = int(rng() % 36);
    const int64_t x = int64_t(rng() >> (64 - xb - 1)) * ((rng() & 1) ? -1 : 1);
    const Requant q{int64_t(rng() >> (64 - mb - 1)), int(rng() % 64)};
    const int64_t expect = ref_shift_round(__int128(x) * q.multiplier, q.shift, M);
    ASSERT_EQ(requantize<M>(x, q), expect) << x << " * " << q.multiplier << " >> " << q.shift;
    ASSERT_EQ(requantize(x, q, M), expect);
  }
}

TEST(FixedPointNarrow, RequantizeWithFixedRoundingMatchesDivision) {
  check_requantize<Rounding::Floor>(1);
  check_requantize<Rounding::HalfUp>(2);
  check_requantize<Rounding::HalfEven>(3);
}

TEST(FixedPointNarrow, EdgesOfThe64BitPath) {
  constexpr int64_t kI32Min = std::numeric_limits<int32_t>::min(), kI32Max = std::numeric_limits<int32_t>::max();
  // The largest products the 64-bit path takes, at the largest shifts.
  EXPECT_EQ(multiply_shift(kI32Min, kI32Min, 62, Rounding::HalfUp), 1);    // 2^62 / 2^62
  EXPECT_EQ(multiply_shift(kI32Min, kI32Max, 62, Rounding::HalfUp), -1);   // -(1 - 2^-31) -> -1
  EXPECT_EQ(multiply_shift(kI32Min, kI32Max, 61, Rounding::Floor), -2);    // -(2 - 2^-30) -> -2
  EXPECT_EQ(multiply_shift(kI32Min, kI32Min, 63, Rounding::HalfEven), 0);  // 0.5 -> 0
  EXPECT_EQ(multiply_shift(kI32Min, kI32Min, 63, Rounding::HalfUp), 1);    // 0.5 -> 1
  EXPECT_EQ(multiply_shift(-kI32Max, kI32Max, 64, Rounding::Floor), -1);
  EXPECT_EQ(multiply_shift(-kI32Max, kI32Max, 64, Rounding::HalfUp), 0);
  EXPECT_EQ(multiply_shift(-5, 3, -2, Rounding::HalfUp), -15);  // a negative shift is clamped to 0
  // Ties: -2.5 and 2.5 in each mode.
  const Requant half{1, 1};
  EXPECT_EQ(requantize<Rounding::HalfUp>(-5, half), -2);
  EXPECT_EQ(requantize<Rounding::HalfUp>(5, half), 3);
  EXPECT_EQ(requantize<Rounding::HalfEven>(-5, half), -2);
  EXPECT_EQ(requantize<Rounding::HalfEven>(7, half), 4);
  EXPECT_EQ(requantize<Rounding::Floor>(-5, half), -3);
  // A multiplier past 32 bits takes the 128-bit path and saturates.
  EXPECT_EQ(requantize<Rounding::HalfUp>(std::numeric_limits<int64_t>::max(), Requant{int64_t(1) << 40, 0}),
            std::numeric_limits<int64_t>::max());
}

}  // namespace
}  // namespace edrnr::fx
