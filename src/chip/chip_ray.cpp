#include "chip/chip_ray.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "core/error.h"

namespace edrnr::chip {

namespace {
// Smallest k in [lo, hi) with pred(k) true, or hi if none; pred is monotone
// (false then true) on [lo, hi).
template <class Pred>
int64_t first_true(int64_t lo, int64_t hi, Pred pred) {
  while (lo < hi) {
    const int64_t mid = lo + (hi - lo) / 2;
    const bool p = pred(mid);
    hi = p ? mid : hi;  // conditional moves: the outcome is unpredictable
    lo = p ? lo : mid + 1;
  }
  return lo;
}

}  // namespace

// The bisection's path follows from e alone (pred(k) is k >= e on a
// monotone predicate), so it is replayed without evaluating. On n = hi - lo
// candidates, the answer's offset j = e - lo in [0, n], a step keeps the
// n / 2 (rounded down) below the midpoint when j <= n / 2, else the
// n - n / 2 - 1 above it. With n + 1 a power of two every path takes
// log2(n + 1) more steps; with n a power of two 2^b, every path takes b
// steps, one more for j <= 1 (by induction: j <= n / 2 halves n, j > n / 2
// leaves n / 2 - 1).
uint64_t first_true_steps(int64_t lo, int64_t hi, int64_t e) {
  if (lo >= hi) return 0;
  uint64_t n = uint64_t(hi - lo);
  uint64_t j = e <= lo ? 0 : std::min(uint64_t(e - lo), n);  // an answer outside [lo, hi] walks as its end does
  if ((n & (n - 1)) == 0) return uint64_t(std::countr_zero(n)) + (j <= 1 ? 1 : 0);  // a power of two (n > 0)
  uint64_t steps = 0;
  while ((n & (n + 1)) != 0) {  // n + 1 is not a power of two (n > 0 here)
    const uint64_t half = n >> 1;
    const bool above = j > half;
    n = above ? n - half - 1 : half;  // conditional moves: no branch on the path
    j = above ? j - half - 1 : j;
    ++steps;
  }
  return steps + uint64_t(std::bit_width(n));  // n = 2^b - 1: b more steps
}

namespace {

// A search's first guess ceil(y) as an integer, clamped to +-2^62 (far past
// any candidate range), or kNoGuess for a y that is not finite. Clamping it
// to a range [lo, hi - 1] gives what clamping ceil(y) as a double and
// converting it gives.
constexpr int64_t kNoGuess = std::numeric_limits<int64_t>::min();
int64_t guess_index(double y) {
  constexpr double kFar = 0x1p62;
  if (!(y > -kFar && y < kFar))
    return std::isnan(y) || std::isinf(y) ? kNoGuess : (y > 0 ? int64_t(kFar) : -int64_t(kFar));
  const int64_t t = int64_t(y);  // truncation toward zero
  return t + (double(t) < y ? 1 : 0);
}

// first_true(lo, hi, pred) found from a guess (guess_index; kNoGuess: start
// in the middle): a few steps from it, checked exactly (pred(e - 1) false
// unless e == lo, pred(e) true unless e == hi), and bisection on what remains
// if the guess is far off. The predicate must be monotone on [lo, hi).
template <class Pred>
int64_t first_true_from(int64_t lo, int64_t hi, int64_t guess, Pred pred) {
  if (lo >= hi) return lo;
  constexpr int kWalk = 4;
  const int64_t g = guess != kNoGuess ? std::clamp(guess, lo, hi - 1) : lo + (hi - lo) / 2;
  int64_t e = g;
  if (pred(g)) {
    for (int n = 0; e > lo && pred(e - 1); --e)
      if (++n == kWalk) return first_true(lo, e - 1, pred);  // pred(e - 1) is true
  } else {
    e = g + 1;
    for (int n = 0; e < hi && !pred(e); ++e)
      if (++n == kWalk) return first_true(e + 1, hi, pred);  // pred(e) is false
  }
  return e;
}
}  // namespace

RayMath::RayMath(const FloatFormat& fmt, double step_micro, int micro_res)
    : fmt_(fmt), step_(fmt.round(step_micro)), micro_res_(micro_res) {
  if (!(step_ > 0.0) || !std::isfinite(step_micro)) fail("sample step {} (micro voxels) must be positive", step_micro);
  if (micro_res < 1) fail("micro resolution {} must be positive", micro_res);
  // Cameras sit a few box sizes from the scene: t up to 16 box edges covers
  // the candidates of a frame; larger k are computed (same values). At most
  // 2^18 entries (2 MiB).
  const double reach = 16.0 * double(micro_res) / step_ + 2.0;
  const size_t entries = size_t(std::min(reach, double(int64_t(1) << 18)));
  t_table_.resize(entries);
  for (size_t k = 0; k < entries; ++k) t_table_[k] = t_exact(int64_t(k));
  make_thresholds();
}

void RayMath::make_thresholds() {
  // For f in [1, Rm): the midpoint between f and the format value below it
  // (a quarter step below f when f is a power of two: the spacing halves
  // there), checked against round() itself. Every real x below mid lies at
  // or below its double predecessor after the fused multiply-add's round to
  // odd (mid has at most p + 2 significant bits, so its last double bit is
  // even), likewise above, and round() is monotone: the three checks prove
  // the threshold for every sum.
  std::vector<Threshold> th(static_cast<size_t>(micro_res_));
  const double inf = std::numeric_limits<double>::infinity();
  for (int f = 1; f < micro_res_; ++f) {
    const double F = double(f);
    const int e = std::bit_width(unsigned(f)) - 1;  // f in [2^e, 2^(e+1))
    const double step = std::ldexp(1.0, e + 1 - fmt_.significand_bits());
    const double mid = std::has_single_bit(unsigned(f)) ? F - 0.25 * step : F - 0.5 * step;
    const bool below_ok = fmt_.round(std::nextafter(mid, -inf)) < F;
    const bool above_ok = fmt_.round(std::nextafter(mid, inf)) >= F;
    // micro_index_at relies on every threshold lying in [f - 1/2, f) (true
    // whenever every integer below Rm is a format value; checked anyway).
    const bool near_f = mid >= F - 0.5 && mid < F;
    if (!below_ok || !above_ok || !near_f || fmt_.round(F) != F) return;  // no fast tests for this format
    th[size_t(f)] = {mid, fmt_.round(mid) >= F};
  }
  thresholds_ = std::move(th);
}

int64_t RayMath::cell_exit(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell_micro,
                           uint64_t* evals) const {
  if (thresholds_.empty()) return cell_exit_rounded(r, k0, k_end, c, cell_micro, evals);
  // The search of cell_exit_rounded, each position tested against the
  // thresholds of the cell's faces instead of rounded, and its evaluations
  // counted from the answer (a bisection's path follows from it).
  constexpr double kInf = std::numeric_limits<double>::infinity();
  int64_t best = k_end;
  uint64_t n = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) continue;  // the coordinate never changes
    const int first = c[a] * cell_micro, last = first + cell_micro - 1;
    const double face = d > 0 ? double((c[a] + 1) * cell_micro) : double(c[a] * cell_micro);
    if ((d > 0 && face >= double(micro_res_)) || (d < 0 && face <= 0.0))
      continue;                            // the last cell: only the box ends it
    const int64_t lo = k0 + 1, hi = best;  // only an exit before `best` matters
    if (lo >= hi) break;
    // Outside: micro voxel below `first` or above `last` (micro_index clamps
    // to [0, Rm), so a cell touching the grid's side has no face there).
    const double o = r.origin[a];
    const Threshold low = first > 0 ? thresholds_[size_t(first)] : Threshold{-kInf, true};
    const Threshold high = last + 1 < micro_res_ ? thresholds_[size_t(last + 1)] : Threshold{kInf, false};
    auto outside = [&](int64_t k) {
      const double prod = d * t_of(k), s = prod + o;
      return !sum_at_least(prod, o, s, low) || sum_at_least(prod, o, s, high);
    };
    const double guess = std::ceil((face - o) / (d * step_) - 0.5);
    const int64_t g = std::isfinite(guess) ? int64_t(std::clamp(guess, double(lo), double(hi - 1))) : hi - 1;
    int64_t e;
    if (outside(g)) {
      if (g == lo) {
        e = g;
        n += 1;
      } else if (!outside(g - 1)) {
        e = g;
        n += 2;
      } else {
        e = first_true(lo, g - 1, outside);
        n += 2 + first_true_steps(lo, g - 1, e);
      }
    } else {
      if (g + 1 >= hi) {
        e = g + 1;
        n += 1;
      } else if (outside(g + 1)) {
        e = g + 1;
        n += 2;
      } else {
        e = first_true(g + 2, hi, outside);
        n += 2 + first_true_steps(g + 2, hi, e);
      }
    }
    best = std::min(best, e);
  }
  if (evals) *evals += n;
  return best;
}

