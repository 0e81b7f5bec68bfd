#include <gtest/gtest.h>

#include <vector>

#include "core/error.h"
#include "core/stats.h"
#include "sim/fifo.h"

namespace edrnr::sim {
namespace {

TEST(Fifo, RefusesPushWhenFullAndKeepsOrder) {
  Fifo<int> f("q", 2);
  EXPECT_TRUE(f.can_push());
  f.push(1, 0);
  f.push(2, 0);
  EXPECT_TRUE(f.full());
  EXPECT_FALSE(f.can_push());
  EXPECT_FALSE(f.try_push(3, 0));
  EXPECT_EQ(f.stats().push_stalls, 1u);
  EXPECT_THROW(f.push(3, 0), Error);
  EXPECT_EQ(f.occupancy(), 2u);

  EXPECT_EQ(f.pop(0), 1);
  EXPECT_TRUE(f.try_push(3, 0));
  EXPECT_EQ(f.pop(0), 2);
  EXPECT_EQ(f.pop(0), 3);
  EXPECT_TRUE(f.empty());
  EXPECT_EQ(f.stats().pushes, 3u);
  EXPECT_EQ(f.stats().pops, 3u);
  EXPECT_EQ(f.stats().max_occupancy, 2u);
}

TEST(Fifo, LatencyDelaysVisibility) {
  Fifo<int> f("pipe", 4, 3);
  f.push(10, 10);  // visible from cycle 13
  f.push(11, 11);  // visible from cycle 14
  EXPECT_FALSE(f.can_pop(10));
  EXPECT_FALSE(f.can_pop(12));
  EXPECT_THROW(f.pop(12), Error);
  EXPECT_TRUE(f.can_pop(13));
  EXPECT_EQ(f.pop(13), 10);
  EXPECT_FALSE(f.can_pop(13));
  EXPECT_TRUE(f.can_pop(14));
  EXPECT_EQ(f.front(), 11);
  EXPECT_EQ(f.pop(14), 11);
}

TEST(Fifo, InFlightItemsOccupySpace) {
  Fifo<int> f("pipe", 1, 5);
  f.push(7, 0);
  EXPECT_FALSE(f.can_pop(0));
  EXPECT_FALSE(f.can_push());  // the item is not visible yet but holds its slot
}

TEST(Fifo, SampleCountsFullAndEmptyCycles) {
  Fifo<int> f("q", 1, 1);
  f.push(1, 0);
  f.sample(0);  // full, and the item is not visible before cycle 1
  EXPECT_EQ(f.pop(1), 1);
  f.sample(1);  // empty
  f.sample(2);  // empty
  const FifoStats& s = f.stats();
  EXPECT_EQ(s.sampled_cycles, 3u);
  EXPECT_EQ(s.full_cycles, 1u);
  EXPECT_EQ(s.empty_cycles, 3u);
  EXPECT_EQ(s.occupancy_sum, 1u);
  EXPECT_DOUBLE_EQ(s.mean_occupancy(), 1.0 / 3.0);
}

// A producer that tries to push every cycle into a 2-deep, 1-cycle FIFO whose
// consumer pops only in cycles 2, 5, 8, 11. Worked by hand: pushes in cycles
// 0, 1, 2, 5, 8, 11 (items 0..5); stalls in 3, 4, 6, 7, 9, 10; pops items 0..3.
TEST(Fifo, BackPressureThrottlesProducerToConsumerRate) {
  Fifo<int> f("q", 2, 1);
  int next_item = 0;
  std::vector<int> popped;
  std::vector<uint64_t> push_cycles;
  for (uint64_t c = 0; c < 12; ++c) {
    if (c % 3 == 2 && f.can_pop(c)) popped.push_back(f.pop(c));
    if (f.try_push(next_item, c)) {
      push_cycles.push_back(c);
      ++next_item;
    }
  }
  EXPECT_EQ(popped, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(push_cycles, (std::vector<uint64_t>{0, 1, 2, 5, 8, 11}));
  EXPECT_EQ(f.stats().push_stalls, 6u);
  EXPECT_EQ(f.occupancy(), 2u);
}

TEST(Fifo, RejectsZeroCapacityAndEmptyPop) {
  EXPECT_THROW(Fifo<int>("bad", 0), Error);
  Fifo<int> f("q", 1);
  EXPECT_FALSE(f.can_pop(0));
  EXPECT_THROW(f.pop(0), Error);
  EXPECT_THROW(f.front(), Error);
}

TEST(Fifo, ExportsStatistics) {
  Fifo<int> f("q", 3);
  f.push(1, 0);
  f.sample(0);
  StatsRegistry reg;
  f.export_stats(reg, "fifo.q");
  EXPECT_EQ(reg.get("fifo.q.capacity"), 3.0);
  EXPECT_EQ(reg.get("fifo.q.pushes"), 1.0);
  EXPECT_EQ(reg.get("fifo.q.mean_occupancy"), 1.0);
  EXPECT_EQ(reg.get("fifo.q.empty_cycles"), 0.0);
}

}  // namespace
}  // namespace edrnr::sim
