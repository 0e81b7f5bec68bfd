#pragma once
// Reproducible random test inputs for the trainer's kernel tests.
#include <cstdint>

#include "train/rng.h"

namespace edrnr::train {

// A value in [lo, hi) fixed by (seed, i).
inline float rnd(uint64_t seed, uint64_t i, float lo, float hi) {
  return lo + (hi - lo) * uniform01(hash3(seed, 99, i));
}

}  // namespace edrnr::train
