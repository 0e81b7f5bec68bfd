#include <gtest/gtest.h>

#include <vector>

#include "chip/zorg.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

TEST(Zorg, MortonInterleaveByHand) {
  // x = 101b to bits 0 and 4, y = 011b to bits 1 and 3: 10001b + 01010b = 27.
  EXPECT_EQ(morton_interleave(5, 3), 27u);
  uint32_t x, y;
  morton_split(27, x, y);
  EXPECT_EQ(x, 5u);
  EXPECT_EQ(y, 3u);
  morton_split((1u << 22) - 1, x, y);  // all 22 counter bits set
  EXPECT_EQ(x, 2047u);
  EXPECT_EQ(y, 2047u);
}

TEST(Zorg, FourByFourIsTheZCurveOfQuads) {
  Zorg z(4, 4);
  ASSERT_EQ(z.packet_count(), 4u);
  const int qx[4] = {0, 1, 0, 1}, qy[4] = {0, 0, 1, 1};
  for (int p = 0; p < 4; ++p) {
    ASSERT_FALSE(z.done());
    EXPECT_EQ(z.counter(), uint32_t(4 * p));
    PixelQuad q = z.next();
    EXPECT_EQ(q.sequence, uint32_t(p));
    EXPECT_EQ(q.valid_mask, 0xF);
    // Rays in a quad: (0,0), (1,0), (0,1), (1,1).
    for (int r = 0; r < 4; ++r) {
      EXPECT_EQ(q.x[r], 2 * qx[p] + (r & 1));
      EXPECT_EQ(q.y[r], 2 * qy[p] + (r >> 1));
    }
  }
  EXPECT_TRUE(z.done());
  EXPECT_EQ(z.skipped_quads(), 0u);
}

TEST(Zorg, SkipsOutOfBoundsQuadsBeforeTheyAreIssued) {
  // 6x2 pixels = 3x1 quads. Z order of quads: (0,0)=0, (1,0)=1, then codes 2
  // (0,1) and 3 (1,1) are out of bounds, then (2,0)=4.
  Zorg z(6, 2);
  ASSERT_EQ(z.packet_count(), 3u);
  PixelQuad a = z.next(), b = z.next();
  EXPECT_EQ(a.x[0], 0);
  EXPECT_EQ(b.x[0], 2);
  EXPECT_EQ(z.counter(), 16u);  // quad code 4 -> pixel counter 16
  PixelQuad c = z.next();
  EXPECT_EQ(c.x[0], 4);
  EXPECT_EQ(c.y[0], 0);
  EXPECT_EQ(z.skipped_quads(), 2u);
  EXPECT_EQ(z.jumps(), 1u);
  EXPECT_TRUE(z.done());
}

TEST(Zorg, JumpsOverWholeBlocks) {
  // A 2x2-quad grid inside the 1024x1024 curve: after code 3 nothing else is
  // in bounds, and the end is reached in one search.
  EXPECT_EQ(zorg_next_in_bounds(4, 2, 2), 1u << 20);
  // 3x3 quads: code 4 = (2,0) is in; 5 = (3,0) is out, 6 = (2,1) in.
  EXPECT_EQ(zorg_next_in_bounds(5, 3, 3), 6u);
  // From (3,1) = 7 the next in bounds is (0,2) = 8.
  EXPECT_EQ(zorg_next_in_bounds(7, 3, 3), 8u);
  // The last in-bounds code of a 3x3 grid is (2,2) = 12: 13 = (3,2), 14 =
  // (2,3), 15 = (3,3) and every code from 16 on lie outside.
  EXPECT_EQ(zorg_next_in_bounds(13, 3, 3), 1u << 20);
}

// Every pixel exactly once, no out-of-bounds pixel, quads in increasing Z
// order, and the issued quads are exactly the in-bounds quads of the curve.
void check_coverage(int w, int h) {
  SCOPED_TRACE(testing::Message() << w << "x" << h);
  Zorg z(w, h);
  const uint32_t qw = uint32_t(w + 1) / 2, qh = uint32_t(h + 1) / 2;
  EXPECT_EQ(z.packet_count(), qw * qh);
  std::vector<uint8_t> seen(size_t(w) * h, 0);
  uint32_t issued = 0;
  int64_t last_code = -1;
  bool ok = true;
  while (!z.done()) {
    const uint32_t code = z.counter() >> 2;
    ok &= int64_t(code) > last_code;
    last_code = code;
    PixelQuad q = z.next();
    ok &= q.valid_mask != 0;
    for (int r = 0; r < 4; ++r) {
      if (!(q.valid_mask >> r & 1)) continue;
      ok &= q.x[r] < w && q.y[r] < h;
      if (q.x[r] < w && q.y[r] < h) ++seen[size_t(q.y[r]) * w + q.x[r]];
    }
    ++issued;
  }
  EXPECT_TRUE(ok);
  EXPECT_EQ(issued, qw * qh);
  size_t wrong = 0;
  for (uint8_t s : seen) wrong += s != 1;
  EXPECT_EQ(wrong, 0u);
  // The partial quads are exactly those on an odd edge.
  Zorg again(w, h);
  int partial = 0;
  while (!again.done()) partial += again.next().valid_mask != 0xF;
  int expect_partial = int((w % 2 ? qh : 0) + (h % 2 ? qw : 0) - ((w % 2 && h % 2) ? 1 : 0));
  EXPECT_EQ(partial, expect_partial);
}

TEST(Zorg, CoversManyImageSizes) {
  for (auto [w, h] : std::vector<std::pair<int, int>>{
           {1, 1}, {3, 5}, {5, 3}, {2, 2}, {7, 1}, {1, 9}, {17, 33}, {64, 64}, {100, 37}, {800, 800}, {1920, 1080}})
    check_coverage(w, h);
}

TEST(Zorg, FullSizeImageHasNoSkips) {
  Zorg z(2048, 2048);
  EXPECT_EQ(z.packet_count(), 1u << 20);
  uint32_t n = 0;
  while (!z.done()) {
    z.next();
    ++n;
  }
  EXPECT_EQ(n, 1u << 20);
  EXPECT_EQ(z.skipped_quads(), 0u);
}

TEST(Zorg, RowOrderGroupsFourPixelsOfARow) {
  Zorg z(5, 2, ScanOrder::RowOrder);
  ASSERT_EQ(z.packet_count(), 4u);
  PixelQuad a = z.next();
  EXPECT_EQ(a.valid_mask, 0xF);
  for (int r = 0; r < 4; ++r) {
    EXPECT_EQ(a.x[r], r);
    EXPECT_EQ(a.y[r], 0);
  }
  PixelQuad b = z.next();
  EXPECT_EQ(b.valid_mask, 0x1);
  EXPECT_EQ(b.x[0], 4);
  PixelQuad c = z.next();
  EXPECT_EQ(c.y[0], 1);
  EXPECT_EQ(c.x[3], 3);
  z.next();
  EXPECT_TRUE(z.done());
}

TEST(Zorg, RejectsSizesBeyondElevenBits) {
  EXPECT_THROW(Zorg(0, 4), Error);
  EXPECT_THROW(Zorg(2049, 4), Error);
  EXPECT_THROW(Zorg(4, 2049), Error);
}

}  // namespace
}  // namespace edrnr::chip
