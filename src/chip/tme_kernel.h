#pragma once
// The TME's multiply-accumulate array as a small integer GEMM, through
// Highway with runtime dispatch (the best SIMD target the CPU has).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace edrnr::chip {

// Output rows of a transposed weight matrix are padded to a multiple of
// tme_lane_pad(): the int32 lanes of the SIMD target the dispatch picks, at
// most this (the lanes of the widest int32 vector). Padding to the target's
// own width spares the narrower targets columns of zeros (an 8-output layer
// is one AVX2 vector, not two).
inline constexpr size_t kTmeLanePad = 16;
size_t tme_lane_pad();

// For each of `samples` input rows x_s = x + s * x_stride and each output j <
// out_pad:
//   y[s * y_stride + j] = sum_{i in [i_begin, i_end)} wt[i * out_pad + j] * x_s[i]
// in int32 arithmetic. wt is the weight matrix transposed (input-major, out_pad
// a multiple of tme_lane_pad(), padding zero). Exact when every partial sum fits
// int32 (the caller's contract: |w| <= 2^7, |x| <= 2^15 and at most 2^8 inputs
// give |sum| <= 2^30).
void tme_dot_columns(const int32_t* wt, size_t out_pad, size_t i_begin, size_t i_end, const int32_t* x, size_t x_stride,
                     size_t samples, int32_t* y, size_t y_stride);

// At most this many input pairs (512 inputs) in tme_dot_columns_pairs.
inline constexpr size_t kTmeMaxPairs = 256;

// tme_dot_columns with i_begin = 0, the products formed two at a time from
// 16-bit halves: wt_pairs holds pair p = inputs (2p, 2p + 1) of output j at
// [2 (p out_pad + j)] and [2 (p out_pad + j) + 1] (tme_pair_weights), wt the
// same weights as tme_dot_columns takes (for an odd i_end's last input).
// The same int32 results as tme_dot_columns whenever every x fits int16 and
// every weight int8 (a pair's two products then sum to under 2^23, and the
// lanes add in int32 as tme_dot_columns does).
// The pair layout of tme_dot_columns_pairs for wt (in x out_pad, transposed,
// int8 values; throws otherwise): in / 2 pairs, an odd last input left out.
std::vector<int16_t> tme_pair_weights(const int32_t* wt, size_t in, size_t out_pad);
void tme_dot_columns_pairs(const int16_t* wt_pairs, const int32_t* wt, size_t out_pad, size_t i_end, const int32_t* x,
                           size_t x_stride, size_t samples, int32_t* y, size_t y_stride);

// The requantization of a hidden layer whose sums are exact: for each of
// `samples` rows and each j < out_pad,
//   v = max(sum[s * sum_stride + j] + bias[j], 0)   (int32, no overflow: the
//       caller's contract)
//   r = (v * mult[j] + half[j]) >> shift[j]          (exact in 64 bits:
//       mult < 2^31, shift <= 62, half < 2^shift)
//   y[s * y_stride + j] = min(r, 2^(out_bits - 1) - 1)
// Returns how many values were clamped. out_bits in [1, 32].
uint64_t tme_requant_relu(const int32_t* sum, size_t sum_stride, size_t samples, const int32_t* bias,
                          const uint32_t* mult, const uint64_t* half, const uint64_t* shift, size_t out_pad,
                          int out_bits, int32_t* y, size_t y_stride);

// The signed requantization of `count` values per row (any count; the last
// partial vector lane by lane): for each of `samples` rows and each j < count,
//   v = x[s * x_stride + j] + bias[j]                (int64; the caller's
//       contract: v fits int32)
//   r = floor((v * mult[j] + half[j]) / 2^shift[j])  (exact in 64 bits:
//       mult < 2^31, shift <= 62, half <= 2^61)
//   y[s * y_stride + j] = r saturated to a signed out_bits integer
// Returns how many values were clamped. out_bits in [1, 32]. With half[j] =
// 2^shift[j] / 2 (or 0) this is fx::requantize<HalfUp> (or <Floor>).
uint64_t tme_requant_signed(const int32_t* x, size_t x_stride, size_t samples, size_t count, const int32_t* bias,
                            const uint32_t* mult, const uint64_t* half, const uint64_t* shift, int out_bits, int32_t* y,
                            size_t y_stride);

// A layer's sums completed by per-sample terms: for each of `samples` rows
// and each j < count,
//   v = base[j] + sum[s * sum_stride + j] + terms[s][j]   (int64; the
//       caller's contract: no overflow)
//   sum[s * sum_stride + j] = clamp(v, -2^(acc_bits - 1), 2^(acc_bits - 1) - 1)
// Returns how many values were clamped. acc_bits in [2, 32].
uint64_t tme_add_terms(int32_t* sum, size_t sum_stride, size_t samples, size_t count, const int64_t* base,
                       const int64_t* const* terms, int acc_bits);

// The SIMD target the dispatch picked (for benchmarks and reports).
const char* tme_kernel_target();

}  // namespace edrnr::chip
