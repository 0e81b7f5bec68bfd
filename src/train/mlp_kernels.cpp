#include "train/mlp_kernels.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "train/mlp_layer_kernels.h"
#include "train/rng.h"

namespace edrnr::train {
MlpLayout::MlpLayout(const MlpArch& a) : arch(a) {
  const auto& dw = arch.density_widths;
  const auto& cw = arch.color_widths;
  if (dw.size() < 2 || cw.size() < 2) fail("MLP shape: density and colour nets need at least one layer each");
  if (cw.front() != dw.back() + arch.dir_dims())
    fail("MLP shape: colour net input {} is not density output {} + direction encoding {}", cw.front(), dw.back(),
         arch.dir_dims());
  if (cw.back() != 3) fail("MLP shape: colour net output is {}, not 3", cw.back());
  size_t off = 0;
  auto add = [&](const std::vector<int>& widths, std::vector<Layer>& out, int& act_floats) {
    for (size_t i = 1; i < widths.size(); ++i) {
      if (widths[i - 1] <= 0 || widths[i] <= 0) fail("MLP shape: layer widths must be positive");
      Layer l;
      l.in = widths[i - 1];
      l.out = widths[i];
      l.w = off;
      off += size_t(l.in) * size_t(l.out);
      l.b = off;
      off += size_t(l.out);
      act_floats += l.out;
      max_width = std::max({max_width, l.in, l.out});
      out.push_back(l);
    }
  };
  add(dw, density, density_act_floats);
  add(cw, color, color_act_floats);
  param_count = off;
}

std::vector<float> flatten_mlp(const MlpLayout& layout, const MlpF& mlp) {
  std::vector<float> p(layout.param_count);
  auto put = [&](const std::vector<MlpLayout::Layer>& ls, const std::vector<DenseF>& ds) {
    if (ls.size() != ds.size()) fail("MLP has {} layers, expected {}", ds.size(), ls.size());
    for (size_t i = 0; i < ls.size(); ++i) {
      if (ds[i].in != ls[i].in || ds[i].out != ls[i].out || ds[i].w.size() != size_t(ls[i].in) * ls[i].out ||
          ds[i].b.size() != size_t(ls[i].out))
        fail("MLP layer {} has shape {}x{}, expected {}x{}", i, ds[i].out, ds[i].in, ls[i].out, ls[i].in);
      std::copy(ds[i].w.begin(), ds[i].w.end(), p.begin() + ptrdiff_t(ls[i].w));
      std::copy(ds[i].b.begin(), ds[i].b.end(), p.begin() + ptrdiff_t(ls[i].b));
    }
  };
  put(layout.density, mlp.density);
  put(layout.color, mlp.color);
  return p;
}

MlpF unflatten_mlp(const MlpLayout& layout, const float* params) {
  MlpF m;
  auto get = [&](const std::vector<MlpLayout::Layer>& ls, std::vector<DenseF>& ds) {
    for (const auto& l : ls) {
      DenseF d;
      d.in = l.in;
      d.out = l.out;
      d.w.assign(params + l.w, params + l.w + size_t(l.in) * l.out);
      d.b.assign(params + l.b, params + l.b + l.out);
      ds.push_back(std::move(d));
    }
  };
  get(layout.density, m.density);
  get(layout.color, m.color);
  return m;
}

void init_mlp_params(const MlpLayout& layout, uint64_t seed, float* params) {
  std::fill(params, params + layout.param_count, 0.f);
  auto init = [&](const std::vector<MlpLayout::Layer>& ls, uint64_t net) {
    for (size_t li = 0; li < ls.size(); ++li) {
      const auto& l = ls[li];
      bool output = li + 1 == ls.size();
      float a = std::sqrt((output ? 3.f : 6.f) / float(l.in));
      for (size_t i = 0; i < size_t(l.in) * l.out; ++i) {
        uint64_t h = hash3(hash_combine(seed, uint64_t(RngStream::MlpInit)), net * 64 + li, i);
        params[l.w + i] = (2.f * uniform01(h) - 1.f) * a;
      }
    }
  };
  init(layout.density, 0);
  init(layout.color, 1);
}

float int8_row_scale(const float* row, int n) {
  float m = 0.f;
  for (int i = 0; i < n; ++i) m = std::max(m, std::fabs(row[i]));
  return m > 0.f ? m / 127.f : 1.f;
}

int8_t int8_quantize(float w, float scale) {
  float q = std::nearbyint(w / scale);
  return int8_t(std::clamp(q, -127.f, 127.f));
}

void fake_quantize_mlp(const MlpLayout& layout, const float* params, float* out) {
  std::copy(params, params + layout.param_count, out);
  for (const auto* ls : {&layout.density, &layout.color})
    for (const auto& l : *ls)
      for (int o = 0; o < l.out; ++o) {
        const float* row = params + l.w + size_t(o) * l.in;
        float s = int8_row_scale(row, l.in);
        for (int i = 0; i < l.in; ++i) out[l.w + size_t(o) * l.in + i] = float(int8_quantize(row[i], s)) * s;
      }
}

void equalize_mlp(const MlpLayout& layout, float strength, float* params, float* adam_m, float* adam_v) {
  if (strength == 0.f) return;
  auto scale = [&](size_t k, double s) {
    params[k] = float(double(params[k]) * s);
    if (adam_m) adam_m[k] = float(double(adam_m[k]) / s);
    if (adam_v) adam_v[k] = float(double(adam_v[k]) / (s * s));
  };
  for (const auto* ls : {&layout.density, &layout.color})
    for (size_t l = 0; l + 1 < ls->size(); ++l) {
      const MlpLayout::Layer& a = (*ls)[l];
      const MlpLayout::Layer& b = (*ls)[l + 1];
      std::vector<double> col_max(size_t(b.in), 0.0);
      for (int o = 0; o < b.out; ++o)
        for (int j = 0; j < b.in; ++j)
          col_max[size_t(j)] = std::max(col_max[size_t(j)], std::fabs(double(params[b.w + size_t(o) * b.in + j])));
      double log_sum = 0.0;
      int nonzero = 0;
      for (double c : col_max)
        if (c > 0.0) {
          log_sum += std::log(c);
          ++nonzero;
        }
      if (nonzero == 0) continue;
      const double g = std::exp(log_sum / nonzero);
      for (int j = 0; j < b.in; ++j) {
        if (col_max[size_t(j)] == 0.0) continue;
        const double s = std::clamp(std::pow(g / col_max[size_t(j)], double(strength)), 1.0 / 256, 256.0);
        for (int o = 0; o < b.out; ++o) scale(b.w + size_t(o) * b.in + size_t(j), s);
        for (int i = 0; i < a.in; ++i) scale(a.w + size_t(j) * a.in + size_t(i), 1.0 / s);
        scale(a.b + size_t(j), 1.0 / s);
      }
    }
}

MlpQ quantize_mlp(const MlpLayout& layout, const float* params, const std::vector<float>& layer_in_max_abs) {
  MlpQ q;
  size_t layer_index = 0;
  auto quant = [&](const std::vector<MlpLayout::Layer>& ls, std::vector<DenseQ>& ds) {
    for (const auto& l : ls) {
      DenseQ d;
      d.in = l.in;
      d.out = l.out;
      d.w.resize(size_t(l.in) * l.out);
      d.w_scale.resize(size_t(l.out));
      for (int o = 0; o < l.out; ++o) {
        const float* row = params + l.w + size_t(o) * l.in;
        float s = int8_row_scale(row, l.in);
        d.w_scale[size_t(o)] = s;
        for (int i = 0; i < l.in; ++i) d.w[size_t(o) * l.in + i] = int8_quantize(row[i], s);
      }
      d.b.assign(params + l.b, params + l.b + l.out);
      float m = layer_index < layer_in_max_abs.size() ? layer_in_max_abs[layer_index] : 0.f;
      d.in_scale = m > 0.f ? m / 127.f : 1.f;
      ++layer_index;
      ds.push_back(std::move(d));
    }
  };
  quant(layout.density, q.density);
  quant(layout.color, q.color);
  return q;
}

void net_forward(const std::vector<MlpLayout::Layer>& layers, const float* params, const float* x0, float* acts,
                 int last_rows, const float* in_steps) {
  const float* x = x0;
  float* y = acts;
  for (size_t k = 0; k < layers.size(); ++k) {
    const auto& l = layers[k];
    const bool last = k + 1 == layers.size();
    const int rows = last && last_rows >= 0 ? std::min(last_rows, l.out) : l.out;
    mlp_layer_forward(params + l.w, params + l.b, l.in, rows, x, y, !last);
    if (in_steps && !last) quantize_block(y, l.out, in_steps[k + 1], 0.f, kActivationMax);
    x = y;
    y += size_t(l.out) * kLanes;
  }
}

void net_backward(const std::vector<MlpLayout::Layer>& layers, const float* params, const float* x0, const float* acts,
                  const float* d_last, float* grad, float* d_x0, float* scratch) {
  const int n = int(layers.size());
  // Offsets of each layer's output inside acts.
  std::vector<size_t> act_off(size_t(n), 0);
  for (int k = 1; k < n; ++k) act_off[size_t(k)] = act_off[size_t(k - 1)] + size_t(layers[size_t(k - 1)].out) * kLanes;
  const float* dy = d_last;
  float* bufs[2] = {scratch, nullptr};
  int max_w = 0;
  for (const auto& l : layers) max_w = std::max({max_w, l.in, l.out});
  bufs[1] = scratch + size_t(max_w) * kLanes;
  int cur = 0;
  for (int k = n - 1; k >= 0; --k) {
    const auto& l = layers[size_t(k)];
    const float* x = k == 0 ? x0 : acts + act_off[size_t(k - 1)];
    mlp_layer_param_grad(x, dy, l.in, l.out, grad + l.w, grad + l.b);
    if (k > 0) {
      float* dx = bufs[cur];
      mlp_layer_input_grad(params + l.w, l.in, l.out, dy, x, dx);
      dy = dx;
      cur ^= 1;
    } else if (d_x0) {
      mlp_layer_input_grad(params + l.w, l.in, l.out, dy, nullptr, d_x0);
    }
  }
}

size_t net_backward_scratch_floats(const MlpLayout& layout) { return 2 * size_t(layout.max_width) * kLanes; }

float block_max_abs(const float* block, int rows, int n) {
  float m = 0.f;
  for (int r = 0; r < rows; ++r)
    for (int l = 0; l < n; ++l) m = std::max(m, std::fabs(block[size_t(r) * kLanes + l]));
  return m;
}

}  // namespace edrnr::train
