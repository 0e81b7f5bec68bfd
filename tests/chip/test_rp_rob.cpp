#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "chip/rp_rob.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

constexpr uint32_t A = 100, B = 200, C = 300;

TEST(RpRob, InsertLabelsEntriesDynamicallyAndRefusesWhenFull) {
  RpRob rob({.entries = 3, .entry_depth = 2, .recent_tags = 2, .reorder = true});
  EXPECT_TRUE(rob.insert(10, A));
  EXPECT_TRUE(rob.insert(11, A));
  EXPECT_TRUE(rob.insert(12, A));  // entry 0 is full: A takes a second entry
  EXPECT_TRUE(rob.insert(13, B));
  EXPECT_EQ(rob.entry_tag(0), A);
  EXPECT_EQ(rob.entry_count(0), 2);
  EXPECT_EQ(rob.entry_tag(1), A);
  EXPECT_EQ(rob.entry_count(1), 1);
  EXPECT_EQ(rob.entry_tag(2), B);
  EXPECT_FALSE(rob.insert(14, C));  // no entry of tag C and no empty entry
  EXPECT_EQ(rob.counters().insert_refusals, 1u);
  EXPECT_TRUE(rob.insert(15, A));  // entry 1 still has room
  EXPECT_EQ(rob.entry_count(1), 2);
  EXPECT_EQ(rob.placeholders(), 5u);
  // The recorder saw A, A, A, B, A (the refused C is not recorded).
  ASSERT_EQ(rob.recent_tags().size(), 2u);
  EXPECT_EQ(rob.recent_tags()[0], A);
  EXPECT_EQ(rob.recent_tags()[1], B);
}

TEST(RpRob, ScheduleRescheduleRetireSequence) {
  // The paper's literal rule: a tag switches once all its CCRPs have retired.
  RpRob rob({.entries = 3, .entry_depth = 2, .recent_tags = 2, .reorder = true, .switch_when_idle = false});
  for (auto [rp, tag] : {std::pair{10u, A}, {11u, A}, {12u, A}, {13u, B}, {15u, A}}) ASSERT_TRUE(rob.insert(rp, tag));
  // Tag switch: every tag is recent; the entry with the fewest CCRPs (B, 1) wins.
  auto s = rob.schedule();
  ASSERT_TRUE(s);
  EXPECT_EQ(s->rp, 13u);
  EXPECT_EQ(s->tag, B);
  // B's only CCRP is in flight: wait for it.
  EXPECT_FALSE(rob.schedule());
  rob.reschedule(13);
  EXPECT_EQ(rob.schedule()->rp, 13u);
  rob.retire(13);
  EXPECT_FALSE(rob.entry_labelled(2));
  // Switch to A: entries 0 and 1 both hold 2; the lower index wins.
  s = rob.schedule();
  EXPECT_EQ(s->rp, 10u);
  EXPECT_EQ(s->entry, 0);
  // Same tag: the entry with the most free room (both hold 2: entry 0).
  EXPECT_EQ(rob.schedule()->rp, 11u);
  EXPECT_EQ(rob.schedule()->rp, 12u);  // entry 0 has nothing ready: entry 1
  rob.retire(10);                      // entry 0 now holds 1
  EXPECT_EQ(rob.schedule()->rp, 15u);
  rob.reschedule(11);
  EXPECT_EQ(rob.schedule()->rp, 11u);
  // The freed entry takes a new tag.
  EXPECT_TRUE(rob.insert(14, C));
  EXPECT_EQ(rob.entry_tag(2), C);
  // A still has CCRPs in flight (11, 12, 15): C waits.
  EXPECT_FALSE(rob.schedule());
  rob.retire(11);
  rob.retire(12);
  rob.retire(15);
  EXPECT_EQ(rob.schedule()->rp, 14u);
  EXPECT_EQ(rob.counters().schedules, 8u);
  EXPECT_EQ(rob.counters().tag_runs, 3u);  // B B | A A A A A | C
  EXPECT_EQ(rob.counters().reschedules, 2u);
  EXPECT_EQ(rob.counters().retires, 5u);
}

TEST(RpRob, InsertPrefersTheMostOccupiedEntryOfItsTag) {
  RpRob rob({.entries = 2, .entry_depth = 4, .recent_tags = 2, .reorder = true});
  for (uint32_t rp = 1; rp <= 5; ++rp) ASSERT_TRUE(rob.insert(rp, A));  // entry 0: 4, entry 1: 1
  EXPECT_EQ(rob.schedule()->rp, 5u);                                    // switch: fewest CCRPs (entry 1)
  EXPECT_EQ(rob.schedule()->rp, 1u);                                    // entry 1 has nothing ready
  rob.retire(1);                                                        // entry 0: 3, entry 1: 1, both with room
  ASSERT_TRUE(rob.insert(6, A));
  EXPECT_EQ(rob.entry_count(0), 4);
  EXPECT_EQ(rob.entry_count(1), 1);
}

TEST(RpRob, RecentTagsRecorderIsLruAndSteersTagSwitches) {
  RpRob lru({.entries = 4, .entry_depth = 4, .recent_tags = 2, .reorder = true});
  lru.insert(1, A);
  lru.insert(2, B);
  lru.insert(3, C);
  EXPECT_EQ(lru.recent_tags(), (std::deque<uint32_t>{C, B}));
  lru.insert(4, A);
  EXPECT_EQ(lru.recent_tags(), (std::deque<uint32_t>{A, C}));

  // X holds 3 CCRPs but only Y is recent: the recorder picks Y.
  for (uint32_t recorder : {1u, 0u}) {
    RpRob rob({.entries = 2, .entry_depth = 4, .recent_tags = int(recorder), .reorder = true});
    rob.insert(1, A);
    rob.insert(2, A);
    rob.insert(3, A);
    rob.insert(4, B);
    // With the recorder: B (recent). Without: the entry holding the most CCRPs.
    EXPECT_EQ(rob.schedule()->tag, recorder ? B : A);
    EXPECT_EQ(rob.counters().recorder_hits, recorder);
  }
}

