#include <gtest/gtest.h>

#include <set>
#include <stdexcept>

#include "chip/feature_cache.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

TEST(BankLayout, VertexTypeCountsAreTheOnesOfA5CubedBlock) {
  // Even coordinates 0, 2, 4 (3 choices), odd 1, 3 (2 choices).
  int count[8] = {};
  for (int v = 0; v < kBlockVerts; ++v) ++count[vertex_type(v)];
  const int expect[8] = {27, 18, 18, 12, 18, 12, 12, 8};
  for (int t = 0; t < 8; ++t) EXPECT_EQ(count[t], expect[t]) << "type " << t;
  EXPECT_EQ(vertex_type(block_vertex(1, 0, 1)), 0b101);
}

void check_conflict_free_and_unique(BankMapping mapping, int lines) {
  BankLayout layout(mapping, lines);
  EXPECT_TRUE(layout.corners_one_per_bank()) << bank_mapping_name(mapping);
  for (int line = 0; line < lines; ++line)
    for (int z = 0; z < 4; ++z)
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) {
          auto banks = layout.corner_banks(line, {x, y, z});
          ASSERT_EQ(std::set<int>(banks.begin(), banks.end()).size(), 8u)
              << bank_mapping_name(mapping) << " line " << line << " micro " << x << y << z;
          ASSERT_EQ(BankLayout::conflict_cycles(banks), 0);
        }
  // Every (bank, row) holds exactly one vertex of one line, inside the depth.
  std::set<std::pair<int, int>> used;
  for (int line = 0; line < lines; ++line)
    for (int v = 0; v < kBlockVerts; ++v) {
      int b = layout.bank(line, v), r = layout.row(line, v);
      ASSERT_GE(r, 0);
      ASSERT_LT(r, layout.bank_depth(b));
      ASSERT_TRUE(used.insert({b, r}).second);
    }
}

TEST(BankLayout, BalancedIsConflictFreeAndUniform) {
  check_conflict_free_and_unique(BankMapping::Balanced, 16);
  BankLayout layout(BankMapping::Balanced, 16);
  for (int b = 0; b < kFeatureBanks; ++b) EXPECT_EQ(layout.bank_depth(b), 250) << "bank " << b;  // 2 groups x 125
  // Within one group of 8 lines every bank holds 27+3*18+3*12+8 = 125 rows.
  for (int b = 0; b < kFeatureBanks; ++b) {
    int rows = 0;
    for (int line = 0; line < 8; ++line) rows += layout.rows_used(line, b);
    EXPECT_EQ(rows, 125);
  }
}

TEST(BankLayout, DirectIsConflictFreeButUnbalanced) {
  check_conflict_free_and_unique(BankMapping::Direct, 8);
  BankLayout layout(BankMapping::Direct, 8);
  EXPECT_EQ(layout.bank_depth(0), 27 * 8);
  EXPECT_EQ(layout.bank_depth(3), 12 * 8);
  EXPECT_EQ(layout.bank_depth(7), 8 * 8);
}

TEST(BankLayout, LinearLayoutConflicts) {
  BankLayout layout(BankMapping::Linear, 1);
  // Corners of micro voxel (0,0,0): vertices 0, 1, 5, 6, 25, 26, 30, 31 ->
  // banks 0, 1, 5, 6, 1, 2, 6, 7: banks 1 and 6 are hit twice.
  auto banks = layout.corner_banks(0, {0, 0, 0});
  EXPECT_EQ(banks, (std::array<int, 8>{0, 1, 5, 6, 1, 2, 6, 7}));
  EXPECT_EQ(BankLayout::conflict_cycles(banks), 1);
  EXPECT_FALSE(layout.corners_one_per_bank());
}

TEST(FeatureCache, MshrMergesDuplicateMissesAndStallsWhenFull) {
  FeatureCache cache({.lines = 2, .mshr_entries = 2, .mapping = BankMapping::Balanced});
  EXPECT_EQ(cache.request(7), CacheAccess::MissAllocated);
  EXPECT_EQ(cache.request(7), CacheAccess::MissMerged);
  EXPECT_TRUE(cache.pending(7));
  EXPECT_EQ(cache.reservations(7), 2);
  EXPECT_EQ(cache.request(8), CacheAccess::MissAllocated);
  EXPECT_EQ(cache.request(9), CacheAccess::Stall);  // both MSHR entries open
  EXPECT_EQ(cache.mshr(), (std::vector<uint32_t>{7, 8}));
  cache.fill(7);
  EXPECT_TRUE(cache.present(7));
  EXPECT_EQ(cache.counters().misses, 2u);  // one DRAM fetch for the two requests of block 7
  EXPECT_EQ(cache.counters().merged_misses, 1u);
  EXPECT_EQ(cache.counters().stalls, 1u);
}

TEST(FeatureCache, ReservationMonitorProtectsLinesInUseAndLruPicksTheVictim) {
  FeatureCache cache({.lines = 2, .mshr_entries = 4, .mapping = BankMapping::Balanced});
  cache.request(7);
  cache.request(8);
  cache.fill(7);
  cache.fill(8);
  cache.use(7);
  cache.use(8);
  // Both lines reserved: a new block cannot evict either.
  EXPECT_EQ(cache.request(9), CacheAccess::Stall);
  cache.release(7);
  cache.release(8);
  EXPECT_EQ(cache.request(8), CacheAccess::Hit);  // reserves 8 again
  cache.use(8);
  // 7 is least recently used and unreserved: it goes.
  EXPECT_EQ(cache.request(9), CacheAccess::MissAllocated);
  EXPECT_FALSE(cache.line_of(7).has_value());
  EXPECT_EQ(cache.counters().evictions, 1u);
  // 8 is reserved and 9 pending: nothing can be evicted for 10.
  EXPECT_EQ(cache.request(10), CacheAccess::Stall);
  EXPECT_THROW(cache.use(9), std::logic_error);  // pending, not valid
  EXPECT_THROW(cache.fill(10), std::logic_error);
}

TEST(FeatureCache, RejectsBadSizes) {
  EXPECT_THROW(FeatureCache({.lines = 0, .mshr_entries = 1, .mapping = BankMapping::Balanced}), Error);
  EXPECT_THROW(FeatureCache({.lines = 1, .mshr_entries = 0, .mapping = BankMapping::Balanced}), Error);
  EXPECT_THROW(parse_bank_mapping("rotated", "chip.yaml: feature_cache.bank_mapping"), Error);
}

}  // namespace
}  // namespace edrnr::chip