namespace {
// The evaluations cell_exit's search makes on one axis over [lo, hi) from the
// clamped guess g when the first candidate outside is e (hi: none): the guess,
// one neighbour, then a bisection of the rest (its path follows from e).
uint64_t exit_search_steps(int64_t lo, int64_t hi, int64_t g, int64_t e) {
  if (g >= e) {  // the guess is outside
    if (g == lo || g == e) return g == lo ? 1 : 2;
    return 2 + first_true_steps(lo, g - 1, e);
  }
  if (g + 1 >= hi) return 1;
  if (g + 1 == e) return 2;
  return 2 + first_true_steps(g + 2, hi, e);
}
}  // namespace

// The crossing of `face` on axis a, made kept[0] (the previous kept[0]
// becomes kept[1]; a face in kept[1] is swapped in without a search).
const RayMath::FaceCrossing& RayMath::crossing(const ChipRay& r, int a, int face, int64_t lo, int64_t k_limit,
                                               std::array<FaceCrossing, 2>& kept) const {
  if (kept[1].face == face) {
    std::swap(kept[0], kept[1]);
    return kept[0];
  }
  kept[1] = kept[0];
  FaceCrossing& x = kept[0];
  const double d = r.dir[a], o = r.origin[a];
  x.face = face;
  x.guess = guess_index((double(face) - o) / (d * step_) - 0.5);
  const Threshold th = thresholds_[size_t(face)];
  if (d > 0)
    x.first = first_true_from(lo, k_limit, x.guess, [&](int64_t k) {
      const double prod = d * t_of(k);
      return sum_at_least(prod, o, prod + o, th);
    });
  else
    x.first = first_true_from(lo, k_limit, x.guess, [&](int64_t k) {
      const double prod = d * t_of(k);
      return !sum_at_least(prod, o, prod + o, th);
    });
  return x;
}

