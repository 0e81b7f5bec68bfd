// The RP buffer's packets: reset() for reuse, and slots exchanged without copying.
#include <gtest/gtest.h>

#include <memory>

#include "chip/rp_buffer.h"

namespace edrnr::chip {
namespace {

// A ray with every field away from its default.
RayState dirty_ray() {
  RayState r;
  r.valid = true;
  r.terminated = true;
  r.ray = {{1.5, 2.5, 3.5}, {0.25, -0.5, 0.75}};
  r.world_dir = {0.1, 0.2, 0.3};
  r.k = 17;
  r.k_end = 90;
  r.transmittance = 12345;
  r.color = {7, 8, 9};
  r.dir_code = {1, 2, 3, 4};
  r.dir_input.x = {5, 6};
  r.dir_input.saturations = 3;
  r.dir_input.terms.term = {10, 11, 12};
  r.dir_input.terms.saturations = 2;
  r.dir_input.terms_tme = reinterpret_cast<const Tme*>(&r);
  r.dir_input.terms_mlp = 4;
  r.exit_memo.axis[1][0] = {8, 20, 24};
  r.exit_memo_limit = 90;
  return r;
}

// Every field but the exit memo's crossings is the default's again, and the
// vectors keep their storage.
TEST(RayState, ResetGivesTheDefaultRayAndKeepsTheVectorsStorage) {
  RayState r = dirty_ray();
  const int32_t* code = r.dir_code.data();
  const int32_t* x = r.dir_input.x.data();
  const int64_t* term = r.dir_input.terms.term.data();
  r.reset();
  const RayState d;
  EXPECT_EQ(r.valid, d.valid);
  EXPECT_EQ(r.terminated, d.terminated);
  EXPECT_EQ(r.ray.origin, d.ray.origin);
  EXPECT_EQ(r.ray.dir, d.ray.dir);
  EXPECT_EQ(r.world_dir, d.world_dir);
  EXPECT_EQ(r.k, d.k);
  EXPECT_EQ(r.k_end, d.k_end);
  EXPECT_EQ(r.transmittance, d.transmittance);
  EXPECT_EQ(r.color, d.color);
  EXPECT_TRUE(r.dir_code.empty());
  EXPECT_TRUE(r.dir_input.x.empty());
  EXPECT_EQ(r.dir_input.saturations, 0u);
  EXPECT_TRUE(r.dir_input.terms.term.empty());
  EXPECT_EQ(r.dir_input.terms.saturations, 0u);
  EXPECT_EQ(r.dir_input.terms_tme, nullptr);
  EXPECT_EQ(r.dir_input.terms_mlp, d.dir_input.terms_mlp);
  EXPECT_EQ(r.exit_memo_limit, d.exit_memo_limit);  // -1: the memo's user clears the crossings first
  EXPECT_FALSE(r.live());
  // The storage stays for the next packet built in this one.
  EXPECT_EQ(r.dir_code.data(), code);
  EXPECT_EQ(r.dir_input.x.data(), x);
  EXPECT_EQ(r.dir_input.terms.term.data(), term);
}

TEST(RayPacket, ResetGivesTheDefaultPacket) {
  RayPacket p;
  p.pixels.sequence = 9;
  p.pixels.x = {1, 2, 3, 4};
  p.pixels.valid_mask = 0xF;
  p.travel_sign = {-1, -1, 1};
  for (RayState& r : p.rays) r = dirty_ray();
  p.rays[2].terminated = false;
  EXPECT_EQ(p.live_mask(), 0x4);
  p.reset();
  const RayPacket d;
  EXPECT_EQ(p.pixels.sequence, d.pixels.sequence);
  EXPECT_EQ(p.pixels.x, d.pixels.x);
  EXPECT_EQ(p.pixels.valid_mask, d.pixels.valid_mask);
  EXPECT_EQ(p.travel_sign, d.travel_sign);
  EXPECT_EQ(p.live_mask(), 0);
  for (const RayState& r : p.rays) EXPECT_FALSE(r.valid);
}

// exchange() swaps the packet objects themselves: the buffer's slot holds
// the given packet at the same address, and the caller gets the old one.
TEST(RpBuffer, ExchangeSwapsPacketsWithoutCopying) {
  RpBuffer b(2);
  const uint32_t rp = *b.allocate();
  RayPacket* old = &b[rp];
  auto p = std::make_unique<RayPacket>();
  p->pixels.sequence = 42;
  RayPacket* given = p.get();
  b.exchange(rp, p);
  EXPECT_EQ(&b[rp], given);
  EXPECT_EQ(b[rp].pixels.sequence, 42u);
  EXPECT_EQ(p.get(), old);
}

}  // namespace
}  // namespace edrnr::chip
