// The engine's quiet cycles: when no unit can act before some later cycle,
// the cycles between are counted in bulk instead of stepped.
#include "sim/engine.h"

namespace edrnr::sim::engine {

uint64_t Engine::quiet_until(uint64_t c) {
  // The most frequent reasons to step the next cycle are tested first.
  const uint64_t next = c + 1;
  const CfiuShell& cf = cfiu_s_;
  const TmeShell& tm = tme_s_;
  const VruShell& vr = vru_s_;
  const bool streaming = cf.active && c >= cf.start;  // the CFIU reads samples (from the cycle after its issue)
  // The CFIU hands a sample to the TME next cycle.
  if (streaming && cf.left <= 1 && tme_in_.can_push()) return next;
  // An item visible to a free TME or VRU.
  if (!tm.holding && tme_in_.can_pop(next)) return next;
  if (!vr.holding && vru_in_.can_pop(next)) return next;
  if (tm.loading || (tm.holding && tm.left == 0)) return next;  // a weight load, or a sample waiting for room
  if (!retry_micro_.empty() || !retry_mlp_.empty()) return next;
  if (prefetch_next_ < prefetch_lines_.size() || !bitmaps_ready_) return next;
  if (mem_.requests_waiting()) return next;  // handed to the DRAM as its queue takes them
  // OoO-SI: waits for the CFIU (its next action is bounded below), or for a
  // fill; anything else may issue.
  UnitState* st = quiet_state_;
  if (ooo_.empty())
    st[kOooSi] = UnitState::Idle;
  else if (cf.active)
    st[kOooSi] = UnitState::StallOutput;
  else if (ooo_.known_waiting(cfiu_.cache()))
    st[kOooSi] = UnitState::StallMemory;
  else
    return next;
  uint64_t u = UINT64_MAX;
  auto until = [&](uint64_t t) { u = std::min(u, std::max(t, next)); };
  // CFIU, TME and VRU count down their samples (each acts in the cycle its
  // count reaches its last), and the TME and VRU, when free, wait for their
  // queue's head to become visible; the CFIU, with its sample done, waits for
  // room that only the TME's pop makes.
  if (!cf.active || !streaming) {
    if (cf.active) until(cf.start);
    st[kCfiu] = UnitState::Idle;
  } else if (cf.left > 1) {
    until(next + cf.left - 1);
    st[kCfiu] = UnitState::Busy;
  } else {
    st[kCfiu] = UnitState::StallOutput;
  }
  auto sample_unit = [&](Unit unit, bool holding, uint64_t left, const Fifo<SampleToken>& in) {
    if (holding)
      until(next + left - 1);
    else
      until(in.head_visible_cycle());
    st[unit] = holding ? UnitState::Busy : UnitState::Idle;
  };
  sample_unit(kTme, tm.holding, tm.left, tme_in_);
  sample_unit(kVru, vr.holding, vr.left, vru_in_);
  until(done_q_.head_visible_cycle());
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
  // CTU: counting down, an insert the RP-ROB keeps refusing, or free and
  // waiting for its FIFOs' next item.
  if (ctu_s_.holding) {
    if (c < ctu_s_.end)
      until(ctu_s_.end);
    else if (!ctu_s_.result.found || !rob_.insert_known_refused(ctu_s_.rp, ctu_s_.result.cv_tag))
      return next;
    st[kCtu] = next < ctu_s_.end ? UnitState::Busy : UnitState::StallOutput;
  } else if (retire_q_.can_pop(c) || fe_out_.can_pop(c)) {
    return next;
  } else {
    // Its FIFOs matter only to a free CTU: a holding one pops after it hands over.
    until(retire_q_.head_visible_cycle());
    until(fe_out_.head_visible_cycle());
    st[kCtu] = UnitState::Idle;
  }
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
  return u;
}

// Counts cycles [first, first + n) as quiet_until() found them: each unit
// in its state (the FIFOs count them when they next change), the back end's
// countdowns run down, refused RP-ROB inserts and OoO-SI waits repeated.
void Engine::skip(uint64_t first, uint64_t n) {
  // In the order the cycle loop steps the units (back end first), so that
  // intervals close in the same order as when every cycle is stepped.
  for (uint32_t u = kUnits; u-- > 0;) activity_.repeat(u, quiet_state_[u], first, n);
  if (ctu_s_.holding && first > ctu_s_.end) rob_.repeat_refused_insert(n);
  // The back end's countdowns (quiet_until() ended the skip before any reaches its last).
  if (quiet_state_[kCfiu] == UnitState::Busy) cfiu_s_.left -= uint32_t(n);
  if (quiet_state_[kTme] == UnitState::Busy) tme_s_.left -= n;
  if (quiet_state_[kVru] == UnitState::Busy) vru_s_.left -= n;
  if (quiet_state_[kOooSi] == UnitState::StallMemory) ooo_.repeat_waits(n);
  skipped_cycles_ += n;
}

}  // namespace edrnr::sim::engine