template <int kShift>
int64_t RayMath::cell_exit_memo(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell_micro,
                                uint64_t* evals, ExitMemo& memo, int64_t k_limit) const {
  if (thresholds_.empty()) return cell_exit_rounded(r, k0, k_end, c, cell_micro, evals);
  // A cell's low face, in micro units: a shift for cells of 2^kShift micro
  // voxels, a product for the other sizes (kShift < 0).
  auto low_face = [cell_micro](int cell) {
    if constexpr (kShift >= 0)
      return cell << kShift;
    else
      return cell * cell_micro;
  };
  // The point of k0 is in the cell, so along an axis the candidates after k0
  // are outside exactly when they are past the far face (the coordinate is
  // monotone): the first of them depends on the ray and that face only, and
  // is found once over [k0 + 1, k_limit). The search of cell_exit over
  // [lo, hi) then answers min(first, hi), and its evaluations follow from
  // that answer and its guess. With no candidate after k0 before k_end there
  // is nothing to search on any axis.
  const int64_t lo = k0 + 1;
  int64_t best = k_end;
  uint64_t n = 0;
  for (int a = 0; a < 3 && lo < best; ++a) {
    const double d = r.dir[a];
    int face;
    if (d > 0) {
      face = low_face(c[a] + 1);
      if (face >= micro_res_) continue;  // the last cell: only the box ends it
    } else if (d < 0) {
      face = low_face(c[a]);
      if (face <= 0) continue;
    } else {
      continue;  // the coordinate never changes
    }
    std::array<FaceCrossing, 2>& kept = memo.axis[size_t(a)];
    const FaceCrossing& x = kept[0].face == face ? kept[0] : crossing(r, a, face, lo, k_limit, kept);
    const int64_t hi = best;  // only an exit before `best` matters
    const int64_t g = x.guess != kNoGuess ? std::clamp(x.guess, lo, hi - 1) : hi - 1;
    const int64_t e = std::min(x.first, hi);
    n += exit_search_steps(lo, hi, g, e);
    best = e;  // e <= hi == best
  }
  if (evals) *evals += n;
  return best;
}

