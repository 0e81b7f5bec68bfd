#include <gtest/gtest.h>

#include <algorithm>
#include <list>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/stats.h"
#include "sim/cache.h"
#include "sim/mshr.h"

namespace edrnr::sim {
namespace {

// 2 sets x 2 ways of 64-byte lines. Line n lives in set n % 2, so lines 0, 2,
// 4, 6 (addresses 0, 128, 256, 384) share set 0.
CacheConfig tiny(Replacement r) {
  CacheConfig c;
  c.name = "tiny";
  c.size_bytes = 256;
  c.line_bytes = 64;
  c.ways = 2;
  c.replacement = r;
  c.mshr_entries = 4;
  c.hit_rate_window_cycles = 0;
  return c;
}

constexpr uint64_t A = 0, B = 128, C = 256, D = 384;  // lines 0, 2, 4, 6: set 0

// One request through the MSHR path, filled at once. Returns "hit", "miss"
// (filled into a free way) or "evict N" (line N replaced).
std::string step(Cache& cache, uint64_t addr, uint64_t cycle) {
  CacheOutcome o = cache.access(addr, cycle);
  if (o == CacheOutcome::Hit) return "hit";
  EXPECT_EQ(o, CacheOutcome::MissIssued);
  FillResult f = cache.fill(addr, cycle);
  EXPECT_TRUE(f.filled);
  return f.evicted ? "evict " + std::to_string(f.victim_line) : "miss";
}

TEST(Cache, Geometry) {
  Cache c(tiny(Replacement::Lru));
  EXPECT_EQ(c.sets(), 2u);
  EXPECT_EQ(c.ways(), 2u);
  EXPECT_EQ(c.line_number(200), 3u);
  EXPECT_EQ(c.set_of(200), 1u);
  EXPECT_EQ(Cache(mlp_cache_config()).sets(), 1u);  // 8448 / 64 = 132 lines, fully associative
  EXPECT_EQ(Cache(mlp_cache_config()).ways(), 132u);
  EXPECT_EQ(Cache(feature_cache_config()).ways(), 256u);    // 256 lines of 1 KB, fully associative
  EXPECT_EQ(Cache(micro_grid_cache_config()).sets(), 32u);  // 128 lines of 64 B, 4 ways
}

TEST(Cache, LruSequence) {
  Cache c(tiny(Replacement::Lru));
  EXPECT_EQ(step(c, A, 0), "miss");
  EXPECT_EQ(step(c, B, 1), "miss");
  EXPECT_EQ(step(c, A, 2), "hit");
  EXPECT_EQ(step(c, C, 3), "evict 2");  // B is least recently used
  EXPECT_EQ(step(c, A, 4), "hit");
  EXPECT_EQ(step(c, B, 5), "evict 4");  // C
  EXPECT_EQ(step(c, C, 6), "evict 0");  // A
  EXPECT_EQ(step(c, 64, 7), "miss");    // line 1, set 1, untouched by set 0
  EXPECT_EQ(c.stats().hits, 2u);
  EXPECT_EQ(c.stats().misses, 6u);
  EXPECT_EQ(c.stats().evictions, 3u);
  EXPECT_EQ(c.stats().hits + c.stats().misses, c.stats().accesses);
}

TEST(Cache, FifoSequence) {
  Cache c(tiny(Replacement::Fifo));
  EXPECT_EQ(step(c, A, 0), "miss");
  EXPECT_EQ(step(c, B, 1), "miss");
  EXPECT_EQ(step(c, A, 2), "hit");      // a hit does not refresh a FIFO entry
  EXPECT_EQ(step(c, C, 3), "evict 0");  // A was filled first
  EXPECT_EQ(step(c, A, 4), "evict 2");  // B
  EXPECT_EQ(step(c, B, 5), "evict 4");  // C
  EXPECT_EQ(step(c, C, 6), "evict 0");  // A
  EXPECT_EQ(c.stats().hits, 1u);
  EXPECT_EQ(c.stats().misses, 6u);
}

// One set of 4 ways. Tree PLRU after using ways 0,1,2,3 then way 1 points to
// way 2 (root -> right half, which was touched longer ago; node 3 -> way 2),
// whereas true LRU would evict way 0.
TEST(Cache, TreePlruDiffersFromLru) {
  CacheConfig cfg = tiny(Replacement::TreePlru);
  cfg.ways = 4;
  Cache plru(cfg);
  cfg.replacement = Replacement::Lru;
  Cache lru(cfg);
  for (Cache* c : {&plru, &lru}) {
    for (uint64_t line = 0; line < 4; ++line) EXPECT_EQ(step(*c, line * 64, line), "miss");
    EXPECT_EQ(step(*c, 64, 4), "hit");
  }
  EXPECT_EQ(step(plru, 4 * 64, 5), "evict 2");
  EXPECT_EQ(step(lru, 4 * 64, 5), "evict 0");
}

TEST(Cache, TreePlruSkipsReservedHalf) {
  CacheConfig cfg = tiny(Replacement::TreePlru);
  cfg.ways = 4;
  Cache c(cfg);
  for (uint64_t line = 0; line < 4; ++line) step(c, line * 64, line);
  step(c, 64, 4);  // tree points at way 2 (line 2)
  c.reserve(2 * 64);
  c.reserve(3 * 64);                         // the whole right half is reserved
  EXPECT_EQ(step(c, 4 * 64, 5), "evict 0");  // left half, node 2 points at way 0
}

TEST(Cache, RandomIsSeededAndAvoidsReservedLines) {
  CacheConfig cfg = tiny(Replacement::Random);
  cfg.ways = 4;
  cfg.random_seed = 42;
  Cache a(cfg), b(cfg);
  for (uint64_t line = 0; line < 4; ++line) {
    step(a, line * 64, 0);
    step(b, line * 64, 0);
  }
  a.reserve(0);
  b.reserve(0);
  std::vector<uint64_t> victims_a, victims_b;
  for (uint64_t i = 4; i < 200; ++i) {
    FillResult fa = a.fill(i * 64, i), fb = b.fill(i * 64, i);
    ASSERT_TRUE(fa.evicted);
    ASSERT_NE(fa.victim_line, 0u);  // the reserved line stays
    victims_a.push_back(fa.victim_line);
    victims_b.push_back(fb.victim_line);
  }
  EXPECT_EQ(victims_a, victims_b);
  EXPECT_TRUE(a.lookup(0));
}

// Independent LRU model: one recency list per set.
TEST(Cache, LruMatchesReferenceModel) {
  CacheConfig cfg;
  cfg.size_bytes = 4 * 4 * 32;
  cfg.line_bytes = 32;
  cfg.ways = 4;  // 4 sets
  Cache c(cfg);
  std::vector<std::list<uint64_t>> sets(4);
  uint64_t expected_hits = 0;
  uint64_t x = 12345;
  for (uint64_t i = 0; i < 3000; ++i) {
    x = x * 6364136223846793005ull + 1442695040888963407ull;
    uint64_t addr = (x >> 33) % (40 * 32);  // 40 distinct lines
    uint64_t line = addr / 32;
    auto& s = sets[line % 4];
    auto it = std::find(s.begin(), s.end(), line);
    if (it != s.end()) {
      ++expected_hits;
      s.erase(it);
    } else if (s.size() == 4) {
      s.pop_back();
    }
    s.push_front(line);
    c.access_and_fill(addr, i);
  }
  EXPECT_EQ(c.stats().hits, expected_hits);
  EXPECT_EQ(c.stats().accesses, 3000u);
  EXPECT_EQ(c.stats().hits + c.stats().misses, 3000u);
}

TEST(Cache, LookupHasNoSideEffects) {
  Cache c(tiny(Replacement::Lru));
  step(c, A, 0);
  step(c, B, 1);
  EXPECT_TRUE(c.lookup(A));  // must not refresh A
  EXPECT_FALSE(c.lookup(C));
  EXPECT_EQ(c.stats().accesses, 2u);
  EXPECT_EQ(step(c, C, 2), "evict 0");
  EXPECT_FALSE(c.mshr().outstanding(C / 64));
}

TEST(Cache, ReservationPreventsEviction) {
  Cache c(tiny(Replacement::Lru));
  step(c, A, 0);
  step(c, B, 1);
  c.reserve(B);  // B is most recently used, A would be the LRU victim...
  c.reserve(A);  // ...but both are reserved now
  c.release(B);
  EXPECT_EQ(c.reservations(A), 1u);
  EXPECT_EQ(c.reservations(B), 0u);
  EXPECT_EQ(step(c, C, 2), "evict 2");  // A is protected, so B goes
  EXPECT_THROW(c.release(B), Error);
}

TEST(Cache, FillWaitsWhileEverySetWayIsReserved) {
  Cache c(tiny(Replacement::Lru));
  step(c, A, 0);
  step(c, B, 1);
  c.reserve(A);
  c.reserve(B);
  EXPECT_EQ(c.access(C, 5), CacheOutcome::MissIssued);
  c.schedule_fill(C, 10);
  EXPECT_TRUE(c.tick(9).empty());  // not arrived yet
  EXPECT_EQ(c.stats().fill_stalls, 0u);
  EXPECT_TRUE(c.tick(10).empty());  // arrived, but the set is fully reserved
  EXPECT_EQ(c.stats().fill_stalls, 1u);
  EXPECT_TRUE(c.mshr().outstanding(C / 64));
  EXPECT_EQ(c.access(C, 11), CacheOutcome::MissMerged);  // still outstanding
  EXPECT_TRUE(c.tick(11).empty());
  EXPECT_EQ(c.stats().fill_stalls, 2u);
  c.release(A);
  EXPECT_EQ(c.tick(12), std::vector<uint64_t>{C / 64});
  EXPECT_TRUE(c.lookup(C));
  EXPECT_FALSE(c.lookup(A));
  EXPECT_TRUE(c.lookup(B));
  EXPECT_EQ(c.mshr().occupancy(), 0u);
  EXPECT_EQ(c.mshr().stats().latency_cycles_sum, 7u);  // allocated in 5, filled in 12
  // A direct fill into a fully reserved set reports it instead of evicting.
  c.reserve(C);
  FillResult f = c.fill(D, 13);
  EXPECT_FALSE(f.filled);
  EXPECT_EQ(c.stats().fill_stalls, 3u);
}

TEST(Cache, ReservationOfLineNotYetResidentHoldsAfterFill) {
  Cache c(tiny(Replacement::Lru));
  c.reserve(A);  // a requester waits for A
  step(c, A, 0);
  step(c, B, 1);
  step(c, B, 2);
  EXPECT_EQ(step(c, C, 3), "evict 2");  // A is the LRU line but reserved
}

TEST(Cache, MshrMergesAndStallsWhenFull) {
  CacheConfig cfg = tiny(Replacement::Lru);
  cfg.mshr_entries = 2;
  Cache c(cfg);
  EXPECT_EQ(c.access(0, 0), CacheOutcome::MissIssued);
  EXPECT_EQ(c.access(64, 0), CacheOutcome::MissIssued);
  EXPECT_EQ(c.access(32, 1), CacheOutcome::MissMerged);  // same line as address 0
  EXPECT_EQ(c.access(0, 2), CacheOutcome::MissMerged);
  EXPECT_EQ(c.access(128, 2), CacheOutcome::MissStalled);
  const CacheStats& s = c.stats();
  EXPECT_EQ(s.accesses, 4u);  // the stalled request is retried, not counted
  EXPECT_EQ(s.misses, 4u);
  EXPECT_EQ(s.misses_issued, 2u);
  EXPECT_EQ(s.misses_merged, 2u);
  EXPECT_EQ(s.mshr_full_stalls, 1u);
  EXPECT_EQ(c.mshr().waiters(0), 3u);
  EXPECT_EQ(c.mshr().waiters(1), 1u);

  c.schedule_fill(64, 30);
  c.schedule_fill(0, 20);
  EXPECT_EQ(c.tick(25), std::vector<uint64_t>{0});
  EXPECT_EQ(c.access(0, 26), CacheOutcome::Hit);
  EXPECT_EQ(c.access(128, 26), CacheOutcome::MissIssued);  // an entry is free again
  EXPECT_EQ(c.tick(40), std::vector<uint64_t>{1});
  EXPECT_EQ(s.hits + s.misses, s.accesses);
  EXPECT_THROW(c.schedule_fill(4096, 50), Error);  // no outstanding miss
}

TEST(Cache, PrefetchIsUncountedAndFeedsLaterHits) {
  CacheConfig cfg = tiny(Replacement::Lru);
  cfg.mshr_entries = 2;
  Cache c(cfg);
  EXPECT_EQ(c.prefetch(0, 0), CacheOutcome::MissIssued);
  EXPECT_EQ(c.prefetch(32, 0), CacheOutcome::MissMerged);  // the same line is outstanding
  EXPECT_EQ(c.prefetch(64, 0), CacheOutcome::MissIssued);
  EXPECT_EQ(c.prefetch(128, 0), CacheOutcome::MissStalled);  // both MSHR entries busy
  EXPECT_EQ(c.stats().accesses, 0u);
  EXPECT_EQ(c.stats().mshr_full_stalls, 0u);
  EXPECT_EQ(c.stats().prefetches_issued, 2u);
  // A demand access to a prefetched line in flight merges; after the fill it hits.
  EXPECT_EQ(c.access(64, 1), CacheOutcome::MissMerged);
  c.schedule_fill(0, 5);
  c.schedule_fill(64, 5);
  c.tick(5);
  EXPECT_EQ(c.prefetch(0, 6), CacheOutcome::Hit);
  EXPECT_EQ(c.access(0, 6), CacheOutcome::Hit);
  EXPECT_EQ(c.stats().accesses, 2u);
  EXPECT_EQ(c.stats().hits, 1u);
  EXPECT_EQ(c.stats().hits + c.stats().misses, c.stats().accesses);
}

TEST(Mshr, AllocatesMergesRefusesAndRetires) {
  Mshr m("m", 2);
  EXPECT_EQ(m.on_miss(7, 0), MshrOutcome::Allocated);
  EXPECT_EQ(m.on_miss(9, 1), MshrOutcome::Allocated);
  EXPECT_EQ(m.on_miss(7, 2), MshrOutcome::Merged);
  EXPECT_EQ(m.on_miss(8, 2), MshrOutcome::Full);
  EXPECT_EQ(m.fill_cycle(7), Mshr::kNotScheduled);
  m.schedule_fill(9, 10);
  m.schedule_fill(7, 10);
  EXPECT_TRUE(m.arrived(9).empty());
  EXPECT_EQ(m.arrived(10), (std::vector<uint64_t>{7, 9}));  // allocation order
  m.retire(9, 12);
  m.retire(7, 14);
  EXPECT_EQ(m.occupancy(), 0u);
  EXPECT_EQ(m.stats().allocations, 2u);
  EXPECT_EQ(m.stats().merges, 1u);
  EXPECT_EQ(m.stats().full_stalls, 1u);
  EXPECT_DOUBLE_EQ(m.stats().mean_latency_cycles(), (11.0 + 14.0) / 2.0);
  EXPECT_THROW(m.retire(7, 15), Error);
  EXPECT_THROW(Mshr("zero", 0), Error);
}

TEST(BankConflicts, CountsDistinctRowsPerBank) {
  // bank 0: rows {1, 2} -> 1 conflict; bank 1: one row; bank 2: rows {3, 4, 7} -> 2.
  std::vector<BankAccess> acc = {{0, 1}, {0, 1}, {0, 2}, {1, 5}, {2, 3}, {2, 4}, {2, 7}};
  BankCycleResult r = count_bank_conflicts(acc);
  EXPECT_EQ(r.conflicts, 3u);
  EXPECT_EQ(r.cycles, 3u);
  EXPECT_EQ(count_bank_conflicts({}).cycles, 0u);
  // Eight accesses to eight different banks: conflict free, one cycle.
  std::vector<BankAccess> spread;
  for (uint64_t b = 0; b < 8; ++b) spread.push_back({b, 100 - b});
  EXPECT_EQ(count_bank_conflicts(spread).conflicts, 0u);
  EXPECT_EQ(count_bank_conflicts(spread).cycles, 1u);
}

TEST(BankConflicts, AddressInterleaveAndStatistics) {
  CacheConfig cfg = tiny(Replacement::Lru);
  cfg.size_bytes = 1024;
  cfg.banks = 4;  // 64-byte interleave: byte address a -> word a / 64 -> bank word % 4
  Cache c(cfg);
  EXPECT_EQ(c.bank_of(256).bank, 0u);
  EXPECT_EQ(c.bank_of(256).row, 1u);
  std::vector<uint64_t> addrs = {0, 64, 256, 8};  // 0 and 8 share bank 0 row 0; 256 is bank 0 row 1
  BankCycleResult r = c.present_cycle(std::span<const uint64_t>(addrs));
  EXPECT_EQ(r.conflicts, 1u);
  EXPECT_EQ(r.cycles, 2u);
  std::vector<BankAccess> none;
  c.present_cycle(std::span<const BankAccess>(none));
  EXPECT_EQ(c.stats().bank_access_cycles, 1u);
  EXPECT_EQ(c.stats().bank_accesses, 4u);
  EXPECT_EQ(c.stats().bank_conflicts, 1u);
  EXPECT_EQ(c.stats().bank_conflict_cycles, 1u);
  std::vector<BankAccess> bad = {{4, 0}};
  EXPECT_THROW(c.present_cycle(std::span<const BankAccess>(bad)), Error);
}

TEST(Cache, HitRateSeriesByWindow) {
  CacheConfig cfg = tiny(Replacement::Lru);
  cfg.hit_rate_window_cycles = 10;
  Cache c(cfg);
  c.access_and_fill(A, 0);   // miss, window 0
  c.access_and_fill(A, 5);   // hit, window 0
  c.access_and_fill(A, 25);  // hit, window 2
  const auto& s = c.hit_rate_series();
  ASSERT_EQ(s.size(), 3u);
  EXPECT_EQ(s[0].start_cycle, 0u);
  EXPECT_EQ(s[0].hits, 1u);
  EXPECT_EQ(s[0].accesses, 2u);
  EXPECT_EQ(s[1].start_cycle, 10u);
  EXPECT_EQ(s[1].accesses, 0u);
  EXPECT_EQ(s[2].start_cycle, 20u);
  EXPECT_EQ(s[2].hits, 1u);
  nlohmann::json j = hit_rate_series_json(s, 10);
  EXPECT_EQ(j["window_cycles"], 10);
  EXPECT_DOUBLE_EQ(j["windows"][0]["hit_rate"].get<double>(), 0.5);
  EXPECT_TRUE(j["windows"][1]["hit_rate"].is_null());
}

TEST(Cache, ExportsStatistics) {
  Cache c(tiny(Replacement::Lru));
  step(c, A, 0);
  step(c, A, 1);
  StatsRegistry reg;
  c.export_stats(reg, "cache.tiny");
  EXPECT_EQ(reg.get("cache.tiny.accesses"), 2.0);
  EXPECT_EQ(reg.get("cache.tiny.hits"), 1.0);
  EXPECT_EQ(reg.get("cache.tiny.hit_rate"), 0.5);
  EXPECT_EQ(reg.get("cache.tiny.misses_issued"), 1.0);
}

TEST(Cache, ConfigErrorsNameTheField) {
  auto message = [](CacheConfig cfg) {
    try {
      validate(cfg);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CacheConfig cfg = tiny(Replacement::Lru);
  cfg.size_bytes = 250;
  EXPECT_NE(message(cfg).find("size_bytes (250) is not a multiple of line_bytes (64)"), std::string::npos);
  cfg = tiny(Replacement::Lru);
  cfg.ways = 3;
  EXPECT_NE(message(cfg).find("'tiny'"), std::string::npos);
  EXPECT_NE(message(cfg).find("ways (3)"), std::string::npos);
  cfg = tiny(Replacement::TreePlru);
  cfg.size_bytes = 64 * 6;
  cfg.ways = kFullyAssociative;  // 6 ways
  EXPECT_NE(message(cfg).find("power of two"), std::string::npos);
  cfg = tiny(Replacement::Lru);
  cfg.banks = 0;
  EXPECT_NE(message(cfg).find("banks"), std::string::npos);
  cfg = tiny(Replacement::Lru);
  cfg.mshr_entries = 0;
  EXPECT_THROW(Cache{cfg}, Error);
  EXPECT_EQ(parse_replacement("plru", "caches.mlp.replacement"), Replacement::TreePlru);
  try {
    parse_replacement("mru", "caches.mlp.replacement");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("caches.mlp.replacement"), std::string::npos);
  }
}

}  // namespace
}  // namespace edrnr::sim
