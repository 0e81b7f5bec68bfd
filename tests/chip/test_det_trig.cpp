#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "chip/activation_lut.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

uint64_t bits(double v) {
  uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

// Arguments around every quadrant boundary and at random, in a count that is
// not a multiple of any vector width or of the kernel's chunk.
std::vector<double> trig_arguments() {
  std::vector<double> x = {0.0, -0.0, 1e-300, -1e-300, 0.5, 1.0, 2.0, -2.0, 3.0, 100.0, -1000.5};
  for (int q = -8; q <= 8; ++q) {
    const double b = q * (M_PI / 4);
    x.push_back(b);
    x.push_back(std::nextafter(b, 1e9));
    x.push_back(std::nextafter(b, -1e9));
  }
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-4.0, 4.0);
  while (x.size() < 1001) x.push_back(u(rng));
  return x;
}

TEST(DetSinCos, GivesTheBitsOfTheScalarFunctions) {
  const std::vector<double> x = trig_arguments();
  std::vector<double> s(x.size()), c(x.size());
  det_sin_cos(x.data(), x.size(), s.data(), c.data());
  for (size_t i = 0; i < x.size(); ++i) {
    ASSERT_EQ(bits(s[i]), bits(det_sin(x[i]))) << "sin of " << x[i];
    ASSERT_EQ(bits(c[i]), bits(det_cos(x[i]))) << "cos of " << x[i];
  }
  // Few arguments (one partial vector) take the same path.
  double s3[3], c3[3];
  det_sin_cos(x.data() + 20, 3, s3, c3);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(bits(s3[i]), bits(s[20 + i]));
}

TEST(DetSinCos, AgreesWithTheLibraryToRounding) {
  const std::vector<double> x = trig_arguments();
  std::vector<double> s(x.size()), c(x.size());
  det_sin_cos(x.data(), x.size(), s.data(), c.data());
  for (size_t i = 0; i < x.size(); ++i) {
    const double tol = 4e-16 * std::max(1.0, std::fabs(x[i]));
    EXPECT_NEAR(s[i], std::sin(x[i]), tol) << x[i];
    EXPECT_NEAR(c[i], std::cos(x[i]), tol) << x[i];
  }
}

TEST(DetSinCos, RejectsArgumentsOutsideTheRange) {
  const double x[2] = {1.0, 2e6};
  double s[2], c[2];
  EXPECT_THROW(det_sin_cos(x, 2, s, c), Error);
  const double nan[1] = {std::nan("")};
  EXPECT_THROW(det_sin_cos(nan, 1, s, c), Error);
}

}  // namespace
}  // namespace edrnr::chip
