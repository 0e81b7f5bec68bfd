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

// The statistics of cycles without a push or pop are counted when the FIFO
// next changes (or by account_until). Worked by hand, capacity 2, latency 2:
// pushes in cycles 1 and 2 (visible from 3 and 4), a pop in cycle 5, cycles
// 0..7 counted. Held: 0, 1, 2, 2, 2, 1, 1, 1 (sum 10); full in 2, 3, 4;
// nothing visible in 0, 1, 2.
TEST(Fifo, CyclesBetweenChangesAreCountedWithTheStateTheyHad) {
  Fifo<int> f("q", 2, 2);
  f.push(1, 1);
  f.push(2, 2);
  EXPECT_EQ(f.pop(5), 1);
  f.account_until(8);
  const FifoStats& s = f.stats();
  EXPECT_EQ(s.sampled_cycles, 8u);
  EXPECT_EQ(s.full_cycles, 3u);
  EXPECT_EQ(s.empty_cycles, 3u);
  EXPECT_EQ(s.occupancy_sum, 10u);
  f.account_until(8);  // already counted
  EXPECT_EQ(f.stats().sampled_cycles, 8u);
}

// The same random pushes and pops, one FIFO sampled every cycle and one
// counted only at its changes and at the end: the same statistics.
TEST(Fifo, CountingAtChangesEqualsSamplingEveryCycle) {
  Fifo<int> every("a", 3, 2), lazy("b", 3, 2);
  uint32_t rng = 12345;
  auto next = [&] { return rng = rng * 1664525u + 1013904223u, rng >> 16; };
  const uint64_t cycles = 5000;
  for (uint64_t c = 0; c < cycles; ++c) {
    if (next() % 3 == 0 && every.can_pop(c)) {
      EXPECT_EQ(every.pop(c), lazy.pop(c));
    }
    if (next() % 2 == 0 && every.can_push()) {
      every.push(int(c), c);
      lazy.push(int(c), c);
    }
    every.sample(c);
  }
  lazy.account_until(cycles);
  const FifoStats &a = every.stats(), &b = lazy.stats();
  EXPECT_EQ(a.sampled_cycles, b.sampled_cycles);
  EXPECT_EQ(a.full_cycles, b.full_cycles);
  EXPECT_EQ(a.empty_cycles, b.empty_cycles);
  EXPECT_EQ(a.occupancy_sum, b.occupancy_sum);
  EXPECT_GT(a.full_cycles, 0u);  // the sequence exercises every case
  EXPECT_GT(a.empty_cycles, 0u);
  EXPECT_GT(a.pops, 1000u);
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
