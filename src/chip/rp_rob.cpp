#include "chip/rp_rob.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "core/error.h"

namespace edrnr::chip {

const char* tag_switch_rule_name(TagSwitchRule r) { return r == TagSwitchRule::Paper ? "paper" : "fullest"; }

TagSwitchRule parse_tag_switch_rule(const std::string& text, const std::string& field) {
  if (text == "paper") return TagSwitchRule::Paper;
  if (text == "fullest") return TagSwitchRule::Fullest;
  fail("{}: unknown tag-switch rule '{}' (known: paper, fullest)", field, text);
}

RpRob::RpRob(const RpRobConfig& config) : config_(config) {
  if (config.entries < 1) fail("RP-ROB entries must be at least 1 (got {})", config.entries);
  if (config.entry_depth < 1) fail("RP-ROB entry depth must be at least 1 (got {})", config.entry_depth);
  if (config.recent_tags < 0)
    fail("RP-ROB recent-tags recorder size must not be negative (got {})", config.recent_tags);
  entries_.resize(size_t(config.entries));
  queues_.resize(size_t(config.entries));
}

void RpRob::note_recent(uint32_t tag) {
  if (config_.recent_tags == 0) return;
  auto it = std::find(recent_.begin(), recent_.end(), tag);
  if (it != recent_.end()) recent_.erase(it);
  recent_.push_front(tag);
  if (recent_.size() > size_t(config_.recent_tags)) recent_.pop_back();
}

bool RpRob::in_recent(uint32_t tag) const { return std::find(recent_.begin(), recent_.end(), tag) != recent_.end(); }

bool RpRob::insert_scan(uint32_t rp, uint32_t tag) {
  if (rp < where_.size() && where_[rp].held)
    throw std::logic_error("RP-ROB insert: RP " + std::to_string(rp) + " is already held");
  int chosen = -1;
  if (config_.reorder) {
    // An entry of this tag with room, the most occupied first.
    for (int e = 0; e < entries(); ++e) {
      const Entry& en = entries_[size_t(e)];
      if (en.count > 0 && en.tag == tag && en.count < config_.entry_depth &&
          (chosen < 0 || en.count > entries_[size_t(chosen)].count))
        chosen = e;
    }
    if (chosen < 0)
      for (int e = 0; e < entries() && chosen < 0; ++e)
        if (entries_[size_t(e)].count == 0) chosen = e;
  } else {
    for (int e = 0; e < entries() && chosen < 0; ++e)
      if (entries_[size_t(e)].count < config_.entry_depth) chosen = e;
  }
  if (chosen < 0) {
    ++counters_.insert_refusals;
    refused_version_ = capacity_version_;
    refused_rp_ = rp;
    refused_tag_ = tag;
    return false;
  }
  // A new CRP of another tag leaves an answer "wait for the current tag's
  // CCRPs" as it was (only the current tag's entries decide it).
  if (!(waiting_ && nothing_version_ == version_ && tag != current_)) ++version_;
  ++capacity_version_;
  Entry& en = entries_[size_t(chosen)];
  if (en.count == 0) {
    en.tag = tag;
    ++entries_used_;
  }
  ++en.count;
  queues_[size_t(chosen)].push_back({rp, tag, stamp_++});
  ++en.ready;
  if (rp >= where_.size()) where_.resize(size_t(rp) + 1);
  where_[rp] = {chosen, tag, false, true};
  ++held_;
  note_recent(tag);
  ++counters_.inserts;
  counters_.peak_entries_used = std::max(counters_.peak_entries_used, entries_used_);
  return true;
}

ScheduledRp RpRob::pop(int e) {
  ++version_;
  Entry& en = entries_[size_t(e)];
  std::deque<Ready>& q = queues_[size_t(e)];
  Ready r = q.front();
  q.pop_front();
  --en.ready;
  where_[r.rp].in_flight = true;
  ++counters_.schedules;
  if (!has_last_scheduled_ || last_scheduled_ != r.tag) ++counters_.tag_runs;
  has_last_scheduled_ = true;
  last_scheduled_ = r.tag;
  return {r.rp, r.tag, e};
}

bool RpRob::schedule_scan(ScheduledRp& out) {
  waiting_ = false;
  if (!config_.reorder) {
    int best = -1;
    for (int e = 0; e < entries(); ++e) {
      const Entry& en = entries_[size_t(e)];
      if (en.ready > 0 && (best < 0 || queues_[size_t(e)].front().stamp < queues_[size_t(best)].front().stamp))
        best = e;
    }
    if (best < 0) return false;
    out = pop(best);
    has_current_ = true;
    current_ = out.tag;
    return true;
  }
  if (has_current_) {
    // Serve the current tag: its entry with the most free room.
    int best = -1;
    bool any_placeholder = false;
    for (int e = 0; e < entries(); ++e) {
      const Entry& en = entries_[size_t(e)];
      if (en.count == 0 || en.tag != current_) continue;
      any_placeholder = true;
      if (en.ready > 0 && (best < 0 || en.count < entries_[size_t(best)].count)) best = e;
    }
    if (best >= 0) {
      out = pop(best);
      return true;
    }
    if (any_placeholder && !config_.switch_when_idle) {
      waiting_ = true;
      return false;  // wait until they come back or retire
    }
  }
  // Tag switch.
  int hit = -1, other = -1;
  for (int e = 0; e < entries(); ++e) {
    const Entry& en = entries_[size_t(e)];
    if (en.ready == 0) continue;
    if (config_.tag_switch == TagSwitchRule::Fullest) {
      if (other < 0 || en.ready > entries_[size_t(other)].ready) other = e;
    } else if (in_recent(en.tag)) {
      if (hit < 0 || en.count < entries_[size_t(hit)].count) hit = e;
    } else if (other < 0 || en.count > entries_[size_t(other)].count) {
      other = e;
    }
  }
  int chosen = hit >= 0 ? hit : other;
  if (chosen < 0) {
    has_current_ = false;
    return false;
  }
  if (hit >= 0) ++counters_.recorder_hits;
  has_current_ = true;
  current_ = entries_[size_t(chosen)].tag;
  out = pop(chosen);
  return true;
}

RpRob::Place& RpRob::in_flight_place(uint32_t rp, const char* op) {
  if (rp >= where_.size() || !where_[rp].held || !where_[rp].in_flight)
    throw std::logic_error(std::string("RP-ROB ") + op + ": RP " + std::to_string(rp) + " is not in flight");
  return where_[rp];
}

void RpRob::reschedule(uint32_t rp) {
  Place& p = in_flight_place(rp, "reschedule");
  p.in_flight = false;
  queues_[size_t(p.entry)].push_back({rp, p.tag, stamp_++});
  ++entries_[size_t(p.entry)].ready;
  ++version_;
  ++counters_.reschedules;
}

void RpRob::retire(uint32_t rp) {
  Place& p = in_flight_place(rp, "retire");
  Entry& en = entries_[size_t(p.entry)];
  if (--en.count == 0) --entries_used_;
  p = Place{};
  --held_;
  ++version_;
  ++capacity_version_;
  ++counters_.retires;
}

}  // namespace edrnr::chip
