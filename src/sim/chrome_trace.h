#pragma once
// Per-unit activity of the cycle simulator: what each unit did in every cycle
// (busy, stalled on its output, waiting for memory, idle), counted over the
// whole run and recorded as intervals over a window of cycles for a Chrome
// trace (chrome://tracing, https://ui.perfetto.dev).
//
// A unit reports one state per cycle through set(); consecutive cycles in the
// same state become one interval. Intervals of the non-idle states that
// overlap [window_start, window_start + window_cycles) are kept (clipped to
// the window), up to max_events in all; later ones are counted as dropped.
#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace edrnr::sim {

enum class UnitState : uint8_t { Busy, StallOutput, StallMemory, Idle };
inline constexpr int kUnitStates = 4;
const char* unit_state_name(UnitState s);  // "busy", "stall_output", "stall_memory", "idle"

struct TraceInterval {
  uint32_t unit = 0;
  UnitState state = UnitState::Busy;
  uint64_t start_cycle = 0;
  uint64_t cycles = 0;
};

class ActivityRecorder {
 public:
  // units: the unit names, in display order.
  ActivityRecorder(std::vector<std::string> units, uint64_t window_start, uint64_t window_cycles,
                   size_t max_events = 1000000);

  // The state of `unit` in `cycle`. Each unit reports cycles in increasing order.
  void set(uint32_t unit, UnitState state, uint64_t cycle) {
    Track& t = tracks_[unit];
    ++t.cycles[size_t(state)];
    if (t.open) {
      if (state == t.state && cycle == t.last + 1) {
        t.last = cycle;
        return;
      }
      close(unit);
    }
    if (cycle >= window_end_) return;  // an interval opened now ends outside the window
    t.open = true;
    t.state = state;
    t.start = cycle;
    t.last = cycle;
  }
  // set(unit, state, c) for each of the `cycles` cycles c from `first`.
  void repeat(uint32_t unit, UnitState state, uint64_t first, uint64_t cycles) {
    Track& t = tracks_[unit];
    t.cycles[size_t(state)] += cycles;
    if (t.open) {
      if (state == t.state && first == t.last + 1) {
        t.last = first + cycles - 1;
        return;
      }
      close(unit);
    }
    if (first >= window_end_) return;
    t.open = true;
    t.state = state;
    t.start = first;
    t.last = first + cycles - 1;
  }
  // Ends every open interval (call once, after the last cycle).
  void finish();

  size_t units() const { return tracks_.size(); }
  const std::string& unit_name(uint32_t unit) const { return names_[unit]; }
  uint64_t cycles(uint32_t unit, UnitState state) const { return tracks_[unit].cycles[size_t(state)]; }
  const std::vector<TraceInterval>& intervals() const { return intervals_; }
  uint64_t dropped_events() const { return dropped_; }

  // The recorded intervals as a Chrome trace: one thread per unit, one
  // complete ("X") event per interval, time in microseconds at clock_MHz.
  nlohmann::json chrome_trace(double clock_MHz) const;

 private:
  struct Track {
    UnitState state = UnitState::Idle;
    uint64_t start = 0;
    uint64_t last = 0;
    bool open = false;
    std::array<uint64_t, kUnitStates> cycles{};
  };
  void close(uint32_t unit);

  std::vector<std::string> names_;
  std::vector<Track> tracks_;
  uint64_t window_start_, window_end_;
  size_t max_events_;
  std::vector<TraceInterval> intervals_;
  uint64_t dropped_ = 0;
};

}  // namespace edrnr::sim
