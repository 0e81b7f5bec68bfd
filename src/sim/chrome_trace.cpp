#include "sim/chrome_trace.h"

#include <algorithm>

#include "core/error.h"

namespace edrnr::sim {

const char* unit_state_name(UnitState s) {
  switch (s) {
    case UnitState::Busy:
      return "busy";
    case UnitState::StallOutput:
      return "stall_output";
    case UnitState::StallMemory:
      return "stall_memory";
    case UnitState::Idle:
      return "idle";
  }
  return "?";
}

ActivityRecorder::ActivityRecorder(std::vector<std::string> units, uint64_t window_start, uint64_t window_cycles,
                                   size_t max_events)
    : names_(std::move(units)),
      tracks_(names_.size()),
      window_start_(window_start),
      window_end_(window_cycles > UINT64_MAX - window_start ? UINT64_MAX : window_start + window_cycles),
      max_events_(max_events) {}

void ActivityRecorder::close(uint32_t unit) {
  Track& t = tracks_[unit];
  if (!t.open) return;
  t.open = false;
  if (t.state == UnitState::Idle) return;
  const uint64_t lo = std::max(t.start, window_start_), hi = std::min(t.last + 1, window_end_);
  if (lo >= hi) return;
  if (intervals_.size() >= max_events_) {
    ++dropped_;
    return;
  }
  intervals_.push_back({unit, t.state, lo, hi - lo});
}

void ActivityRecorder::finish() {
  for (uint32_t u = 0; u < tracks_.size(); ++u) close(u);
}

nlohmann::json ActivityRecorder::chrome_trace(double clock_MHz) const {
  if (!(clock_MHz > 0.0)) fail("chrome trace: clock {} MHz must be positive", clock_MHz);
  nlohmann::json events = nlohmann::json::array();
  events.push_back({{"name", "process_name"}, {"ph", "M"}, {"pid", 1}, {"args", {{"name", "EDR-NR chip"}}}});
  for (uint32_t u = 0; u < names_.size(); ++u) {
    events.push_back({{"name", "thread_name"}, {"ph", "M"}, {"pid", 1}, {"tid", u}, {"args", {{"name", names_[u]}}}});
    events.push_back(
        {{"name", "thread_sort_index"}, {"ph", "M"}, {"pid", 1}, {"tid", u}, {"args", {{"sort_index", u}}}});
  }
  const double us_per_cycle = 1.0 / clock_MHz;
  for (const TraceInterval& i : intervals_)
    events.push_back({{"name", unit_state_name(i.state)},
                      {"cat", names_[i.unit]},
                      {"ph", "X"},
                      {"pid", 1},
                      {"tid", i.unit},
                      {"ts", double(i.start_cycle) * us_per_cycle},
                      {"dur", double(i.cycles) * us_per_cycle},
                      {"args", {{"start_cycle", i.start_cycle}, {"cycles", i.cycles}}}});
  return {{"traceEvents", std::move(events)},
          {"displayTimeUnit", "ns"},
          {"otherData", {{"clock_MHz", clock_MHz}, {"dropped_events", dropped_}}}};
}

}  // namespace edrnr::sim