template int64_t RayMath::cell_exit_memo<-1>(const ChipRay&, int64_t, int64_t, const Vec3i&, int, uint64_t*, ExitMemo&,
                                             int64_t) const;
template int64_t RayMath::cell_exit_memo<1>(const ChipRay&, int64_t, int64_t, const Vec3i&, int, uint64_t*, ExitMemo&,
                                            int64_t) const;
template int64_t RayMath::cell_exit_memo<2>(const ChipRay&, int64_t, int64_t, const Vec3i&, int, uint64_t*, ExitMemo&,
                                            int64_t) const;

int64_t RayMath::cell_exit_rounded(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell_micro,
                                   uint64_t* evals) const {
  int64_t best = k_end;
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) continue;  // the coordinate never changes
    // Leaving the cell along this axis: past its far face in the direction of travel.
    // In the cell: a micro voxel of [first, last] (micro_index is never negative).
    const int first = c[a] * cell_micro, last = first + cell_micro - 1;
    auto outside = [&](int64_t k) {
      if (evals) ++*evals;
      const int m = micro_index(coord(r, k, a));
      return m < first || m > last;
    };
    const double face = d > 0 ? double((c[a] + 1) * cell_micro) : double(c[a] * cell_micro);
    if ((d > 0 && face >= double(micro_res_)) || (d < 0 && face <= 0.0))
      continue;                            // the last cell: only the box ends it
    const int64_t lo = k0 + 1, hi = best;  // only an exit before `best` matters
    if (lo >= hi) break;
    // First guess: the candidate just past the face, then checked exactly.
    const double guess = std::ceil((face - r.origin[a]) / (d * step_) - 0.5);
    const int64_t g = std::isfinite(guess) ? int64_t(std::clamp(guess, double(lo), double(hi - 1))) : hi - 1;
    int64_t e;
    if (outside(g))
      e = (g == lo || !outside(g - 1)) ? g : first_true(lo, g - 1, outside);
    else
      e = (g + 1 >= hi || outside(g + 1)) ? g + 1 : first_true(g + 2, hi, outside);
    best = std::min(best, e);
  }
  return best;
}

KInterval RayMath::box_interval(const ChipRay& r, const Vec3d& lo, const Vec3d& hi, uint64_t* evals) const {
  PreparedBox box;
  box.lo = lo;
  box.hi = hi;  // no fast axes: every position rounded
  return box_interval(r, box, evals);
}

bool RayMath::find_threshold(double v, bool strict, Threshold& out) const {
  // Doubles in order as unsigned integers (the negative ones below the
  // positive ones, -0 just below +0).
  auto key = [](double x) {
    const uint64_t b = std::bit_cast<uint64_t>(x);
    return (b >> 63) ? ~b : b | (uint64_t(1) << 63);
  };
  auto value = [](uint64_t k) { return std::bit_cast<double>((k >> 63) ? k & ~(uint64_t(1) << 63) : ~k); };
  auto passes = [&](double x) { return strict ? fmt_.round(x) > v : fmt_.round(x) >= v; };
  const double big = std::numeric_limits<double>::max();
  if (!passes(big)) return false;
  // The least double that passes (round() is monotone), by bisection.
  uint64_t lo = key(-big), hi = key(big);
  while (lo < hi) {
    const uint64_t mid = lo + (hi - lo) / 2;
    if (passes(value(mid)))
      hi = mid;
    else
      lo = mid + 1;
  }
  // The fused multiply-add rounds the exact sum to odd at double precision
  // first: a sum strictly between b's predecessor and b becomes the odd one
  // of the two. With b even it becomes the predecessor (which does not
  // pass), so the sum must reach b; with b odd it becomes b, so any sum above
  // the predecessor passes.
  const double b = value(lo);
  if (lo == key(-big))
    out = {-std::numeric_limits<double>::infinity(), true};  // every finite sum passes
  else if ((std::bit_cast<uint64_t>(b) & 1) == 0)
    out = {b, true};
  else
    out = {value(lo - 1), false};
  return true;
}

