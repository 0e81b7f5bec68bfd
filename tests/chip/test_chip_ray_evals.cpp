// The TSPS's box run and its position-evaluation count against a plain
// bisection on each bound over [0, kMaxCandidate), as the hardware searches.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "chip/chip_ray.h"
#include "chip/numerics.h"

namespace edrnr::chip {
namespace {

// Smallest k in [lo, hi) with pred(k), or hi; counts the evaluations.
template <class Pred>
int64_t bisect(int64_t lo, int64_t hi, uint64_t& evals, Pred pred) {
  while (lo < hi) {
    const int64_t mid = lo + (hi - lo) / 2;
    ++evals;
    if (pred(mid))
      hi = mid;
    else
      lo = mid + 1;
  }
  return lo;
}

// first_true_steps against the evaluations a bisection makes, for every
// answer on every range of up to 1100 candidates, and at both ends and
// random places of long ranges (offsets from lo, which must not matter).
TEST(RayMathEvals, BisectionStepCountsMatchTheBisection) {
  auto counted = [](int64_t lo, int64_t hi, int64_t e) {
    uint64_t evals = 0;
    const int64_t found = bisect(lo, hi, evals, [e](int64_t k) { return k >= e; });
    EXPECT_EQ(found, std::clamp(e, lo, hi));
    return evals;
  };
  for (int64_t n = 0; n <= 1100; ++n)
    for (int64_t j = 0; j <= n; ++j) {
      const int64_t lo = 37;
      ASSERT_EQ(first_true_steps(lo, lo + n, lo + j), counted(lo, lo + n, lo + j)) << "n " << n << " j " << j;
    }
  std::mt19937_64 rng(5);
  for (int i = 0; i < 20000; ++i) {
    const int64_t lo = int64_t(rng() % 1000), n = 1 + int64_t(rng() % (uint64_t(1) << 22));
    const int64_t pick = int64_t(rng() % 4);
    const int64_t e = pick == 0 ? lo : pick == 1 ? lo + n : pick == 2 ? lo + 1 : lo + int64_t(rng() % uint64_t(n + 1));
    ASSERT_EQ(first_true_steps(lo, lo + n, e), counted(lo, lo + n, e)) << "n " << n << " e - lo " << e - lo;
  }
  // Answers outside the range walk as its ends do.
  EXPECT_EQ(first_true_steps(10, 20, 3), counted(10, 20, 10));
  EXPECT_EQ(first_true_steps(10, 20, 99), counted(10, 20, 20));
  EXPECT_EQ(first_true_steps(10, 10, 10), 0u);
}

KInterval bisected_box(const RayMath& m, const ChipRay& r, const Vec3d& lo, const Vec3d& hi, uint64_t& evals) {
  KInterval out{0, kMaxCandidate};
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) {
      if (!(r.origin[a] >= lo[a] && r.origin[a] <= hi[a])) return {0, 0};
      continue;
    }
    int64_t enter, leave;
    if (d > 0) {
      enter = bisect(0, kMaxCandidate, evals, [&](int64_t k) { return m.coord(r, k, a) >= lo[a]; });
      leave = bisect(enter, kMaxCandidate, evals, [&](int64_t k) { return m.coord(r, k, a) > hi[a]; });
    } else {
      enter = bisect(0, kMaxCandidate, evals, [&](int64_t k) { return m.coord(r, k, a) <= hi[a]; });
      leave = bisect(enter, kMaxCandidate, evals, [&](int64_t k) { return m.coord(r, k, a) < lo[a]; });
    }
    out.begin = std::max(out.begin, enter);
    out.end = std::min(out.end, leave);
  }
  return out.empty() ? KInterval{0, 0} : out;
}

TEST(RayMathEvals, BoxRunAndItsCountMatchTheBisection) {
  const FloatFormat f = ChipNumerics{}.traversal_float;
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int nonempty = 0;
  for (double step : {0.5, 1.0, 3.0}) {
    for (int res : {64, 256}) {
      const RayMath m(f, step, res);
      for (int i = 0; i < 300; ++i) {
        // From outside the grid towards it, some rays in an axis plane or
        // along an axis, some starting inside, some missing the box.
        Vec3d o{u(rng), u(rng), u(rng)};
        o = o * ((i % 5 == 0 ? 0.3 : 1.7) * res / length(o)) + Vec3d{res / 2.0, res / 2.0, res / 2.0};
        Vec3d d = normalize(Vec3d{res / 2.0 + u(rng) * res, res / 2.0 + u(rng) * res, res / 2.0 + u(rng) * res} - o);
        if (i % 7 == 0) d.y = 0;
        if (i % 11 == 0) d = {0, 0, d.z < 0 ? -1.0 : 1.0};
        const ChipRay r{f.round(o), f.round(normalize(d))};
        const Vec3d lo{0, 0, 0}, hi{double(res), double(res), double(res)};
        uint64_t evals = 0, expect_evals = 0;
        const KInterval got = m.box_interval(r, lo, hi, &evals);
        const KInterval expect = bisected_box(m, r, lo, hi, expect_evals);
        ASSERT_EQ(got.begin, expect.begin) << i;
        ASSERT_EQ(got.end, expect.end) << i;
        ASSERT_EQ(evals, expect_evals) << i;
        nonempty += !got.empty();
      }
    }
  }
  EXPECT_GT(nonempty, 600);  // most rays reach the grid
}

}  // namespace
}  // namespace edrnr::chip
