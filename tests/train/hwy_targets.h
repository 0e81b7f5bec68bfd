#pragma once
// Runs a test body once on every SIMD target this build has and the CPU runs
// (for kernels whose results must be the same bits on all of them).
#include <hwy/targets.h>

namespace edrnr::train {

// Calls body(target name) with dispatch pinned to each target in turn.
template <class Body>
void on_every_target(Body body) {
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    body(hwy::TargetName(target));
  }
  hwy::SetSupportedTargetsForTest(0);
}

}  // namespace edrnr::train
