#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>

#include "core/error.h"
#include "core/metrics.h"

namespace edrnr {
namespace {

constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;

// Deterministic pseudo-random image with values in [0, 1).
Image noise_image(int w, int h, int c, uint32_t seed) {
  Image img(w, h, c);
  uint32_t s = seed;
  for (float& v : img.data) {
    s = s * 1664525u + 1013904223u;
    v = float(s >> 8) / float(1u << 24);
  }
  return img;
}

// ---- PSNR -----------------------------------------------------------------------

TEST(Psnr, ConstantOffset) {
  // 0.6f - 0.5f is 0.1 to float precision: MSE 0.01, PSNR 20 dB.
  EXPECT_NEAR(psnr(Image(7, 5, 3, 0.5f), Image(7, 5, 3, 0.6f)), 20.0, 1e-5);
  // An exactly representable offset of 1/8: PSNR = 20 log10(8) = 60 log10(2).
  EXPECT_NEAR(psnr(Image(7, 5, 3, 0.25f), Image(7, 5, 3, 0.375f)), 60 * 0.30102999566398120, 1e-12);
  // Symmetric.
  EXPECT_EQ(psnr(Image(3, 3, 3, 0.375f), Image(3, 3, 3, 0.25f)), psnr(Image(3, 3, 3, 0.25f), Image(3, 3, 3, 0.375f)));
}

TEST(Psnr, AveragesOverAllChannels) {
  // Only the green channel of half the pixels differs, by 0.5: MSE = 0.25 / 6,
  // PSNR = 10 log10(24).
  Image a(4, 2, 3, 0.f), b(4, 2, 3, 0.f);
  for (int x = 0; x < 4; ++x) b.at(x, 0)[1] = 0.5f;
  EXPECT_NEAR(psnr(a, b), 10 * std::log10(24.0), 1e-12);
}

TEST(Psnr, IdenticalIsInfinite) {
  Image a = noise_image(5, 4, 3, 7);
  EXPECT_EQ(psnr(a, a), std::numeric_limits<double>::infinity());
}

TEST(Psnr, ShapeMismatchThrows) {
  EXPECT_THROW(psnr(Image(4, 4, 3), Image(4, 5, 3)), Error);
  EXPECT_THROW(psnr(Image(4, 4, 3), Image(5, 4, 3)), Error);
  EXPECT_THROW(psnr(Image(4, 4, 3), Image(4, 4, 4)), Error);
  EXPECT_THROW(psnr(Image(), Image()), Error);
}

// ---- SSIM -----------------------------------------------------------------------

TEST(Ssim, IdenticalImagesGiveOne) {
  Image a = noise_image(23, 17, 3, 11);
  EXPECT_NEAR(ssim(a, a), 1.0, 1e-15);
}

TEST(Ssim, ConstantImagesGiveLuminanceTerm) {
  // No variance: SSIM = (2ab + C1) / (a^2 + b^2 + C1).
  double a = 0.25, b = 0.75;
  double expected = (2 * a * b + kC1) / (a * a + b * b + kC1);
  EXPECT_NEAR(ssim(Image(15, 12, 3, float(a)), Image(15, 12, 3, float(b))), expected, 1e-12);
  EXPECT_NEAR(ssim(Image(11, 11, 1, 0.f), Image(11, 11, 1, 1.f)), kC1 / (1 + kC1), 1e-12);
}

// One 11x11 window (so exactly one SSIM value per channel) holding
// x = a + d*s and y = b + e*s, where s = sign(column - 5). s is odd about the
// window centre, so its Gaussian-weighted mean is 0, and s^2 = 1 except in the
// centre column, so its weighted variance is v = 1 - g5, g5 being the centre
// tap of the normalized 1-D Gaussian. Then mu_x = a, mu_y = b,
// var_x = d^2 v, var_y = e^2 v, cov = d e v.
TEST(Ssim, ClosedFormSingleWindow) {
  double tap_sum = 1;
  for (int k = 1; k <= 5; ++k) tap_sum += 2 * std::exp(-(k * k) / (2 * 1.5 * 1.5));
  double v = 1 - 1 / tap_sum;

  // Per channel: a, d, b, e (dyadic, so the float images hold them exactly).
  const double p[3][4] = {{0.5, 0.25, 0.375, 0.125}, {0.25, 0.125, 0.75, -0.0625}, {0.625, 0, 0.125, 0.25}};
  Image x(11, 11, 3), y(11, 11, 3);
  for (int row = 0; row < 11; ++row)
    for (int col = 0; col < 11; ++col) {
      double s = col < 5 ? -1 : (col > 5 ? 1 : 0);
      for (int c = 0; c < 3; ++c) {
        x.at(col, row)[c] = float(p[c][0] + p[c][1] * s);
        y.at(col, row)[c] = float(p[c][2] + p[c][3] * s);
      }
    }
  double expected = 0;
  for (int c = 0; c < 3; ++c) {
    double a = p[c][0], d = p[c][1], b = p[c][2], e = p[c][3];
    double luminance = (2 * a * b + kC1) / (a * a + b * b + kC1);
    double structure = (2 * d * e * v + kC2) / ((d * d + e * e) * v + kC2);
    expected += luminance * structure / 3;
  }
  EXPECT_NEAR(ssim(x, y), expected, 1e-12);
  EXPECT_NEAR(ssim(y, x), expected, 1e-12);
}

// A direct evaluation: every valid 11x11 window, 2-D weights normalized over
// the window, two-pass (centred) variances. Written independently of the
// separable implementation.
double ssim_by_windows(const Image& x, const Image& y) {
  double w[11][11], total = 0;
  for (int i = 0; i < 11; ++i)
    for (int j = 0; j < 11; ++j) {
      double r2 = (i - 5) * (i - 5) + (j - 5) * (j - 5);
      w[i][j] = std::exp(-r2 / 4.5);
      total += w[i][j];
    }
  for (auto& row : w)
    for (double& v : row) v /= total;

  double sum = 0;
  int count = 0;
  for (int c = 0; c < x.channels; ++c)
    for (int y0 = 0; y0 + 11 <= x.height; ++y0)
      for (int x0 = 0; x0 + 11 <= x.width; ++x0) {
        double mx = 0, my = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            mx += w[i][j] * x.at(x0 + j, y0 + i)[c];
            my += w[i][j] * y.at(x0 + j, y0 + i)[c];
          }
        double vx = 0, vy = 0, cxy = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            double dx = x.at(x0 + j, y0 + i)[c] - mx, dy = y.at(x0 + j, y0 + i)[c] - my;
            vx += w[i][j] * dx * dx;
            vy += w[i][j] * dy * dy;
            cxy += w[i][j] * dx * dy;
          }
        sum += (2 * mx * my + kC1) * (2 * cxy + kC2) / ((mx * mx + my * my + kC1) * (vx + vy + kC2));
        ++count;
      }
  return sum / count;
}

