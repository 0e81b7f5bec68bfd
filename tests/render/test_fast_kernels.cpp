// The fast renderer's batch kernel: how a batch is cut into SIMD vectors does
// not change any sample's outputs.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include "model/procedural.h"
#include "render/fast_kernels.h"
#include "render/fast_model.h"
#include "render/reference.h"

namespace edrnr {
namespace {

constexpr int kRays = 256;  // direction table width (a tile's rays)

struct Batch {
  uint32_t mlp = 0;
  std::vector<FastSample> samples;
};

// Samples of the MLP whose coarse voxel holds the most feature blocks: each at
// a micro voxel of one of its blocks, with pseudo-random trilinear weights,
// three consecutive samples per ray.
Batch make_batch(const SceneModel& m, size_t n) {
  const int fr = m.fine_res(), cr = m.coarse_res(), per = fr / cr;
  std::vector<std::vector<int32_t>> blocks(m.mlp_count());
  for (int z = 0; z < fr; ++z)
    for (int y = 0; y < fr; ++y)
      for (int x = 0; x < fr; ++x) {
        const int32_t b = m.fine_to_block[linear_index(x, y, z, fr)];
        const int32_t u = m.coarse_to_mlp[linear_index(x / per, y / per, z / per, cr)];
        if (b >= 0 && u >= 0) blocks[size_t(u)].push_back(b);
      }
  Batch batch;
  size_t best = 0;
  for (size_t u = 0; u < blocks.size(); ++u)
    if (blocks[u].size() > blocks[best].size()) best = u;
  batch.mlp = uint32_t(best);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> frac(0.f, 1.f);
  for (size_t i = 0; i < n; ++i) {
    FastSample s;
    s.ray = uint32_t(i / 3);
    s.mlp = batch.mlp;
    const int32_t b = blocks[best][i % blocks[best].size()];
    const int l = int(rng() % 64);  // micro voxel (l & 3, (l >> 2) & 3, l >> 4) of the block
    s.vertex = uint32_t(b) * kBlockVerts +
               uint32_t((l & 3) + kBlockVertsPerAxis * (((l >> 2) & 3) + kBlockVertsPerAxis * (l >> 4)));
    s.fx = frac(rng);
    s.fy = frac(rng);
    s.fz = frac(rng);
    batch.samples.push_back(s);
  }
  return batch;
}

uint32_t bits(float x) { return std::bit_cast<uint32_t>(x); }

// A batch's direction table (the kRays rays' unit directions encoded for
// fm) and its samples in order.
struct BatchInputs {
  std::vector<float> dir;
  std::vector<uint32_t> order;
};
BatchInputs batch_inputs(const FastModel& fm, const Batch& batch, const std::vector<float>& dx,
                         const std::vector<float>& dy, const std::vector<float>& dz) {
  BatchInputs in;
  in.dir.resize(size_t(std::max(fast_direction_rows(fm), 1)) * kRays);
  fast_encode_directions(fm, dx.data(), dy.data(), dz.data(), kRays, in.dir.data(), kRays);
  in.order.resize(batch.samples.size());
  for (size_t i = 0; i < in.order.size(); ++i) in.order[i] = uint32_t(i);
  return in;
}

// Samples [0, len) of the batch through fm's MLP (sample i's outputs at i).
std::vector<FastSampleOut> eval(const FastModel& fm, const Batch& batch, const BatchInputs& in, size_t len, float delta,
                                const FastActivationTables* tables = nullptr) {
  std::vector<FastSampleOut> out(batch.samples.size());
  fast_eval_batch(fm, batch.mlp, batch.samples.data(), in.order.data(), len, in.dir.data(), kRays, delta, out.data(),
                  nullptr, tables);
  return out;
}

// Every sample's outputs, bit for bit.
void expect_same_outputs(const std::vector<FastSampleOut>& x, const std::vector<FastSampleOut>& y, size_t len) {
  for (size_t i = 0; i < len; ++i) {
    SCOPED_TRACE(testing::Message() << "sample " << i);
    ASSERT_EQ(bits(x[i].alpha), bits(y[i].alpha));
    ASSERT_EQ(bits(x[i].trans), bits(y[i].trans));
    for (int c = 0; c < 3; ++c) ASSERT_EQ(bits(x[i].rgb[c]), bits(y[i].rgb[c]));
  }
}

// Every run of samples [start, start + len) evaluated as a batch of its own
// (whose chunks, and short tails in half-width vectors, fall elsewhere) gives
// each sample the outputs, bit for bit, it had in the whole batch. Int8 and
// float arithmetic.
TEST(FastKernels, OutputsDoNotDependOnTheChunking) {
  ProceduralOptions o;
  o.micro_res = 64;
  o.store_float = true;
  o.seed = 7;
  const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
  const Batch batch = make_batch(m, 53);
  ASSERT_GT(m.mlp_count(), 0u);
  std::vector<float> dx(kRays), dy(kRays), dz(kRays);
  for (int r = 0; r < kRays; ++r) {
    const double a = 0.1 * r, b = 0.03 * r - 2.0;
    dx[size_t(r)] = float(std::cos(a) * std::cos(b));
    dy[size_t(r)] = float(std::sin(a) * std::cos(b));
    dz[size_t(r)] = float(std::sin(b));
  }
  const float delta = 2.f / 64.f;
  for (FastArithmetic a : {FastArithmetic::Int8, FastArithmetic::Float}) {
    const FastModel fm = pack_fast_model(m, resolve_model_form(m, ModelForm::Quantized), a);
    const BatchInputs in = batch_inputs(fm, batch, dx, dy, dz);
    const size_t n = batch.samples.size();
    const std::vector<FastSampleOut> whole = eval(fm, batch, in, n, delta);
    int distinct = 0;  // samples whose outputs differ from the first one's: the batch is not degenerate
    for (size_t i = 0; i < n; ++i) distinct += whole[i].alpha != whole[0].alpha || whole[i].rgb[0] != whole[0].rgb[0];
    EXPECT_GT(distinct, int(n) / 2);
    for (size_t start : {size_t(0), size_t(3), size_t(16), size_t(37)})
      for (size_t len = 1; len <= 17 && start + len <= n; ++len) {
        std::vector<FastSampleOut> part(n);
        fast_eval_batch(fm, batch.mlp, batch.samples.data(), in.order.data() + start, len, in.dir.data(), kRays, delta,
                        part.data(), nullptr);
        for (size_t i = start; i < start + len; ++i) {
          SCOPED_TRACE(testing::Message() << "int8 " << (a == FastArithmetic::Int8) << " start " << start << " len "
                                          << len << " sample " << i);
          ASSERT_EQ(bits(part[i].alpha), bits(whole[i].alpha));
          ASSERT_EQ(bits(part[i].trans), bits(whole[i].trans));
          for (int c = 0; c < 3; ++c) ASSERT_EQ(bits(part[i].rgb[c]), bits(whole[i].rgb[c]));
        }
      }
  }
}

// The fused chunk of the default MLP shape (sizes fixed when compiled)
// gives every sample the bits of the general layers, on both paths, in
// whole and half-width vectors.
TEST(FastKernels, FusedChunkGivesTheGeneralLayersBits) {
  ProceduralOptions o;
  o.micro_res = 64;
  o.seed = 11;
  const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
  const Batch batch = make_batch(m, 45);
  std::vector<float> dx(kRays), dy(kRays), dz(kRays);
  for (int r = 0; r < kRays; ++r) {
    const double a = 0.05 * r - 0.4, b = 0.025 * r - 1.2;
    dx[size_t(r)] = float(std::cos(a) * std::cos(b));
    dy[size_t(r)] = float(std::sin(a) * std::cos(b));
    dz[size_t(r)] = float(std::sin(b));
  }
  const float delta = 2.f / 64.f;
  for (FastArithmetic a : {FastArithmetic::Int8, FastArithmetic::Float}) {
    SCOPED_TRACE(testing::Message() << "int8 " << (a == FastArithmetic::Int8));
    const FastModel fused = pack_fast_model(m, resolve_model_form(m, ModelForm::Quantized), a);
    FastModel general = fused;
    general.fused = false;
    // The float path always fuses this shape; the INT8 path where the CPU has byte products.
    EXPECT_EQ(fast_fused_shape(fused), a == FastArithmetic::Float || !fused.quads.empty());
    EXPECT_FALSE(fast_fused_shape(general));
    const BatchInputs in = batch_inputs(fused, batch, dx, dy, dz);
    // The INT8 path's activation tables (read by the fused chunk; made for
    // another spacing, they are not read) give the same bits too.
    const FastActivationTables tables = fast_activation_tables(fused, delta);
    const FastActivationTables other = fast_activation_tables(fused, 2 * delta);
    EXPECT_EQ(tables.alpha.size(), a == FastArithmetic::Int8 ? 65536u : 0u);
    for (size_t len : {batch.samples.size(), size_t(6)}) {
      SCOPED_TRACE(testing::Message() << "len " << len);
      const std::vector<FastSampleOut> y = eval(general, batch, in, len, delta);
      const std::vector<FastSampleOut> x = eval(fused, batch, in, len, delta);
      expect_same_outputs(x, y, len);
      expect_same_outputs(eval(fused, batch, in, len, delta, &tables), y, len);
      expect_same_outputs(eval(fused, batch, in, len, delta, &other), y, len);
      int opaque = 0;
      for (size_t i = 0; i < len; ++i) opaque += x[i].alpha > 0.01f;
      if (len > 6) EXPECT_GT(opaque, 0);  // the later layers see something
    }
  }
}

// Colour outputs far beyond the sigmoid's range give 0 and 1, not NaN: raw
// colours of -1e6 and +1e6 (float arithmetic) and the 16-bit raw limits
// (-128 and 128, Int8) where exp(-raw) overflows.
TEST(FastKernels, SaturatedColoursAreZeroAndOne) {
  ProceduralOptions o;
  o.micro_res = 64;
  o.seed = 3;
  SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
  for (MlpQ& q : m.mlps_q8) {
    DenseQ& last = q.color.back();
    ASSERT_EQ(last.out, 3);
    last.b[0] = -1e6f;
    last.b[1] = 1e6f;
  }
  const Batch batch = make_batch(m, 40);
  std::vector<float> dx(kRays, 0.f), dy(kRays, 0.f), dz(kRays, 1.f);
  for (FastArithmetic a : {FastArithmetic::Int8, FastArithmetic::Float}) {
    const FastModel fm = pack_fast_model(m, resolve_model_form(m, ModelForm::Quantized), a);
    const size_t n = batch.samples.size();
    const std::vector<FastSampleOut> out = eval(fm, batch, batch_inputs(fm, batch, dx, dy, dz), n, 2.f / 64.f);
    for (size_t i = 0; i < n; ++i) {
      SCOPED_TRACE(testing::Message() << "int8 " << (a == FastArithmetic::Int8) << " sample " << i);
      ASSERT_TRUE(out[i].rgb[0] >= 0.f && out[i].rgb[0] <= 1e-30f) << out[i].rgb[0];
      ASSERT_EQ(out[i].rgb[1], 1.f);
      ASSERT_TRUE(out[i].rgb[2] >= 0.f && out[i].rgb[2] <= 1.f) << out[i].rgb[2];
    }
  }
}

// The INT8 layers' byte form (FastModel::quads: inputs as bytes, plus 128
// with AVX-512 VNNI or signed with AVX2, against signed weights) gives every
// sample the bits of the float form of the same integer sums. Where the CPU
// has neither the model has no byte form, and both runs are the float form.
// expect_bytes: whether m has a byte form where the CPU has one;
// expect_fused: whether the byte form then runs in the fused chunk of the
// default MLP shape (fast_fused_shape) rather than the general layers.
void expect_byte_form_matches_float_form(const SceneModel& m, bool expect_bytes = true, bool expect_fused = true) {
  const Batch batch = make_batch(m, 61);
  std::vector<float> dx(kRays), dy(kRays), dz(kRays);
  for (int r = 0; r < kRays; ++r) {
    const double a = 0.07 * r + 0.3, b = 0.02 * r - 1.5;
    dx[size_t(r)] = float(std::cos(a) * std::cos(b));
    dy[size_t(r)] = float(std::sin(a) * std::cos(b));
    dz[size_t(r)] = float(std::sin(b));
  }
  const FastModel bytes = pack_fast_model(m, resolve_model_form(m, ModelForm::Quantized), FastArithmetic::Int8);
  FastModel floats = bytes;
  floats.quads.clear();
  if (bytes.quads.empty()) GTEST_LOG_(INFO) << "no byte form: both runs use the float form";
  EXPECT_EQ(bytes.quads.empty(), fast_byte_form_offset() < 0 || !expect_bytes);
  if (!bytes.quads.empty()) EXPECT_EQ(bytes.byte_offset, fast_byte_form_offset());
  EXPECT_EQ(fast_fused_shape(bytes), !bytes.quads.empty() && expect_fused);
  EXPECT_FALSE(fast_fused_shape(floats));
  // The byte form holds each weight once, in order, 4 to a word.
  if (!bytes.quads.empty()) {
    const FastLayer& L = bytes.density.front();
    const float* p = bytes.mlp(batch.mlp);
    const int32_t* q = bytes.mlp_quads(batch.mlp);
    for (int k = 0; k < L.q_in; ++k)
      EXPECT_EQ(float(int8_t(uint32_t(q[L.wq + size_t(k / 4)]) >> (8 * (k % 4)))), p[L.w + size_t(k)]) << k;
    // The colour net's direction inputs, apart, for every output.
    const FastLayer& C = bytes.color.front();
    ASSERT_GT(bytes.dir_dims, 0);
    ASSERT_EQ(C.in - C.q_in, bytes.dir_dims);
    const int words = (bytes.dir_dims + 3) / 4;
    for (int o = 0; o < C.out; ++o) {
      int64_t sum = 0;
      for (int k = 0; k < bytes.dir_dims; ++k) {
        const float w = p[C.w + size_t(o) * size_t(C.in) + size_t(C.q_in + k)];
        sum += int64_t(w);
        EXPECT_EQ(float(int8_t(uint32_t(q[C.dwq + size_t(o * words + k / 4)]) >> (8 * (k % 4)))), w) << o << " " << k;
      }
      EXPECT_EQ(q[C.dbq + size_t(o)], -bytes.byte_offset * sum) << o;
    }
  }
  const BatchInputs in = batch_inputs(bytes, batch, dx, dy, dz);  // the byte form's rows too
  const size_t n = batch.samples.size();
  const float delta = 2.f / 64.f;
  // Whole batches and short ones (half-width vectors).
  for (size_t len : {n, size_t(5)}) {
    SCOPED_TRACE(testing::Message() << "len " << len);
    const std::vector<FastSampleOut> a = eval(bytes, batch, in, len, delta), b = eval(floats, batch, in, len, delta);
    expect_same_outputs(a, b, len);
    if (testing::Test::HasFatalFailure()) return;
    int opaque = 0;
    for (size_t i = 0; i < len; ++i) opaque += a[i].alpha > 0.01f;
    if (len == n) {
      EXPECT_GT(opaque, 0);  // the samples reach the nets' later layers with something to say
    }
  }
}

TEST(FastKernels, Int8ByteFormGivesTheFloatFormsOutputs) {
  ProceduralOptions o;
  o.micro_res = 64;
  o.seed = 5;
  const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
  {
    SCOPED_TRACE("procedural model");
    expect_byte_form_matches_float_form(m);
  }
  // Another shape (8 feature channels) takes the general layers.
  {
    ProceduralOptions o8 = o;
    o8.feature_channels = 8;
    SCOPED_TRACE("8 feature channels");
    expect_byte_form_matches_float_form(make_procedural_model("several", procedural_shapes("several"), o8), true,
                                        false);
  }
  // The byte form's limits: weights of +-127 and inputs scaled 64 times up,
  // so that the first layers' inputs reach -128 and 127 and the hidden
  // layers' 127 (the 16-bit pair sums of AVX2's form are largest there).
  SceneModel extreme = m;
  for (MlpQ& q : extreme.mlps_q8)
    for (std::vector<DenseQ>* net : {&q.density, &q.color})
      for (DenseQ& d : *net) {
        for (size_t i = 0; i < d.w.size(); ++i)
          d.w[i] = int8_t(i % 3 == 0 ? 127 : i % 3 == 1 ? -127 : int(i * 37 % 255) - 127);
        d.in_scale /= 64.f;
      }
  {
    SCOPED_TRACE("weights +-127, saturated inputs");
    expect_byte_form_matches_float_form(extreme);
  }
  // A weight of -128 fits the form with inputs plus 128 (AVX-512 VNNI) but
  // not AVX2's signed inputs, whose sign it would have to take: there the
  // model has no byte form (and the float form gives the results).
  extreme.mlps_q8.front().density.front().w.front() = -128;
  {
    SCOPED_TRACE("a weight -128");
    expect_byte_form_matches_float_form(extreme, fast_byte_form_offset() == 128);
  }
}

}  // namespace
}  // namespace edrnr
