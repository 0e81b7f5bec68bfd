#pragma once
// Set-associative cache tag store with MSHR, reservation monitor and banks, for
// the cycle simulator (docs/caches.md). Only tags are modelled: the data stay
// in the functional model.
//
// Addresses are byte addresses; a line is line_bytes bytes and its line number
// is addr / line_bytes. A line lives in set (line number % sets).
//
// Timing contract, per request in cycle c:
// - access(addr, c) on a resident line is a hit; the data are ready in
//   c + hit_latency_cycles.
// - Otherwise it is a miss handed to the MSHR: MissIssued (the caller sends
//   one DRAM request for line_number(addr) and later calls schedule_fill with
//   the arrival cycle), MissMerged (the line is already outstanding: no DRAM
//   request), or MissStalled (MSHR full: nothing is counted as an access; the
//   requester retries in a later cycle).
// - tick(c) moves lines whose data have arrived into the cache (allocate on
//   fill). The victim is the policy's choice among the set's ways that hold no
//   reserved line; if every way of the set is reserved the fill waits in the
//   MSHR (counted as a fill stall) and is retried on the next tick.
// Reservation monitor: reserve(addr) / release(addr) keep a per-line count,
// also for lines not yet resident (a requester reserves the line it waits on),
// and a line with a non-zero count is never chosen as a victim.
// Bank conflicts: present_cycle() takes all bank accesses of one cycle. Accesses
// to the same row of a bank share one read; each further distinct row in a
// bank is a conflict and costs one more cycle.
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "core/stats.h"
#include "sim/mshr.h"

namespace edrnr::sim {

enum class Replacement {
  Lru,       // least recently used (hit or fill) way
  Fifo,      // oldest filled way
  Random,    // uniform among eligible ways, from a seeded generator
  TreePlru,  // binary-tree pseudo-LRU (ways must be a power of two)
};

// "lru", "fifo", "random", "plru".
std::string_view replacement_name(Replacement r);
// Parses a replacement name; throws Error naming `field` and the accepted names.
Replacement parse_replacement(std::string_view text, std::string_view field);

inline constexpr uint64_t kFullyAssociative = 0;

struct CacheConfig {
  std::string name = "cache";
  uint64_t size_bytes = 0;
  uint64_t line_bytes = 64;
  uint64_t ways = 4;  // kFullyAssociative (0): one set holding every line
  Replacement replacement = Replacement::Lru;
  uint64_t random_seed = 1;  // only for Replacement::Random
  uint64_t banks = 1;
  uint64_t bank_interleave_bytes = 0;  // consecutive bytes per bank; 0 = line_bytes
  size_t mshr_entries = 8;
  uint64_t hit_latency_cycles = 1;
  uint64_t hit_rate_window_cycles = 1000;  // window of the hit-rate series; 0 = no series
};

// Throws Error naming the cache and the field if the geometry is inconsistent:
// size_bytes and line_bytes non-zero, size a multiple of the line size, the
// line count a multiple of ways, ways a power of two for TreePlru, banks and
// mshr_entries at least 1.
void validate(const CacheConfig& config);

// The chip's caches of Table I (sizes from the paper; line size, ways, banks
// interleave and MSHR depth are this model's assumptions, see docs/caches.md).
CacheConfig micro_grid_cache_config();  // 8 KB
CacheConfig feature_cache_config();     // 256 KB in 8 banks of 32 KB
CacheConfig mlp_cache_config();         // 8.25 KB

enum class CacheOutcome { Hit, MissIssued, MissMerged, MissStalled };

struct FillResult {
  bool filled = false;       // false: every way of the set holds a reserved line; retry later
  bool evicted = false;      // a valid line was replaced
  uint64_t victim_line = 0;  // its line number, when evicted
};

// One bank access of a cycle: bank index and row (word) inside the bank.
struct BankAccess {
  uint64_t bank = 0;
  uint64_t row = 0;
};

struct BankCycleResult {
  uint64_t conflicts = 0;  // accesses that wait behind another row of the same bank
  uint64_t cycles = 0;     // cycles to serve them all: the most distinct rows in one bank (0 if no access)
};

// Counts the conflicts of one cycle's accesses; pure function.
BankCycleResult count_bank_conflicts(std::span<const BankAccess> accesses);

struct HitRateWindow {
  uint64_t start_cycle = 0;
  uint64_t hits = 0;
  uint64_t accesses = 0;
};

struct CacheStats {
  uint64_t accesses = 0;  // hits + misses (stalled requests are not accesses)
  uint64_t hits = 0;
  uint64_t misses = 0;            // issued + merged
  uint64_t misses_issued = 0;     // new MSHR entries = DRAM line requests
  uint64_t misses_merged = 0;     // absorbed by an outstanding MSHR entry
  uint64_t mshr_full_stalls = 0;  // requests refused because the MSHR was full
  uint64_t fills = 0;
  uint64_t evictions = 0;
  uint64_t fill_stalls = 0;         // fill attempts refused: every way of the set reserved
  uint64_t prefetches_issued = 0;   // prefetch() calls that opened an MSHR entry (a DRAM line request each)
  uint64_t bank_access_cycles = 0;  // present_cycle() calls with at least one access
  uint64_t bank_accesses = 0;
  uint64_t bank_conflicts = 0;
  uint64_t bank_conflict_cycles = 0;  // extra cycles the conflicts cost

