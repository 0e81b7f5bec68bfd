#pragma once
// Counter-based random numbers: every draw is a pure function of (seed, step,
// index), so results do not depend on thread count or scheduling and a
// resumed run draws exactly what an uninterrupted one would.
#include <cstdint>

namespace edrnr::train {

// SplitMix64 finalizer: a bijective 64-bit mix.
inline uint64_t mix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

inline uint64_t hash_combine(uint64_t a, uint64_t b) { return mix64(a ^ mix64(b)); }
inline uint64_t hash3(uint64_t a, uint64_t b, uint64_t c) { return hash_combine(hash_combine(a, b), c); }

// Uniform float in [0, 1) from the top 24 bits of h.
inline float uniform01(uint64_t h) { return float(h >> 40) * (1.0f / 16777216.0f); }

// Streams named by a purpose tag, so draws for different purposes never collide.
enum class RngStream : uint64_t { MlpInit = 1, GridInit = 2, Rays = 3, Occupancy = 4 };

}  // namespace edrnr::train
