#pragma once
// Miss status holding registers (MSHR): a bounded table of outstanding line
// misses of one cache (docs/caches.md).
//
// Contract:
// - on_miss(line) opens an entry for a line that is not outstanding
//   (Allocated: the caller issues exactly one DRAM request for it), merges
//   into the entry of a line that is (Merged: no new DRAM request), or, when
//   every entry is busy, refuses (Full: the requester stalls and retries in a
//   later cycle; the attempt is counted as a stall, not as a miss).
// - schedule_fill(line, cycle) records when the line's data arrive (the DRAM
//   model knows); arrived(cycle) lists the lines whose data are there.
// - retire(line, cycle) frees the entry once the line is in the cache and
//   records the miss latency (retire cycle - allocation cycle).
// Entries are kept in allocation order, so every query is deterministic.
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace edrnr::sim {

enum class MshrOutcome { Allocated, Merged, Full };

struct MshrStats {
  uint64_t allocations = 0;  // new entries: one DRAM request each
  uint64_t merges = 0;       // misses absorbed by an outstanding entry
  uint64_t full_stalls = 0;  // on_miss() calls refused because every entry was busy
  uint64_t retired = 0;
  uint64_t latency_cycles_sum = 0;  // sum over retired entries of (retire - allocation) cycles
  size_t max_occupancy = 0;

  double mean_latency_cycles() const { return retired ? double(latency_cycles_sum) / double(retired) : 0.0; }
};

class Mshr {
 public:
  static constexpr uint64_t kNotScheduled = std::numeric_limits<uint64_t>::max();

  // Throws Error if entries is 0. `name` appears in error messages.
  Mshr(std::string name, size_t entries);

  size_t capacity() const { return capacity_; }
  size_t occupancy() const { return entries_.size(); }
  bool full() const { return entries_.size() == capacity_; }

  // Records a miss to `line_addr` (a line number, not a byte address) in `cycle`.
  MshrOutcome on_miss(uint64_t line_addr, uint64_t cycle);

  bool outstanding(uint64_t line_addr) const { return find(line_addr) != nullptr; }
  // Requests waiting on the line: 1 + merges; 0 if not outstanding.
  uint32_t waiters(uint64_t line_addr) const;
  // The cycle the line's data arrive, or kNotScheduled. Throws Error if not outstanding.
  uint64_t fill_cycle(uint64_t line_addr) const;

  // Sets the arrival cycle of an outstanding line. Throws Error if it is not outstanding.
  void schedule_fill(uint64_t line_addr, uint64_t fill_cycle);

  // Lines whose data have arrived by `cycle` (fill cycle <= cycle), oldest entry first.
  std::vector<uint64_t> arrived(uint64_t cycle) const;

  // Frees the entry of `line_addr` in `cycle`. Throws Error if it is not outstanding.
  void retire(uint64_t line_addr, uint64_t cycle);

  const MshrStats& stats() const { return stats_; }
  const std::string& name() const { return name_; }

 private:
  struct Entry {
    uint64_t line_addr = 0;
    uint64_t alloc_cycle = 0;
    uint64_t fill_cycle = kNotScheduled;
    uint32_t waiters = 0;
  };
  const Entry* find(uint64_t line_addr) const;
  Entry* find(uint64_t line_addr);

  std::string name_;
  size_t capacity_ = 0;
  std::vector<Entry> entries_;  // allocation order
  MshrStats stats_;
};

}  // namespace edrnr::sim
