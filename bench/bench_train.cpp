// Trainer kernels: MLP forward / backward per chunk of samples, feature
// pyramid interpolation and gradient scatter, a whole training step.
#include <benchmark/benchmark.h>

#include <vector>

#include "model/mlp.h"
#include "train/feature_grid.h"
#include "train/mlp_kernels.h"
#include "train/occupancy_kernels.h"
#include "train/rng.h"

namespace edrnr::train {
namespace {

struct MlpBench {
  MlpLayout layout{default_mlp_arch(16)};
  std::vector<float> params, grad, xd, xc, actd, actc, dz, dxc, scratch;
  MlpBench() {
    params.resize(layout.param_count);
    init_mlp_params(layout, 1, params.data());
    grad.assign(layout.param_count, 0.f);
    xd.resize(size_t(layout.feature_dims()) * kLanes);
    xc.resize(size_t(layout.geo_dims() + layout.dir_dims()) * kLanes);
    for (size_t i = 0; i < xd.size(); ++i) xd[i] = uniform01(mix64(i)) - 0.5f;
    for (size_t i = 0; i < xc.size(); ++i) xc[i] = uniform01(mix64(i + 7)) - 0.5f;
    actd.resize(size_t(layout.density_act_floats) * kLanes);
    actc.resize(size_t(layout.color_act_floats) * kLanes);
    dz.assign(3 * kLanes, 0.01f);
    dxc.resize(xc.size());
    scratch.resize(net_backward_scratch_floats(layout));
  }
};

void BM_MlpForward(benchmark::State& state) {
  MlpBench b;
  for (auto _ : state) {
    net_forward(b.layout.density, b.params.data(), b.xd.data(), b.actd.data());
    net_forward(b.layout.color, b.params.data(), b.xc.data(), b.actc.data());
    benchmark::DoNotOptimize(b.actc.data());
  }
  state.SetItemsProcessed(state.iterations() * kLanes);
}
BENCHMARK(BM_MlpForward);

void BM_MlpBackward(benchmark::State& state) {
  MlpBench b;
  net_forward(b.layout.density, b.params.data(), b.xd.data(), b.actd.data());
  net_forward(b.layout.color, b.params.data(), b.xc.data(), b.actc.data());
  std::vector<float> dgeo(size_t(b.layout.geo_dims()) * kLanes), dfeat(b.xd.size());
  for (auto _ : state) {
    net_backward(b.layout.color, b.params.data(), b.xc.data(), b.actc.data(), b.dz.data(), b.grad.data(), b.dxc.data(),
                 b.scratch.data());
    std::copy(b.dxc.begin(), b.dxc.begin() + ptrdiff_t(dgeo.size()), dgeo.begin());
    net_backward(b.layout.density, b.params.data(), b.xd.data(), b.actd.data(), dgeo.data(), b.grad.data(),
                 dfeat.data(), b.scratch.data());
    benchmark::DoNotOptimize(dfeat.data());
  }
  state.SetItemsProcessed(state.iterations() * kLanes);
}
BENCHMARK(BM_MlpBackward);

void BM_PyramidInterpolate(benchmark::State& state) {
  FeaturePyramid pyr(256, {32, 64, 128, 256}, 1, 0.1f);
  std::vector<Vec3f> pts(4096);
  for (size_t i = 0; i < pts.size(); ++i)
    pts[i] = {256.f * uniform01(mix64(3 * i)), 256.f * uniform01(mix64(3 * i + 1)),
              256.f * uniform01(mix64(3 * i + 2))};
  float out[16];
  size_t i = 0;
  for (auto _ : state) {
    const Vec3f& p = pts[i++ & 4095];
    pyr.interpolate(p, {int(p.x), int(p.y), int(p.z)}, out);
    benchmark::DoNotOptimize(out);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PyramidInterpolate);

// The occupancy refresh's row kernel: kLanes cells of one micro row (every
// other x, as a sweep part) through the 4 levels, rows in sweep order; the
// scalar interpolation of the same cells for comparison.
struct RefreshRows {
  FeaturePyramid pyr{256, {32, 64, 128, 256}, 1, 0.1f};
  std::vector<PyramidLevelView> views;
  float px[kLanes], py[kLanes], pz[kLanes];
  std::vector<float> x0 = std::vector<float>(size_t(16) * kLanes);
  RefreshRows() {
    for (const PyramidLevel& L : pyr.levels()) views.push_back({L.value.data(), L.res, L.shift, true});
  }
  // Cells of chunk i: x = 2 j + 64 (i % 4), y = 2 ((i / 4) % 128), z = 2 (i / 512 % 128).
  void set_up(size_t i, int& xs, int& y, int& z) {
    xs = 64 * int(i % 4), y = 2 * int((i / 4) % 128), z = 2 * int((i / 512) % 128);
    for (int j = 0; j < kLanes; ++j) {
      const uint64_t h = mix64(i * kLanes + size_t(j));
      px[j] = float(xs + 2 * j) + uniform01(h);
      py[j] = float(y) + uniform01(mix64(h));
      pz[j] = float(z) + uniform01(mix64(h + 1));
    }
  }
};

void BM_RefreshInterpolateRow(benchmark::State& state) {
  RefreshRows r;
  size_t i = 0;
  for (auto _ : state) {
    int xs, y, z;
    r.set_up(i++, xs, y, z);
    refresh_interpolate_row(r.views.data(), 4, xs, y, z, kLanes, r.px, r.py, r.pz, r.x0.data());
    benchmark::DoNotOptimize(r.x0.data());
  }
  state.SetItemsProcessed(state.iterations() * kLanes);
}
BENCHMARK(BM_RefreshInterpolateRow);

void BM_RefreshInterpolateScalar(benchmark::State& state) {
  RefreshRows r;
  size_t i = 0;
  float out[16];
  for (auto _ : state) {
    int xs, y, z;
    r.set_up(i++, xs, y, z);
    for (int j = 0; j < kLanes; ++j) {
      r.pyr.interpolate({r.px[j], r.py[j], r.pz[j]}, {xs + 2 * j, y, z}, out);
      benchmark::DoNotOptimize(out);
    }
  }
  state.SetItemsProcessed(state.iterations() * kLanes);
}
BENCHMARK(BM_RefreshInterpolateScalar);

}  // namespace
}  // namespace edrnr::train

BENCHMARK_MAIN();
