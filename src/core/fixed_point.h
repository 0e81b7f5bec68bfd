#pragma once
// Integer and fixed-point arithmetic as the chip's datapaths do it, emulated
// exactly on int64_t storage (intermediates in __int128 where a product needs
// it). Every function is defined for every input: widths and shifts outside
// their range are clamped as documented, overflow saturates or wraps as named,
// and nothing relies on undefined behaviour (C++20 fixes two's complement and
// arithmetic right shift of negative values).
//
// Conventions: `bits` is the total width of the integer. A signed N-bit value
// lies in [-2^(N-1), 2^(N-1)-1] (N in 1..64); an unsigned N-bit value in
// [0, 2^N-1] (N in 0..63). A fixed-point number with F fraction bits stores
// the integer q and stands for q * 2^-F.
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace edrnr::fx {

// How a value between two integers is rounded.
//   Floor:    toward -infinity (a plain arithmetic shift; truncation).
//   HalfUp:   to nearest, ties toward +infinity: add 2^(s-1), then shift. The
//             cheap hardware rounding. -2.5 -> -2, 2.5 -> 3.
//   HalfEven: to nearest, ties to the even integer. -2.5 -> -2, -3.5 -> -4.
enum class Rounding { Floor, HalfUp, HalfEven };

// Range limits of N-bit integers (N clamped to the valid range).
constexpr int64_t max_signed(int bits) {
  if (bits <= 1) return 0;
  if (bits >= 64) return std::numeric_limits<int64_t>::max();
  return (int64_t(1) << (bits - 1)) - 1;
}
constexpr int64_t min_signed(int bits) {
  if (bits <= 1) return -1;
  if (bits >= 64) return std::numeric_limits<int64_t>::min();
  return -(int64_t(1) << (bits - 1));
}
constexpr int64_t max_unsigned(int bits) {
  if (bits <= 0) return 0;
  if (bits >= 63) return std::numeric_limits<int64_t>::max();
  return (int64_t(1) << bits) - 1;
}

// Clamps x into the signed / unsigned N-bit range.
constexpr int64_t saturate(int64_t x, int bits) {
  const int64_t lo = min_signed(bits), hi = max_signed(bits);
  return x < lo ? lo : (x > hi ? hi : x);
}
constexpr int64_t saturate_unsigned(int64_t x, int bits) {
  const int64_t hi = max_unsigned(bits);
  return x < 0 ? 0 : (x > hi ? hi : x);
}
constexpr bool fits(int64_t x, int bits) { return x >= min_signed(bits) && x <= max_signed(bits); }
constexpr bool fits_unsigned(int64_t x, int bits) { return x >= 0 && x <= max_unsigned(bits); }

// Keeps the low N bits of x (two's complement overflow): the signed version
// sign-extends bit N-1, the unsigned one zero-extends.
constexpr int64_t wrap(int64_t x, int bits) {
  if (bits >= 64) return x;
  const int n = bits < 1 ? 1 : bits;
  const uint64_t u = uint64_t(x) << (64 - n);
  return int64_t(u) >> (64 - n);
}
constexpr int64_t wrap_unsigned(int64_t x, int bits) {
  if (bits <= 0) return 0;
  if (bits >= 63) return int64_t(uint64_t(x) & (~uint64_t(0) >> 1));
  return int64_t(uint64_t(x) & ((uint64_t(1) << bits) - 1));
}

namespace detail {
// round(x / 2^s) for 0 <= s < width of I (I is int64_t or __int128).
template <class I, class U>
constexpr I shift_right_round(I x, int s, Rounding mode) {
  if (s == 0) return x;
  const I floor_q = x >> s;
  const U rem = U(x) & ((U(1) << s) - 1);
  const U half = U(1) << (s - 1);
  switch (mode) {
    case Rounding::Floor:
      return floor_q;
    case Rounding::HalfUp:
      return floor_q + (rem >= half ? 1 : 0);
    case Rounding::HalfEven:
      return floor_q + ((rem > half || (rem == half && (floor_q & 1) != 0)) ? 1 : 0);
  }
  return floor_q;
}
}  // namespace detail

// round(x / 2^shift) with the given rounding. shift > 63 behaves as the exact
// quotient does (0, or -1 for Floor of a negative x). A negative shift
// multiplies by 2^-shift, saturating to the int64_t range.
constexpr int64_t shift_right_round(int64_t x, int shift, Rounding mode) {
  if (shift < 0) {
    if (x == 0) return 0;
    const int up = -shift;
    if (up >= 63) return x < 0 ? std::numeric_limits<int64_t>::min() : std::numeric_limits<int64_t>::max();
    const int64_t limit = std::numeric_limits<int64_t>::max() >> up;
    if (x > limit) return std::numeric_limits<int64_t>::max();
    if (x < -limit - 1) return std::numeric_limits<int64_t>::min();
    return int64_t(uint64_t(x) << up);
  }
  if (shift >= 64) {
    // |x| / 2^shift <= 1/2, with equality only for x = -2^63, shift = 64,
    // which both nearest modes round to 0.
    return (mode == Rounding::Floor && x < 0) ? -1 : 0;
  }
  return detail::shift_right_round<int64_t, uint64_t>(x, shift, mode);
}

// round(a * b / 2^shift), the product formed exactly in 128 bits, the result
// saturated to int64_t. shift is clamped to [0, 127].
constexpr int64_t multiply_shift(int64_t a, int64_t b, int shift, Rounding mode) {
  if (a == int32_t(a) && b == int32_t(b)) {
    // |a * b| <= 2^62: the product is exact in 64 bits, and so is its
    // rounding (shifts past 63 give what the exact quotient rounds to).
    return shift_right_round(a * b, shift < 0 ? 0 : shift, mode);
  }
  using I = __int128;
  using U = unsigned __int128;
  const I p = I(a) * I(b);
  const int s = shift < 0 ? 0 : (shift > 127 ? 127 : shift);
  const I q = detail::shift_right_round<I, U>(p, s, mode);
  if (q > I(std::numeric_limits<int64_t>::max())) return std::numeric_limits<int64_t>::max();
  if (q < I(std::numeric_limits<int64_t>::min())) return std::numeric_limits<int64_t>::min();
  return int64_t(q);
}

// A real scale factor as integer-only inference stores it: the scale is
// multiplier * 2^-shift, with 0 <= multiplier < 2^multiplier_bits and
// 0 <= shift <= 63 (a 6-bit shift field).
struct Requant {
  int64_t multiplier = 1;
  int shift = 0;
  constexpr double scale() const { return double(multiplier) / double(uint64_t(1) << shift); }
  constexpr bool operator==(const Requant& o) const = default;
};

// round(x * multiplier / 2^shift): x times the scale, rounded once (exact
// 128-bit product), saturated to int64_t.
constexpr int64_t requantize(int64_t x, Requant q, Rounding mode) {
  return multiply_shift(x, q.multiplier, q.shift, mode);
}
// The same with the rounding fixed at compile time, for inner loops: with
// |x| and the multiplier below 2^31 (an accumulator of at most 32 bits, a
// multiplier of at most 31) the product and its rounding stay in 64 bits.
template <Rounding M>
constexpr bool requantize_fits_64(Requant q) {
  return M != Rounding::HalfEven && q.multiplier == int32_t(q.multiplier) && q.shift >= 0 && q.shift <= 62;
}
// requantize<M>'s 64-bit path: x fits 32 bits and requantize_fits_64<M>(q).
template <Rounding M>
constexpr int64_t requantize_64(int64_t x, Requant q) {
  const int64_t p = x * q.multiplier;  // |p| <= 2^62
  if constexpr (M == Rounding::Floor) return p >> q.shift;
  // floor((p + 2^(s-1)) / 2^s): ties up; no overflow with |p| <= 2^62.
  return (p + ((int64_t(1) << q.shift) >> 1)) >> q.shift;
}
template <Rounding M>
constexpr int64_t requantize(int64_t x, Requant q) {
  if constexpr (M != Rounding::HalfEven)
    if (x == int32_t(x) && requantize_fits_64<M>(q)) return requantize_64<M>(x, q);
  return multiply_shift(x, q.multiplier, q.shift, M);
}

// out[j] = saturate(requantize<M>(x[j], q), bits) for j < n; returns how
// many values the saturation changed. The inputs fit 32 bits, so the 64-bit
// path's conditions are the multiplier's, checked once per row.
template <Rounding M>
uint64_t requantize_saturate_row(const int32_t* x, size_t n, Requant q, int bits, int32_t* out) {
  const int64_t lo = min_signed(bits), hi = max_signed(bits);
  const bool fits_64 = requantize_fits_64<M>(q);
  uint64_t saturations = 0;
  for (size_t j = 0; j < n; ++j) {
    const int64_t r = fits_64 ? requantize_64<M>(x[j], q) : requantize<M>(x[j], q);
    const int64_t v = r < lo ? lo : (r > hi ? hi : r);
    saturations += v != r;
    out[j] = int32_t(v);
  }
  return saturations;
}

// out[j] = requantize<M>(saturate(x[j], bits), q) for j < n; returns how
// many x[j] the saturation changed. The saturated values fit 32 bits, so
// the 64-bit path's conditions are the multiplier's, checked once per row.
template <Rounding M>
uint64_t saturate_requantize_row(const int32_t* x, size_t n, int bits, Requant q, int64_t* out) {
  const int64_t lo = min_signed(bits), hi = max_signed(bits);
  uint64_t saturations = 0;
  if (requantize_fits_64<M>(q)) {
    for (size_t j = 0; j < n; ++j) {
      const int64_t v = x[j], s = v < lo ? lo : (v > hi ? hi : v);
      saturations += s != v;
      out[j] = requantize_64<M>(s, q);
    }
    return saturations;
  }
  for (size_t j = 0; j < n; ++j) {
    const int64_t v = x[j], s = saturate(v, bits);
    saturations += s != v;
    out[j] = requantize<M>(s, q);
  }
  return saturations;
}

// The (multiplier, shift) pair for a real scale > 0, with multiplier_bits in
// 1..62. The multiplier is round-half-even(scale * 2^shift) for the largest
// shift <= 63 that keeps it below 2^multiplier_bits, so normally
// 2^(multiplier_bits-1) <= multiplier < 2^multiplier_bits and
//   |multiplier * 2^-shift - scale| <= 2^-(shift+1) <= scale * 2^-multiplier_bits.
// Exactness: the pair equals the scale exactly iff the scale is a dyadic
// rational with at most multiplier_bits significant bits and an exponent the
// shift range reaches (e.g. 0.75 with any multiplier_bits >= 2). Then
// requantize(x) is exactly round(x * scale); otherwise requantize(x) is the
// correctly rounded value of x * (the pair's scale), which differs from
// round(x * scale) by at most 1 while |x * scale| <= 2^(multiplier_bits-1).
// Scales below 2^-63 lose significant bits (multiplier may be 0).
// Throws edrnr::Error if the scale is not finite and > 0, if
// scale >= 2^multiplier_bits or rounds up to it (a right shift cannot
// express it), or if
// multiplier_bits is out of range.
Requant requant_from_scale(double scale, int multiplier_bits);

// 2^e as a double, exactly, for -1022 <= e <= 1023 (a normal double).
constexpr double pow2(int e) { return std::bit_cast<double>(uint64_t(1023 + e) << 52); }
// |v| <= 1 scaled by 2^frac_bits stays below 2^52 (round_scaled_small) up to this.
inline constexpr int kSmallScaleFracBitsMax = 51;

namespace detail {
// round(v * 2^frac_bits) as an int64_t (saturated), before the N-bit clamp.
inline int64_t round_scaled(double v, int frac_bits, Rounding mode) {
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  constexpr double kTwo63 = 9223372036854775808.0;
  if (v != v) return 0;
  if (frac_bits > 1000) frac_bits = 1000;
  if (frac_bits < -1000) frac_bits = -1000;
  // v * 2^frac_bits, as std::ldexp gives it (both are the correctly rounded
  // product; 2^frac_bits is a normal double for |frac_bits| <= 1000).
  const double s = v * pow2(frac_bits);
  if (s == 0.0) {
    // A negative v whose scaled value underflowed lies in (-1, 0).
    return (v < 0.0 && mode == Rounding::Floor) ? -1 : 0;
  }
  if (s >= kTwo63) return kMax;
  if (s <= -kTwo63) return kMin;  // floor(s) <= -2^63
  // floor(s) without a library call: truncation toward zero (exact in this
  // range), one less for a negative s with a fraction. The integer converts
  // back exactly (below 2^53 in magnitude, or s was already an integer).
  int64_t q = int64_t(s);
  if (double(q) > s) --q;
  const double frac = s - double(q);  // exact: the fraction bits of s, in [0, 1)
  bool up = false;
  switch (mode) {
    case Rounding::Floor:
      break;
    case Rounding::HalfUp:
      up = frac >= 0.5;
      break;
    case Rounding::HalfEven:
      up = frac > 0.5 || (frac == 0.5 && (q & 1) != 0);
      break;
  }
  return q + (up ? 1 : 0);  // q < 2^63 - 1 whenever frac > 0
}
}  // namespace detail

// The fixed-point value round(v * 2^frac_bits) saturated to a signed /
// unsigned N-bit integer. The scaling by 2^frac_bits is exact, so the value
// is rounded once. NaN gives 0; +-infinity saturates. frac_bits is clamped to
// [-1000, 1000].
inline int64_t to_fixed(double v, int frac_bits, int bits, Rounding mode) {
  return saturate(detail::round_scaled(v, frac_bits, mode), bits);
}
inline int64_t to_fixed_unsigned(double v, int frac_bits, int bits, Rounding mode) {
  return saturate_unsigned(detail::round_scaled(v, frac_bits, mode), bits);
}

// round(v * scale) with the rounding fixed at compile time, for inner loops:
// scale = 2^frac_bits and |v * scale| < 2^52, so the product is exact and
// round_scaled's range checks are not needed (the same result).
template <Rounding M>
inline int64_t round_scaled_small(double v, double scale) {
  const double s = v * scale;
  int64_t q = int64_t(s);  // truncation toward zero
  if (double(q) > s) --q;  // the floor
  const double frac = s - double(q);
  if constexpr (M == Rounding::HalfUp) return q + (frac >= 0.5 ? 1 : 0);
  if constexpr (M == Rounding::HalfEven) return q + ((frac > 0.5 || (frac == 0.5 && (q & 1) != 0)) ? 1 : 0);
  return q;
}

// The value q * 2^-frac_bits. Exact when |q| < 2^53 (otherwise the nearest
// double, ties to even).
// Scaling by 2^-frac_bits, a normal double for |frac_bits| <= 960, is exact
// unless the product leaves the normal range, which it cannot for such
// frac_bits and |q| < 2^63 (std::ldexp, a library call, for the rest).
inline double from_fixed(int64_t q, int frac_bits) {
  if (frac_bits < -960 || frac_bits > 960) return std::ldexp(double(q), -frac_bits);
  return double(q) * pow2(-frac_bits);
}

}  // namespace edrnr::fx
