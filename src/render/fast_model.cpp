#include "render/fast_model.h"

#include <cmath>

#include "core/error.h"
#include "model/mlp.h"
#include "render/fast_kernels.h"

namespace edrnr {
namespace {

// The INT8 direction inputs have the fixed step 1/127 (+-1 is the largest code).
constexpr double kDirectionStep = 1.0 / 127.0;

// Shapes of the layers of one net, laid out from `offset` (advanced).
std::vector<FastLayer> layout_net(const std::vector<int>& widths, size_t& offset, bool int8) {
  std::vector<FastLayer> net;
  for (size_t l = 0; l + 1 < widths.size(); ++l) {
    FastLayer L;
    L.in = widths[l];
    L.out = widths[l + 1];
    L.w = offset;
    offset += size_t(L.in) * size_t(L.out);
    L.b = offset;
    offset += size_t(L.out);
    if (int8) {
      L.m = offset;
      offset += size_t(L.out);
    }
    net.push_back(L);
  }
  return net;
}

void check_dense(const DenseF& d, const FastLayer& L, size_t mlp, const char* net, size_t l) {
  if (d.in != L.in || d.out != L.out || d.w.size() != size_t(d.in) * size_t(d.out) || d.b.size() != size_t(d.out))
    fail("MLP {} {} layer {} is {}x{} with {} weights, mlp_arch says {}x{}", mlp, net, l, d.out, d.in, d.w.size(),
         L.out, L.in);
}

void check_dense(const DenseQ& d, const FastLayer& L, size_t mlp, const char* net, size_t l) {
  if (d.in != L.in || d.out != L.out || d.w.size() != size_t(d.in) * size_t(d.out) || d.b.size() != size_t(d.out) ||
      d.w_scale.size() != size_t(d.out))
    fail("INT8 MLP {} {} layer {} is {}x{} with {} weights, mlp_arch says {}x{}", mlp, net, l, d.out, d.in, d.w.size(),
         L.out, L.in);
  if (!(d.in_scale > 0.f) || !std::isfinite(d.in_scale))
    fail("INT8 MLP {} {} layer {}: input scale {} is not positive and finite", mlp, net, l, d.in_scale);
  for (int o = 0; o < d.out; ++o)
    if (!(d.w_scale[size_t(o)] >= 0.f) || !std::isfinite(d.w_scale[size_t(o)]))
      fail("INT8 MLP {} {} layer {} neuron {}: weight scale {} is not finite and >= 0", mlp, net, l, o,
           d.w_scale[size_t(o)]);
}

void pack_float_net(const std::vector<DenseF>& net, const std::vector<FastLayer>& layout, float* p, size_t mlp,
                    const char* name) {
  if (net.size() != layout.size())
    fail("MLP {} has {} {} layers, mlp_arch says {}", mlp, net.size(), name, layout.size());
  for (size_t l = 0; l < net.size(); ++l) {
    check_dense(net[l], layout[l], mlp, name, l);
    std::copy(net[l].w.begin(), net[l].w.end(), p + layout[l].w);
    std::copy(net[l].b.begin(), net[l].b.end(), p + layout[l].b);
  }
}

// The chip's INT8 form: integer weights, biases in accumulator units (weight
// scale times input step) and one multiplier per neuron to the next layer's
// input step, or to raw outputs in 1/256 steps.
void pack_int8_net(const std::vector<DenseQ>& net, const std::vector<FastLayer>& layout, float* p, size_t mlp,
                   const char* name) {
  if (net.size() != layout.size())
    fail("INT8 MLP {} has {} {} layers, mlp_arch says {}", mlp, net.size(), name, layout.size());
  for (size_t l = 0; l < net.size(); ++l) {
    const DenseQ& d = net[l];
    const FastLayer& L = layout[l];
    check_dense(d, L, mlp, name, l);
    const bool hidden = l + 1 < net.size();
    for (int o = 0; o < d.out; ++o) {
      const double ws = d.w_scale[size_t(o)];
      double acc_unit = ws * double(d.in_scale);
      for (int i = 0; i < d.in; ++i) {
        const size_t k = size_t(o) * size_t(d.in) + size_t(i);
        p[L.w + k] = ws == 0.0 ? 0.f : float(d.w[k]);
      }
      if (ws == 0.0) acc_unit = double(d.in_scale);
      p[L.b + size_t(o)] = float(std::nearbyint(double(d.b[size_t(o)]) / acc_unit));
      p[L.m + size_t(o)] = float(hidden ? acc_unit / double(net[l + 1].in_scale) : acc_unit * 256.0);
    }
  }
}

// The byte form of the INT8 layers (FastModel::quads) for inputs packed
// plus `offset` (128 or 0, fast_byte_form_offset), or nothing when a weight
// is not an integer in [-128, 127] ([-127, 127] for offset 0) or a bias is
// beyond 2^23 (then the float form's sums could round, and the two forms
// would differ).
void pack_quads(FastModel& fm, size_t mlps, int offset_bytes) {
  const float w_min = offset_bytes == 0 ? -127.f : -128.f;
  size_t offset = 0;
  for (std::vector<FastLayer>* net : {&fm.density, &fm.color})
    for (size_t l = 0; l < net->size(); ++l) {
      FastLayer& L = (*net)[l];
      L.q_in = net == &fm.color && l == 0 && fm.dir_dims > 0 ? fm.geo_width : L.in;
      L.wq = offset;
      offset += size_t(L.out) * size_t((L.q_in + 3) / 4);
      L.bq = offset;
      offset += size_t(L.out);
      if (L.q_in < L.in) {  // the direction part
        L.dwq = offset;
        offset += size_t(L.out) * size_t((L.in - L.q_in + 3) / 4);
        L.dbq = offset;
        offset += size_t(L.out);
      }
    }
  const size_t stride = (offset + 15) / 16 * 16;
  std::vector<int32_t> quads(stride * mlps, 0);
  for (size_t i = 0; i < mlps; ++i) {
    const float* p = fm.mlp(i);
    int32_t* q = quads.data() + i * stride;
    for (const std::vector<FastLayer>* net : {&fm.density, &fm.color})
      for (const FastLayer& L : *net) {
        // Inputs [k0, k1) of output o as words at wq, their weights' sum
        // returned; false if a weight is not a byte.
        auto pack = [&](int o, int k0, int k1, size_t wq, int64_t& sum) {
          const int words = (k1 - k0 + 3) / 4;
          sum = 0;
          for (int k = k0; k < k1; ++k) {
            const float w = p[L.w + size_t(o) * size_t(L.in) + size_t(k)];
            if (!(w >= w_min && w <= 127.f && w == std::nearbyint(w))) return false;
            sum += int64_t(w);
            const uint32_t byte = uint32_t(uint8_t(int8_t(w)));
            q[wq + size_t(o) * size_t(words) + size_t((k - k0) / 4)] |= int32_t(byte << (8 * ((k - k0) % 4)));
          }
          return true;
        };
        for (int o = 0; o < L.out; ++o) {
          int64_t sum = 0;
          if (!pack(o, 0, L.q_in, L.wq, sum)) return;
          const float b = p[L.b + size_t(o)];
          if (!(std::abs(b) <= float(1 << 23))) return;
          q[L.bq + size_t(o)] = int32_t(b) - int32_t(offset_bytes * sum);
          if (L.q_in < L.in) {
            if (!pack(o, L.q_in, L.in, L.dwq, sum)) return;
            q[L.dbq + size_t(o)] = -int32_t(offset_bytes * sum);
          }
        }
      }
  }
  fm.quad_stride = stride;
  fm.quads = std::move(quads);
  fm.byte_offset = offset_bytes;
}

}  // namespace

FastModel pack_fast_model(const SceneModel& model, const ResolvedForm& form, FastArithmetic arithmetic) {
  model.check_structure();
  if (model.feature_channels < 1 || model.feature_channels > kFastMaxWidth)
    fail("model has {} feature channels, the fast renderer takes 1..{}", model.feature_channels, kFastMaxWidth);
  const bool int8 = arithmetic == FastArithmetic::Int8;
  if (int8 && !(form.quantized_features && form.quantized_mlps))
    fail("the INT8 path needs the model's INT4 features and INT8 MLPs");
  check_feature_storage(model, form);

  FastModel fm;
  fm.model = &model;
  fm.arithmetic = arithmetic;
  fm.form = form;
  fm.feature_channels = model.feature_channels;
  const size_t F = size_t(model.feature_channels);
  if (form.quantized_features) {
    fm.feature_scale = model.feature_quant.scale;
    for (size_t c = 0; c < F; ++c) {
      if (!std::isfinite(fm.feature_scale[c]) || fm.feature_scale[c] < 0.f)
        fail("model feature channel {} has scale {}, not finite and >= 0", c, fm.feature_scale[c]);
      fm.feature_zero_point.push_back(float(model.feature_quant.zero_point[c]));
    }
  }
  if (model.mlp_count() == 0) return fm;

  const MlpArch& arch = model.mlp_arch;
  check_mlp_arch(arch, model.feature_channels, kFastMaxWidth, "the fast renderer's limit");
  fm.geo_width = arch.geo_width();
  fm.dir_dims = arch.dir_dims();
  fm.dir_frequencies = arch.dir_frequencies;
  if (fm.geo_width + fm.dir_dims > kFastMaxWidth)
    fail("mlp_arch colour input {} is wider than {}", fm.geo_width + fm.dir_dims, kFastMaxWidth);
  size_t offset = 0;
  fm.density = layout_net(arch.density_widths, offset, int8);
  fm.color = layout_net(arch.color_widths, offset, int8);
  if (int8) {
    fm.feature_in = offset;
    offset += F;
    fm.geo_in = offset++;
    fm.dir_in = offset++;
  }
  fm.mlp_stride = (offset + 15) / 16 * 16;  // each MLP starts on a 64-byte boundary of the array
  fm.params.assign(fm.mlp_stride * model.mlp_count(), 0.f);

  const size_t n = int8 ? model.mlps_q8.size() : (form.quantized_mlps ? model.mlps_q8.size() : model.mlps_f32.size());
  if (n != model.mlp_count()) fail("model has {} MLPs of the rendered form for {} coarse voxels", n, model.mlp_count());
  for (size_t i = 0; i < n; ++i) {
    float* p = fm.params.data() + i * fm.mlp_stride;
    if (int8) {
      const MlpQ& q = model.mlps_q8[i];
      pack_int8_net(q.density, fm.density, p, i, "density");
      pack_int8_net(q.color, fm.color, p, i, "colour");
      const double d_in = q.density.front().in_scale, c_in = q.color.front().in_scale;
      for (size_t c = 0; c < F; ++c) p[fm.feature_in + c] = float(double(fm.feature_scale[c]) / d_in);
      p[fm.geo_in] = float(1.0 / (256.0 * c_in));
      p[fm.dir_in] = float(kDirectionStep / c_in);
    } else if (form.quantized_mlps) {
      const MlpQ& q = model.mlps_q8[i];
      for (const auto* net : {&q.density, &q.color})
        for (const DenseQ& d : *net)
          if (d.w_scale.size() != size_t(d.out) || d.w.size() != size_t(d.in) * size_t(d.out))
            fail("INT8 MLP {} has a {}x{} layer with {} weights and {} scales", i, d.out, d.in, d.w.size(),
                 d.w_scale.size());
      const MlpF f = dequantize_mlp(q);
      pack_float_net(f.density, fm.density, p, i, "density");
      pack_float_net(f.color, fm.color, p, i, "colour");
    } else {
      pack_float_net(model.mlps_f32[i].density, fm.density, p, i, "density");
      pack_float_net(model.mlps_f32[i].color, fm.color, p, i, "colour");
    }
  }
  const int offset_bytes = fast_byte_form_offset();
  if (int8 && offset_bytes >= 0) pack_quads(fm, n, offset_bytes);
  return fm;
}

}  // namespace edrnr
