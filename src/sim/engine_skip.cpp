// The engine's quiet cycles: when no unit can act before some later cycle,
// the cycles between are counted in bulk instead of stepped.
#include "sim/engine.h"

namespace edrnr::sim::engine {

// After cycle c has run: the first later cycle in which any unit, FIFO or
// the memory system may act differently from c (a countdown ending, an
// item becoming visible). In the cycles between, every unit reports c's
// state, and the only side effects are the per-cycle counts that skip()
// adds in bulk. c + 1 when that cannot be shown.
uint64_t Engine::quiet_until(uint64_t c) {
  // The most frequent reasons to step the next cycle are tested first.
  const uint64_t next = c + 1;
  // OoO-SI, CFIU, TME and VRU: quiet only when empty.
  if (!ooo_.empty() || tme_s_.holding || vru_s_.holding || !tme_in_.empty() || !vru_in_.empty()) return next;
  if (tme_s_.loading || (cfiu_s_.active && c >= cfiu_s_.start)) return next;
  if (!retry_micro_.empty() || !retry_mlp_.empty()) return next;
  if (prefetch_next_ < prefetch_lines_.size() || !bitmaps_ready_) return next;
  uint64_t u = UINT64_MAX;
  auto until = [&](uint64_t t) { u = std::min(u, std::max(t, next)); };
  if (cfiu_s_.active) until(cfiu_s_.start);
  until(done_q_.head_visible_cycle());
  UnitState* st = quiet_state_;
  st[kOooSi] = st[kCfiu] = st[kTme] = st[kVru] = UnitState::Idle;
  // Front end: a packet counting down, or a hand-over waiting for room
  // that only another unit's action makes, or the frame done.
  if (fe_.holding) {
    if (c < fe_.end) until(fe_.end);
    st[kFrontEnd] = next < fe_.end ? UnitState::Busy : UnitState::StallOutput;
  } else if (!zorg_.done()) {
    return next;
  } else {
    st[kFrontEnd] = UnitState::Idle;
  }
  // CTU: counting down, an insert the RP-ROB keeps refusing, or waiting
  // for its FIFOs' next item.
  if (ctu_s_.holding) {
    if (c < ctu_s_.end)
      until(ctu_s_.end);
    else if (!ctu_s_.result.found || !rob_.insert_known_refused(ctu_s_.rp, ctu_s_.result.cv_tag))
      return next;
    st[kCtu] = next < ctu_s_.end ? UnitState::Busy : UnitState::StallOutput;
  } else if (retire_q_.can_pop(c) || fe_out_.can_pop(c)) {
    return next;
  } else {
    st[kCtu] = UnitState::Idle;
  }
  until(retire_q_.head_visible_cycle());
  until(fe_out_.head_visible_cycle());
  // FTU: its result waiting for a full OoO-SI; or all its micro-grid words
  // read and its run counting down; or free with nothing to schedule.
  const FtuShell& f = ftu_s_;
  if (f.holding) {
    if (f.output) {
      if (!f.has_batch || !ooo_.full()) return next;
      st[kFtu] = UnitState::StallOutput;
    } else {
      if (f.next_read < f.reads.size() || !f.waiting.empty()) return next;
      until(std::max(f.ready, f.end - 1));  // the cycle it decides to hand over
      if (c < f.end) until(f.end);          // busy until then, waiting after
      st[kFtu] = next < f.end ? UnitState::Busy : UnitState::StallMemory;
    }
  } else if (free_slots_.empty()) {
    st[kFtu] = rob_.empty() ? UnitState::Idle : UnitState::StallOutput;
  } else if (!rob_.schedule_known_empty()) {
    return next;
  } else {
    st[kFtu] = UnitState::Idle;
  }
  until(mem_.quiet_until(c));  // no transfer completes before
  return u;
}

// Counts cycles [first, first + n) as quiet_until() found them: each unit
// in its state (the FIFOs count them when they next change), the memory
// clocks run, refused RP-ROB inserts repeated.
void Engine::skip(uint64_t first, uint64_t n) {
  for (uint32_t u = 0; u < kUnits; ++u) activity_.repeat(u, quiet_state_[u], first, n);
  if (ctu_s_.holding && first > ctu_s_.end) rob_.repeat_refused_insert(n);
  completions_.clear();
  mem_.advance(first + n - 1, completions_);  // the DRAM clocks, ticking only where it must
  if (!completions_.empty()) throw std::logic_error("cycle simulator: a memory completion in skipped cycles");
  skipped_cycles_ += n;
}

}  // namespace edrnr::sim::engine
