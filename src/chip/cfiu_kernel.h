#pragma once
// The CFIU's corner sums through Highway with runtime dispatch (the best SIMD
// target the CPU has).
#include <cstddef>
#include <cstdint>

namespace edrnr::chip {

// For each of 8 corners c, codes start at byte q4 + byte_first[c]: INT4 codes
// two a byte, the even channel in the low nibble. For each byte b < bytes:
//   even[b] = sum_c coef[c] * (q4[byte_first[c] + b] & 15)   (channel 2b)
//   odd[b]  = sum_c coef[c] * (q4[byte_first[c] + b] >> 4)   (channel 2b + 1)
// in int32. Exact when 15 * sum_c |coef[c]| < 2^31 (the caller's contract).
void cfiu_corner_sums(const uint8_t* q4, const size_t* byte_first, const int32_t* coef, size_t bytes, int32_t* even,
                      int32_t* odd);

// cfiu_corner_sums over at most 32 bytes, each sum then finished as the
// CFIU's floor or half-up requantization does, in int32:
//   out[2b]     = clamp((even[b] - zero_even[b] + half) >> shift, lo, hi)
//   out[2b + 1] = clamp((odd[b] - zero_odd[b] + half) >> shift, lo, hi)
// (an arithmetic shift: the floor). The caller ensures that nothing leaves
// int32 (|sum - zero| + half < 2^31) and 0 <= shift < 32.
void cfiu_corner_features(const uint8_t* q4, const size_t* byte_first, const int32_t* coef, size_t bytes,
                          const int32_t* zero_even, const int32_t* zero_odd, int32_t half, int shift, int32_t lo,
                          int32_t hi, int32_t* out);

}  // namespace edrnr::chip
