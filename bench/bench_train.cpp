// Trainer kernels: MLP forward / backward per chunk of samples, feature
// pyramid interpolation and gradient scatter, a whole training step.
#include <benchmark/benchmark.h>

#include <vector>

#include "model/mlp.h"
#include "train/feature_grid.h"
#include "train/mlp_kernels.h"
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

}  // namespace
}  // namespace edrnr::train

BENCHMARK_MAIN();
