#include <gtest/gtest.h>

#include "chip/lfau.h"

namespace edrnr::chip {
namespace {

const Vec3i kPlus{1, 1, 1};

TEST(Lfau, AllRaysInOneVoxelAdvanceTogether) {
  std::array<Vec3i, 4> v{Vec3i{2, 3, 4}, Vec3i{2, 3, 4}, Vec3i{2, 3, 4}, Vec3i{2, 3, 4}};
  LfauSelection s = lfau_select(v, 0xF, kPlus, true);
  EXPECT_EQ(s.selected_mask, 0xF);
  EXPECT_EQ(s.selected_rays(), 4);
  EXPECT_EQ(s.voxel, (Vec3i{2, 3, 4}));
}

TEST(Lfau, LaggingRaysGoFirstAlongX) {
  // Travelling +X: rays 1 and 3 lag at x = 1.
  std::array<Vec3i, 4> v{Vec3i{2, 0, 0}, Vec3i{1, 0, 0}, Vec3i{2, 0, 0}, Vec3i{1, 0, 0}};
  LfauSelection s = lfau_select(v, 0xF, kPlus, true);
  EXPECT_EQ(s.selected_mask, 0b1010);
  EXPECT_EQ(s.voxel, (Vec3i{1, 0, 0}));
  // Travelling -X the rays at x = 2 lag.
  s = lfau_select(v, 0xF, Vec3i{-1, 1, 1}, true);
  EXPECT_EQ(s.selected_mask, 0b0101);
}

TEST(Lfau, TiesOnXAreBrokenByYThenZ) {
  // Same x; ray 2 lags in y (travelling -Y: largest y lags); rays 0 and 2
  // differ in z only if y ties.
  std::array<Vec3i, 4> v{Vec3i{5, 1, 7}, Vec3i{5, 2, 3}, Vec3i{5, 2, 9}, Vec3i{6, 9, 0}};
  LfauSelection s = lfau_select(v, 0xF, Vec3i{1, -1, 1}, true);
  // EN1 keeps rays 0..2 (x = 5), EN2 rays 1 and 2 (y = 2), EN3 ray 1 (z = 3).
  EXPECT_EQ(s.selected_mask, 0b0010);
  EXPECT_EQ(s.voxel, (Vec3i{5, 2, 3}));
}

TEST(Lfau, InactiveRaysNeverTakePart) {
  std::array<Vec3i, 4> v{Vec3i{0, 0, 0}, Vec3i{1, 0, 0}, Vec3i{1, 0, 0}, Vec3i{0, 0, 0}};
  LfauSelection s = lfau_select(v, 0b0110, kPlus, true);
  EXPECT_EQ(s.selected_mask, 0b0110);
  EXPECT_EQ(lfau_select(v, 0, kPlus, true).selected_mask, 0);
}

TEST(Lfau, WithoutLagFirstTheLowestActiveRayLeads) {
  std::array<Vec3i, 4> v{Vec3i{3, 0, 0}, Vec3i{1, 0, 0}, Vec3i{3, 0, 0}, Vec3i{1, 0, 0}};
  LfauSelection s = lfau_select(v, 0xF, kPlus, false);
  EXPECT_EQ(s.selected_mask, 0b0101);
  EXPECT_EQ(s.voxel, (Vec3i{3, 0, 0}));
  s = lfau_select(v, 0b1010, kPlus, false);
  EXPECT_EQ(s.selected_mask, 0b1010);
}

}  // namespace
}  // namespace edrnr::chip