RayMath::PreparedBox RayMath::prepare_box(const Vec3d& lo, const Vec3d& hi) const {
  PreparedBox box;
  box.lo = lo;
  box.hi = hi;
  for (int a = 0; a < 3; ++a)
    box.fast[size_t(a)] = find_threshold(lo[a], false, box.at_least_lo[size_t(a)]) &&
                          find_threshold(hi[a], true, box.above_hi[size_t(a)]);
  return box;
}

KInterval RayMath::box_interval(const ChipRay& r, const PreparedBox& box, uint64_t* evals) const {
  // The TSPS bisects each bound over [0, kMaxCandidate). The bounds are found
  // here from the ray's distance to each face, checked exactly (the
  // coordinate is monotone in k, so the first k past a face is unique), and
  // the bisection's evaluations are counted as the hardware makes them.
  const Vec3d &lo = box.lo, &hi = box.hi;
  KInterval out{0, kMaxCandidate};
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) {
      const double c = r.origin[a];  // fma(0, t, o) = o
      if (!(c >= lo[a] && c <= hi[a])) return {0, 0};
      continue;
    }
    // Inside along this axis: a run [enter, leave) of k (the coordinate is monotone).
    const double o = r.origin[a];
    auto k_at = [&](double face) { return guess_index((face - o) / (d * step_) - 0.5); };
    int64_t enter, leave;
    if (box.fast[size_t(a)]) {
      const Threshold at_lo = box.at_least_lo[size_t(a)], past_hi = box.above_hi[size_t(a)];
      auto at_least_lo = [&](int64_t k) {
        const double prod = d * t_of(k);
        return sum_at_least(prod, o, prod + o, at_lo);
      };
      auto above_hi = [&](int64_t k) {
        const double prod = d * t_of(k);
        return sum_at_least(prod, o, prod + o, past_hi);
      };
      if (d > 0) {
        enter = first_true_from(0, kMaxCandidate, k_at(lo[a]), at_least_lo);
        leave = first_true_from(enter, kMaxCandidate, k_at(hi[a]), above_hi);
      } else {
        enter = first_true_from(0, kMaxCandidate, k_at(hi[a]), [&](int64_t k) { return !above_hi(k); });
        leave = first_true_from(enter, kMaxCandidate, k_at(lo[a]), [&](int64_t k) { return !at_least_lo(k); });
      }
    } else if (d > 0) {
      enter = first_true_from(0, kMaxCandidate, k_at(lo[a]), [&](int64_t k) { return coord(r, k, a) >= lo[a]; });
      leave = first_true_from(enter, kMaxCandidate, k_at(hi[a]), [&](int64_t k) { return coord(r, k, a) > hi[a]; });
    } else {
      enter = first_true_from(0, kMaxCandidate, k_at(hi[a]), [&](int64_t k) { return coord(r, k, a) <= hi[a]; });
      leave = first_true_from(enter, kMaxCandidate, k_at(lo[a]), [&](int64_t k) { return coord(r, k, a) < lo[a]; });
    }
    if (evals) *evals += first_true_steps(0, kMaxCandidate, enter) + first_true_steps(enter, kMaxCandidate, leave);
    out.begin = std::max(out.begin, enter);
    out.end = std::min(out.end, leave);
  }
  if (out.empty()) return {0, 0};
  return out;
}

}  // namespace edrnr::chip
