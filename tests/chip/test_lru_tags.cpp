// The LRU tag store against a plain list kept most recent first.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "chip/lru_tags.h"

namespace edrnr::chip {
namespace {

TEST(LruTags, EvictsTheLeastRecentByHand) {
  LruTags t(2);
  EXPECT_FALSE(t.access(5));
  EXPECT_FALSE(t.access(9));
  EXPECT_TRUE(t.access(5));   // 5 most recent, 9 least
  EXPECT_FALSE(t.access(3));  // evicts 9
  EXPECT_FALSE(t.contains(9));
  EXPECT_TRUE(t.contains(5));
  EXPECT_TRUE(t.access(3));
  EXPECT_EQ(t.hits(), 2u);
  EXPECT_EQ(t.misses(), 3u);
  LruTags none(0);
  EXPECT_FALSE(none.access(1));
  EXPECT_FALSE(none.access(1));
  EXPECT_EQ(none.misses(), 2u);
}

// Random streams over tag ranges a little larger than the capacity (many
// evictions), far larger (mostly misses) and with tags that collide in the
// table's low bits: every answer and every tag kept as the plain list says.
TEST(LruTags, MatchesAPlainListOnRandomStreams) {
  std::mt19937_64 rng(11);
  for (size_t capacity : {size_t(1), size_t(2), size_t(7), size_t(64), size_t(1024)}) {
    for (uint64_t range : {uint64_t(capacity + capacity / 4 + 1), uint64_t(8 * capacity + 3)}) {
      for (uint64_t stride : {uint64_t(1), uint64_t(1) << 20}) {
        LruTags t(capacity);
        std::vector<uint64_t> plain;  // most recent first
        uint64_t hits = 0;
        for (int i = 0; i < 20000; ++i) {
          const uint64_t tag = (rng() % range) * stride;
          const auto it = std::find(plain.begin(), plain.end(), tag);
          const bool hit = it != plain.end();
          if (hit) plain.erase(it);
          plain.insert(plain.begin(), tag);
          if (plain.size() > capacity) plain.pop_back();
          hits += hit;
          ASSERT_EQ(t.access(tag), hit) << capacity << " " << range << " " << i;
        }
        EXPECT_EQ(t.hits(), hits);
        EXPECT_GT(hits, 0u);
        for (uint64_t tag = 0; tag < range; ++tag)
          ASSERT_EQ(t.contains(tag * stride), std::find(plain.begin(), plain.end(), tag * stride) != plain.end());
      }
    }
  }
}

}  // namespace
}  // namespace edrnr::chip