TEST(Ssim, MatchesDirectWindowEvaluation) {
  Image x = noise_image(24, 19, 3, 1);
  Image y = noise_image(24, 19, 3, 2);
  // y: a blend of x and independent noise, so SSIM lands well inside (0, 1).
  for (size_t i = 0; i < y.data.size(); ++i) y.data[i] = 0.7f * x.data[i] + 0.3f * y.data[i];
  double direct = ssim_by_windows(x, y);
  EXPECT_GT(direct, 0.2);
  EXPECT_LT(direct, 0.99);
  EXPECT_NEAR(ssim(x, y), direct, 1e-10);

  Image unrelated = noise_image(24, 19, 3, 3);
  EXPECT_NEAR(ssim(x, unrelated), ssim_by_windows(x, unrelated), 1e-10);
}

TEST(Ssim, ShapeErrors) {
  EXPECT_THROW(ssim(Image(12, 12, 3), Image(12, 13, 3)), Error);
  EXPECT_THROW(ssim(Image(12, 12, 3), Image(12, 12, 1)), Error);
  // Smaller than one 11x11 window.
  EXPECT_THROW(ssim(Image(10, 20, 3), Image(10, 20, 3)), Error);
  EXPECT_THROW(ssim(Image(20, 10, 3), Image(20, 10, 3)), Error);
}

}  // namespace
}  // namespace edrnr
