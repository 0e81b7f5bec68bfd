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

}  // namespace edrnr::chip
