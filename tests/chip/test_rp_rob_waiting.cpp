// The RP-ROB asked again and again while nothing changes (the CTU retrying a
// refused insert, the FTU polling schedule() every cycle): every refusal is
// counted, and the answer changes as soon as an insert, a schedule, a
// reschedule or a retire changes the buffer.
#include <gtest/gtest.h>

#include "chip/rp_rob.h"

namespace edrnr::chip {
namespace {

constexpr uint32_t A = 100, B = 200, C = 300;

TEST(RpRobWaiting, RepeatedRefusalsAreCountedAndEndWithTheFirstRetire) {
  RpRob rob({.entries = 2, .entry_depth = 1, .recent_tags = 2, .reorder = true});
  ASSERT_TRUE(rob.insert(1, A));
  ASSERT_TRUE(rob.insert(2, B));
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(rob.insert(3, C));
  EXPECT_EQ(rob.counters().insert_refusals, 5u);
  // Another RP or tag is decided afresh (and refused too: both entries are taken).
  EXPECT_FALSE(rob.insert(4, C));
  EXPECT_FALSE(rob.insert(3, A));
  EXPECT_EQ(rob.counters().insert_refusals, 7u);
  // A schedule changes nothing about room: still refused.
  const auto s = rob.schedule();
  ASSERT_TRUE(s.has_value());
  EXPECT_FALSE(rob.insert(3, C));
  // The retire frees an entry: the same insert now succeeds.
  rob.retire(s->rp);
  EXPECT_TRUE(rob.insert(3, C));
  EXPECT_EQ(rob.counters().insert_refusals, 8u);
  EXPECT_EQ(rob.counters().inserts, 3u);
}

TEST(RpRobWaiting, AnEmptyScheduleIsAnsweredAgainAfterEachChange) {
  // The paper's rule: while the current tag has a CCRP in flight nothing is
  // scheduled, however often the FTU asks.
  RpRob rob({.entries = 3, .entry_depth = 2, .recent_tags = 2, .reorder = true, .switch_when_idle = false});
  EXPECT_FALSE(rob.schedule().has_value());  // empty
  ASSERT_TRUE(rob.insert(10, A));
  const auto first = rob.schedule();  // the insert is seen at once
  ASSERT_TRUE(first.has_value());
  EXPECT_EQ(first->rp, 10u);
  ASSERT_TRUE(rob.insert(11, B));
  for (int i = 0; i < 4; ++i) EXPECT_FALSE(rob.schedule().has_value());  // A is in flight
  rob.reschedule(10);                                                    // back, ready: served before B
  const auto again = rob.schedule();
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->rp, 10u);
  EXPECT_FALSE(rob.schedule().has_value());
  rob.retire(10);  // A is done: the tag switches to B
  const auto next = rob.schedule();
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->rp, 11u);
  EXPECT_EQ(next->tag, B);
  EXPECT_EQ(rob.counters().schedules, 3u);
}

}  // namespace
}  // namespace edrnr::chip
