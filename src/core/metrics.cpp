#include "core/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/error.h"

namespace edrnr {

namespace {

void check_same_shape(const Image& a, const Image& b, const char* metric) {
  if (a.width != b.width || a.height != b.height || a.channels != b.channels)
    fail("{}: image sizes differ ({}x{}x{} vs {}x{}x{})", metric, a.width, a.height, a.channels, b.width, b.height,
         b.channels);
  if (a.data.empty()) fail("{}: the images are empty", metric);
  if (a.data.size() != size_t(a.width) * a.height * a.channels || b.data.size() != a.data.size())
    fail("{}: image data does not match its {}x{}x{} size", metric, a.width, a.height, a.channels);
}

constexpr int kSsimWindow = 11;
constexpr double kSsimSigma = 1.5;
constexpr double kSsimK1 = 0.01, kSsimK2 = 0.03;

// The 1-D Gaussian taps, normalized to sum to 1; the 2-D window is their outer
// product.
std::vector<double> gaussian_taps() {
  std::vector<double> taps(kSsimWindow);
  double sum = 0;
  int half = kSsimWindow / 2;
  for (int i = 0; i < kSsimWindow; ++i) {
    double t = (i - half) / kSsimSigma;
    taps[i] = std::exp(-0.5 * t * t);
    sum += taps[i];
  }
  for (double& t : taps) t /= sum;
  return taps;
}

// 'valid' separable filtering of one w x h plane: the result is
// (w - n + 1) x (h - n + 1), each value a weighted mean of an n x n window.
std::vector<double> filter_valid(const std::vector<double>& plane, int w, int h, const std::vector<double>& taps) {
  int n = int(taps.size());
  int ow = w - n + 1, oh = h - n + 1;
  std::vector<double> rows(size_t(ow) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < ow; ++x) {
      double s = 0;
      for (int k = 0; k < n; ++k) s += taps[k] * plane[size_t(y) * w + x + k];
      rows[size_t(y) * ow + x] = s;
    }
  std::vector<double> out(size_t(ow) * oh);
  for (int y = 0; y < oh; ++y)
    for (int x = 0; x < ow; ++x) {
      double s = 0;
      for (int k = 0; k < n; ++k) s += taps[k] * rows[size_t(y + k) * ow + x];
      out[size_t(y) * ow + x] = s;
    }
  return out;
}

// Sum of the SSIM map of one channel over its valid windows.
double ssim_channel_sum(const Image& a, const Image& b, int channel, const std::vector<double>& taps) {
  int w = a.width, h = a.height;
  size_t n = size_t(w) * h;
  std::vector<double> x(n), y(n), xx(n), yy(n), xy(n);
  for (size_t i = 0; i < n; ++i) {
    x[i] = a.data[i * a.channels + channel];
    y[i] = b.data[i * b.channels + channel];
    xx[i] = x[i] * x[i];
    yy[i] = y[i] * y[i];
    xy[i] = x[i] * y[i];
  }
  std::vector<double> mu_x = filter_valid(x, w, h, taps), mu_y = filter_valid(y, w, h, taps);
  std::vector<double> e_xx = filter_valid(xx, w, h, taps), e_yy = filter_valid(yy, w, h, taps);
  std::vector<double> e_xy = filter_valid(xy, w, h, taps);

  const double c1 = kSsimK1 * kSsimK1, c2 = kSsimK2 * kSsimK2;  // data range 1
  double sum = 0;
  for (size_t i = 0; i < mu_x.size(); ++i) {
    double mx = mu_x[i], my = mu_y[i];
    // Rounding can make E[x^2] - mu^2 slightly negative, or the covariance
    // slightly larger than Cauchy-Schwarz allows: clamp both.
    double var_x = std::max(0.0, e_xx[i] - mx * mx);
    double var_y = std::max(0.0, e_yy[i] - my * my);
    double cov = e_xy[i] - mx * my;
    double cov_bound = std::sqrt(var_x * var_y);
    cov = std::clamp(cov, -cov_bound, cov_bound);
    double num = (2 * mx * my + c1) * (2 * cov + c2);
    double den = (mx * mx + my * my + c1) * (var_x + var_y + c2);
    sum += num / den;
  }
  return sum;
}

}  // namespace

double psnr(const Image& a, const Image& b) {
  check_same_shape(a, b, "psnr");
  double sum_sq = 0;
  for (size_t i = 0; i < a.data.size(); ++i) {
    double d = double(a.data[i]) - double(b.data[i]);
    sum_sq += d * d;
  }
  double mse = sum_sq / double(a.data.size());
  if (mse == 0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

double ssim(const Image& a, const Image& b) {
  check_same_shape(a, b, "ssim");
  if (a.width < kSsimWindow || a.height < kSsimWindow)
    fail("ssim: images must be at least {}x{} pixels, got {}x{}", kSsimWindow, kSsimWindow, a.width, a.height);
  std::vector<double> taps = gaussian_taps();
  std::vector<double> channel_sums(a.channels);
#pragma omp parallel for schedule(static, 1)
  for (int c = 0; c < a.channels; ++c) channel_sums[c] = ssim_channel_sum(a, b, c, taps);
  double sum = 0;
  for (double s : channel_sums) sum += s;
  double windows = double(a.width - kSsimWindow + 1) * double(a.height - kSsimWindow + 1);
  return sum / (windows * a.channels);
}

}  // namespace edrnr
