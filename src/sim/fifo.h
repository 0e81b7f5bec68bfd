#pragma once
// Bounded FIFO with back-pressure and an optional pipeline latency, the queue
// between two units of the cycle simulator.
//
// Contract:
// - At most `capacity` items are held. A producer checks can_push() (or uses
//   try_push()) and stalls while the queue is full: that is the back-pressure.
// - An item pushed in cycle c becomes visible to the consumer in cycle
//   c + latency_cycles. With latency 0 a consumer evaluated after the producer
//   in the same cycle sees it at once; latency 1 models one register stage and
//   makes the result independent of the order units are evaluated in.
// - Items leave in the order they entered.
// - Per-cycle statistics (cycles spent full, cycles with nothing visible to
//   pop, the occupancy summed over cycles) are counted without a call per
//   cycle: between two pushes or pops the state is constant but for the
//   head's visibility, so the cycles before a push or pop in cycle c are
//   counted by it, each with the state it ended with. account_until(end)
//   counts the cycles before `end` not yet counted (call it once the run is
//   over, with the run's length in cycles, before reading the statistics);
//   sample(cycle) is account_until(cycle + 1). Cycles are non-decreasing.
// T must be default-constructible and movable (the storage is a ring buffer).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/stats.h"

namespace edrnr::sim {

struct FifoStats {
  uint64_t pushes = 0;
  uint64_t pops = 0;
  uint64_t push_stalls = 0;     // try_push() calls refused because the FIFO was full
  uint64_t sampled_cycles = 0;  // sample() calls
  uint64_t full_cycles = 0;     // sampled cycles in which the FIFO was full
  uint64_t empty_cycles = 0;    // sampled cycles in which no item was visible to pop
  uint64_t occupancy_sum = 0;   // items held, summed over sampled cycles
  size_t max_occupancy = 0;

  double mean_occupancy() const { return sampled_cycles ? double(occupancy_sum) / double(sampled_cycles) : 0.0; }
};

template <class T>
class Fifo {
 public:
  // Throws Error if capacity is 0. `name` appears in error messages and statistics.
  explicit Fifo(std::string name, size_t capacity, uint64_t latency_cycles = 0)
      : name_(std::move(name)), latency_cycles_(latency_cycles) {
    if (capacity == 0) fail("fifo '{}': capacity must be at least 1", name_);
    slots_.resize(capacity);
  }

  const std::string& name() const { return name_; }
  size_t capacity() const { return slots_.size(); }
  uint64_t latency_cycles() const { return latency_cycles_; }
  // Items held, visible or still in flight.
  size_t occupancy() const { return count_; }
  bool empty() const { return count_ == 0; }
  bool full() const { return count_ == slots_.size(); }

  bool can_push() const { return !full(); }

  // Appends `item`, pushed in `cycle`. Precondition: can_push(); throws Error otherwise.
  void push(T item, uint64_t cycle) {
    if (full()) fail("fifo '{}': push while full (capacity {}); check can_push() first", name_, capacity());
    account_until(cycle);
    size_t tail = head_ + count_;
    if (tail >= slots_.size()) tail -= slots_.size();
    Slot& s = slots_[tail];
    s.item = std::move(item);
    s.visible_cycle = cycle + latency_cycles_;
    ++count_;
    ++stats_.pushes;
    if (count_ > stats_.max_occupancy) stats_.max_occupancy = count_;
  }

  // Pushes if there is room and returns true; otherwise counts a push stall and returns false.
  bool try_push(T item, uint64_t cycle) {
    if (full()) {
      ++stats_.push_stalls;
      return false;
    }
    push(std::move(item), cycle);
    return true;
  }

  // True when the oldest item exists and is visible in `cycle`.
  bool can_pop(uint64_t cycle) const { return count_ > 0 && slots_[head_].visible_cycle <= cycle; }

  // The oldest item. Precondition: can_pop(cycle) for the current cycle.
  const T& front() const {
    if (count_ == 0) fail("fifo '{}': front() of an empty fifo", name_);
    return slots_[head_].item;
  }
  T& front() {
    if (count_ == 0) fail("fifo '{}': front() of an empty fifo", name_);
    return slots_[head_].item;
  }

  // Removes and returns the oldest item. Precondition: can_pop(cycle); throws Error otherwise.
  T pop(uint64_t cycle) {
    if (!can_pop(cycle)) fail("fifo '{}': pop in cycle {} with no visible item", name_, cycle);
    account_until(cycle);
    T out = std::move(slots_[head_].item);
    slots_[head_].item = T{};
    if (++head_ == slots_.size()) head_ = 0;
    --count_;
    ++stats_.pops;
    return out;
  }

  // The cycle the oldest item becomes visible; UINT64_MAX when empty.
  uint64_t head_visible_cycle() const { return count_ > 0 ? slots_[head_].visible_cycle : UINT64_MAX; }

  // Counts cycles [first counted, end) in the statistics with the current
  // state: occupancy and fullness constant, nothing visible to pop before the
  // head's visible cycle.
  void account_until(uint64_t end) {
    if (end <= accounted_) return;
    const uint64_t n = end - accounted_;
    stats_.sampled_cycles += n;
    if (full()) stats_.full_cycles += n;
    const uint64_t visible = head_visible_cycle();  // UINT64_MAX when empty
    if (visible > accounted_) stats_.empty_cycles += std::min(end, visible) - accounted_;
    stats_.occupancy_sum += count_ * n;
    accounted_ = end;
  }

  // The statistics of cycle `cycle` (and any before it not yet counted).
  void sample(uint64_t cycle) { account_until(cycle + 1); }

  const FifoStats& stats() const { return stats_; }

  // Registers this FIFO's statistics as "<prefix>.*" in `registry` with their
  // current values; call once, when the run is over.
  void export_stats(StatsRegistry& registry, const std::string& prefix) const {
    registry.counter(prefix + ".capacity", "items", "capacity").value = capacity();
    registry.counter(prefix + ".pushes", "items", "items pushed").value = stats_.pushes;
    registry.counter(prefix + ".pops", "items", "items popped").value = stats_.pops;
    registry.counter(prefix + ".push_stalls", "attempts", "pushes refused because the fifo was full").value =
        stats_.push_stalls;
    registry.counter(prefix + ".full_cycles", "cycles", "cycles the fifo was full (producer back-pressured)").value =
        stats_.full_cycles;
    registry.counter(prefix + ".empty_cycles", "cycles", "cycles with no item visible to the consumer").value =
        stats_.empty_cycles;
    registry.value(prefix + ".mean_occupancy", "items", "items held, averaged over sampled cycles")
        .set(stats_.mean_occupancy());
    registry.counter(prefix + ".max_occupancy", "items", "most items held at once").value = stats_.max_occupancy;
  }

 private:
  struct Slot {
    T item{};
    uint64_t visible_cycle = 0;
  };
  std::string name_;
  uint64_t latency_cycles_ = 0;
  std::vector<Slot> slots_;
  size_t head_ = 0;
  size_t count_ = 0;
  uint64_t accounted_ = 0;  // cycles before this one are in stats_
  FifoStats stats_;
};

}  // namespace edrnr::sim