  double hit_rate() const { return accesses ? double(hits) / double(accesses) : 0.0; }
};

// The hit-rate series as JSON: {"window_cycles": W, "windows": [{"start_cycle",
// "hits", "accesses", "hit_rate"}, ...]}; hit_rate is null for a window with
// no access.
nlohmann::json hit_rate_series_json(const std::vector<HitRateWindow>& series, uint64_t window_cycles);

class Cache {
 public:
  // Validates the config (see validate()).
  explicit Cache(const CacheConfig& config);

  const CacheConfig& config() const { return config_; }
  const std::string& name() const { return config_.name; }
  uint64_t sets() const { return sets_; }
  uint64_t ways() const { return ways_; }
  uint64_t line_number(uint64_t addr) const { return addr / config_.line_bytes; }
  uint64_t set_of(uint64_t addr) const { return line_number(addr) % sets_; }
  // Bank and row of a byte address under the interleave mapping.
  BankAccess bank_of(uint64_t addr) const;

  // True if the line holding `addr` is resident. No side effects.
  bool lookup(uint64_t addr) const;

  // A counted request in `cycle` (see the timing contract above). A hit refreshes
  // the replacement state.
  CacheOutcome access(uint64_t addr, uint64_t cycle);

  // An uncounted request that brings `addr`'s line towards the cache ahead of
  // use (counted only as a prefetch): Hit when resident (the replacement
  // state is left alone), MissIssued when an MSHR entry opens (the caller
  // sends the DRAM request, as for access), MissMerged when the line is
  // already outstanding, MissStalled when the MSHR is full (try again later).
  CacheOutcome prefetch(uint64_t addr, uint64_t cycle);
  // A counted request that, on a miss, fills the line at once without the MSHR
  // (for trace-driven hit-rate studies). Returns true on a hit. If every way of
  // the set is reserved the line is not allocated (a fill stall is counted).
  bool access_and_fill(uint64_t addr, uint64_t cycle);

  // Records when the outstanding miss of `addr`'s line gets its data. Throws
  // Error if the line is not outstanding.
  void schedule_fill(uint64_t addr, uint64_t fill_cycle);

  // Fills every outstanding line whose data have arrived by `cycle`, oldest
  // first, and retires its MSHR entry. Returns the line numbers filled now;
  // lines whose set is fully reserved stay outstanding.
  std::vector<uint64_t> tick(uint64_t cycle);

  // Allocates `addr`'s line now (no-op if resident) and retires its MSHR entry
  // if it has one. See FillResult for a set whose ways are all reserved.
  FillResult fill(uint64_t addr, uint64_t cycle);

  // Reservation monitor.
  void reserve(uint64_t addr);
  // Throws Error if the line holds no reservation.
  void release(uint64_t addr);
  uint32_t reservations(uint64_t addr) const;

  // Counts one cycle's bank accesses by byte address (interleave mapping) or
  // by explicit bank and row (for a custom mapping such as the feature cache's
  // vertex-to-bank allocation), and adds them to the statistics.
  BankCycleResult present_cycle(std::span<const uint64_t> addrs);
  BankCycleResult present_cycle(std::span<const BankAccess> accesses);

  const CacheStats& stats() const { return stats_; }
  const Mshr& mshr() const { return mshr_; }
  // Hit rate per window of hit_rate_window_cycles cycles: window i covers
  // cycles [i * window, (i + 1) * window). Windows with no access are kept.
  const std::vector<HitRateWindow>& hit_rate_series() const { return series_; }

  // Registers the cache's and its MSHR's statistics as "<prefix>.*" in
  // `registry` with their current values; call once, when the run is over.
  void export_stats(StatsRegistry& registry, const std::string& prefix) const;

 private:
  struct Way {
    bool valid = false;
    uint64_t line = 0;
    uint64_t last_use = 0;  // LRU: stamp of the last hit or fill
    uint64_t filled = 0;    // FIFO: stamp of the fill
  };
  Way* way_ptr(uint64_t set, uint64_t way) { return &ways_store_[set * ways_ + way]; }
  void touch(uint64_t set, uint64_t way);
  bool reserved_line(uint64_t line) const;
  // The way to fill in `set`, or ways_ if every way holds a reserved line.
  uint64_t choose_victim(uint64_t set);
  uint64_t plru_victim(uint64_t set);  // among the ways eligible_ marks
  void record(uint64_t cycle, bool hit);
  uint64_t next_random();

  CacheConfig config_;
  uint64_t sets_ = 0;
  uint64_t ways_ = 0;
  uint64_t interleave_bytes_ = 0;
  std::vector<Way> ways_store_;                      // sets_ x ways_
  std::vector<uint8_t> plru_bits_;                   // sets_ x (ways_ - 1), heap order per set
  std::unordered_map<uint64_t, uint64_t> where_;     // resident line -> set * ways_ + way
  std::unordered_map<uint64_t, uint32_t> reserved_;  // line -> reservation count (> 0)
  std::vector<uint8_t> eligible_;                    // choose_victim's scratch: per way, 1 if it may be replaced
  std::vector<uint64_t> plru_count_;                 // plru_victim's scratch: eligible ways per tree node
  uint64_t stamp_ = 0;
  uint64_t random_state_ = 0;
  Mshr mshr_;
  CacheStats stats_;
  std::vector<HitRateWindow> series_;
};

}  // namespace edrnr::sim