TEST(RpRob, TagSwitchRulesOnAHandMadeSequence) {
  // Entries: A holds 3 ready CCRPs, B 1, C 2; the recorder (2 tags) ends as
  // {C, B}. The paper's rule prefers recorder hits and, among them, the entry
  // with the fewest CCRPs: B. "fullest" ignores the recorder: A.
  auto fill = [](RpRob& rob) {
    rob.insert(1, A);
    rob.insert(2, A);
    rob.insert(3, A);
    rob.insert(4, B);
    rob.insert(5, C);
    rob.insert(6, C);
  };
  RpRob paper({.entries = 4, .entry_depth = 4, .recent_tags = 2, .reorder = true, .tag_switch = TagSwitchRule::Paper});
  fill(paper);
  EXPECT_EQ(paper.recent_tags(), (std::deque<uint32_t>{C, B}));
  EXPECT_EQ(paper.schedule()->tag, B);
  RpRob fullest({.entries = 4,
                 .entry_depth = 4,
                 .recent_tags = 2,
                 .reorder = true,
                 .tag_switch = TagSwitchRule::Fullest,
                 .switch_when_idle = false});
  fill(fullest);
  const auto first = fullest.schedule();
  EXPECT_EQ(first->tag, A);
  EXPECT_EQ(fullest.counters().recorder_hits, 0u);
  // It stays on A while A has ready CCRPs, then switches to the fuller of B and C.
  EXPECT_EQ(fullest.schedule()->tag, A);
  EXPECT_EQ(fullest.schedule()->tag, A);
  EXPECT_FALSE(fullest.schedule());  // A's CCRPs are in flight: wait
  for (uint32_t rp : {1u, 2u, 3u}) fullest.retire(rp);
  EXPECT_EQ(fullest.schedule()->tag, C);
  EXPECT_EQ(std::string(tag_switch_rule_name(TagSwitchRule::Fullest)), "fullest");
  EXPECT_EQ(parse_tag_switch_rule("paper", "x"), TagSwitchRule::Paper);
  EXPECT_THROW(parse_tag_switch_rule("lru", "rp_rob.tag_switch"), Error);
}

TEST(RpRob, SwitchWhenIdleLeavesATagWhoseCcrpsAreAllInFlight) {
  for (bool idle : {false, true}) {
    RpRob rob({.entries = 3, .entry_depth = 4, .recent_tags = 0, .reorder = true, .switch_when_idle = idle});
    rob.insert(1, A);
    rob.insert(2, A);
    rob.insert(3, B);
    EXPECT_EQ(rob.schedule()->tag, A);  // no recorder: the fullest entry
    EXPECT_EQ(rob.schedule()->rp, 2u);
    // A's CCRPs are both in flight: the literal rule waits, "idle" serves B.
    const auto next = rob.schedule();
    EXPECT_EQ(bool(next), idle);
    if (!idle) continue;
    EXPECT_EQ(next->tag, B);
    // A's CCRP comes back while B is current; B has nothing ready: back to A.
    rob.reschedule(1);
    EXPECT_EQ(rob.schedule()->rp, 1u);
    EXPECT_EQ(rob.counters().tag_runs, 3u);  // A A | B | A
  }
}

TEST(RpRob, WithoutReorderingItIsAFifo) {
  RpRob rob({.entries = 2, .entry_depth = 2, .recent_tags = 2, .reorder = false});
  EXPECT_TRUE(rob.insert(1, A));
  EXPECT_TRUE(rob.insert(2, B));
  EXPECT_TRUE(rob.insert(3, A));
  EXPECT_TRUE(rob.insert(4, C));
  EXPECT_FALSE(rob.insert(5, C));  // 4 placeholders fill 2 x 2
  EXPECT_EQ(rob.schedule()->rp, 1u);
  rob.reschedule(1);
  EXPECT_EQ(rob.schedule()->rp, 2u);
  EXPECT_EQ(rob.schedule()->rp, 3u);
  EXPECT_EQ(rob.schedule()->rp, 4u);
  EXPECT_EQ(rob.schedule()->rp, 1u);
  EXPECT_FALSE(rob.schedule());
  EXPECT_EQ(rob.counters().tag_runs, 5u);  // A B A C A
}

TEST(RpRob, RejectsBadUseAndBadSizes) {
  RpRob rob({.entries = 2, .entry_depth = 2, .recent_tags = 2, .reorder = true});
  rob.insert(1, A);
  EXPECT_THROW(rob.reschedule(1), std::logic_error);  // ready, not in flight
  EXPECT_THROW(rob.retire(7), std::logic_error);
  EXPECT_THROW(rob.insert(1, B), std::logic_error);
  EXPECT_THROW(RpRob({.entries = 0, .entry_depth = 2, .recent_tags = 2, .reorder = true}), Error);
  EXPECT_THROW(RpRob({.entries = 2, .entry_depth = 0, .recent_tags = 2, .reorder = true}), Error);
}

}  // namespace
}  // namespace edrnr::chip
