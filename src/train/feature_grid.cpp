#include "train/feature_grid.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>

#include "core/error.h"
#include "train/feature_kernels.h"
#include "train/rng.h"

namespace edrnr::train {

void GradientSlabs::build(int micro_res, int slab_micro_, const std::vector<int32_t>& ids,
                          const std::vector<int16_t>& micro) {
  slab_micro = slab_micro_;
  const int n_slabs = micro_res / slab_micro;
  begin.assign(size_t(n_slabs) + 1, 0);
  for (int32_t s : ids) ++begin[size_t(micro[3 * size_t(s) + 2] / slab_micro) + 1];
  for (int j = 0; j < n_slabs; ++j) begin[size_t(j) + 1] += begin[size_t(j)];
  samples.resize(ids.size());
  std::vector<int32_t> fill(begin.begin(), begin.end() - 1);
  for (int32_t s : ids) samples[size_t(fill[size_t(micro[3 * size_t(s) + 2] / slab_micro)]++)] = s;
}

void LazyAdamArray::resize(size_t vertices, int channels, int slabs) {
  grad.assign(vertices * size_t(channels), 0.f);
  m.assign(vertices * size_t(channels), 0.f);
  v.assign(vertices * size_t(channels), 0.f);
  touched_list.assign(size_t(slabs), {});
}

// ---------------------------------------------------------------------------
// FeaturePyramid

FeaturePyramid::FeaturePyramid(int micro_res, const std::vector<int>& level_res, uint64_t seed, float init_scale)
    : micro_res_(micro_res) {
  if (level_res.empty()) fail("feature levels: at least one level is needed");
  for (int r : level_res) {
    if (r <= 0 || r > micro_res || micro_res % r || !std::has_single_bit(unsigned(micro_res / r)))
      fail("feature levels: resolution {} does not divide the micro resolution {} by a power of two", r, micro_res);
  }
  int max_cell = 1;
  for (int r : level_res) max_cell = std::max(max_cell, micro_res / r);
  const int slabs = micro_res / max_cell;
  for (size_t li = 0; li < level_res.size(); ++li) {
    PyramidLevel L;
    L.res = level_res[li];
    L.shift = std::countr_zero(unsigned(micro_res / L.res));
    size_t nv = size_t(L.res + 1) * size_t(L.res + 1) * size_t(L.res + 1);
    L.value.resize(nv * kLevelChannels);
    const uint64_t base = hash3(seed, uint64_t(RngStream::GridInit), li);
    float* val = L.value.data();
    const size_t total = L.value.size();
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < total; ++i) val[i] = (2.f * uniform01(hash_combine(base, i)) - 1.f) * init_scale;
    L.adam.resize(nv, kLevelChannels, slabs);
    levels_.push_back(std::move(L));
  }
}

int FeaturePyramid::slab_micro() const {
  int max_cell = 1;
  for (const auto& L : levels_) max_cell = std::max(max_cell, 1 << L.shift);
  return max_cell;
}

void FeaturePyramid::interpolate(const Vec3f& p, const Vec3i& m, float* out) const {
  for (size_t li = 0; li < levels_.size(); ++li) {
    const PyramidLevel& L = levels_[li];
    if (!level_active(li)) {
      std::fill_n(out + li * kLevelChannels, kLevelChannels, 0.f);
      continue;
    }
    const float inv = 1.f / float(1 << L.shift);  // exact: a power of two
    const int cx = m.x >> L.shift, cy = m.y >> L.shift, cz = m.z >> L.shift;
    float w[8];
    trilinear_weights(p.x * inv - float(cx), p.y * inv - float(cy), p.z * inv - float(cz), w);
    const size_t n = size_t(L.res) + 1;
    const size_t base = L.vertex_index(cx, cy, cz);
    const size_t off[8] = {0, 1, n, n + 1, n * n, n * n + 1, n * n + n, n * n + n + 1};
    float acc[kLevelChannels] = {0, 0, 0, 0};
    for (int c = 0; c < 8; ++c) {
      const float* v = &L.value[(base + off[c]) * kLevelChannels];
      for (int k = 0; k < kLevelChannels; ++k) acc[k] += w[c] * v[k];
    }
    for (int k = 0; k < kLevelChannels; ++k) out[li * kLevelChannels + size_t(k)] = acc[k];
  }
}

void FeaturePyramid::prefetch(const Vec3i& m) const {
  for (size_t li = 0; li < levels_.size(); ++li) {
    if (!level_active(li)) continue;
    const PyramidLevel& L = levels_[li];
    const size_t n = size_t(L.res) + 1;
    const size_t base = L.vertex_index(m.x >> L.shift, m.y >> L.shift, m.z >> L.shift);
    const float* v = L.value.data();
    for (size_t off : {size_t(0), n, n * n, n * n + n}) {
      __builtin_prefetch(v + (base + off) * kLevelChannels);
      __builtin_prefetch(v + (base + off + 1) * kLevelChannels);
    }
  }
}

namespace {
// gv[k] += w * g[k] for the 4 channels of a vertex (a product, then a sum,
// as the scalar loop); true if the row was all zeros (of either sign)
// before and is not after (the vertex is touched now).
inline bool add_row4(float* gv, float w, const float* g) {
#if defined(__SSE2__)
  const __m128 zero = _mm_setzero_ps();
  const __m128 old = _mm_loadu_ps(gv);
  const __m128 sum = _mm_add_ps(old, _mm_mul_ps(_mm_set1_ps(w), _mm_loadu_ps(g)));
  _mm_storeu_ps(gv, sum);
  return _mm_movemask_ps(_mm_cmpeq_ps(old, zero)) == 0xF && _mm_movemask_ps(_mm_cmpeq_ps(sum, zero)) != 0xF;
#else
  const bool was_zero = gv[0] == 0.f && gv[1] == 0.f && gv[2] == 0.f && gv[3] == 0.f;
  for (int k = 0; k < kLevelChannels; ++k) gv[k] += w * g[k];
  return was_zero && (gv[0] != 0.f || gv[1] != 0.f || gv[2] != 0.f || gv[3] != 0.f);
#endif
}
}  // namespace

void FeaturePyramid::scatter_gradients(const GradientSlabs& slabs, const std::vector<float>& pos,
                                       const std::vector<int16_t>& micro, const std::vector<float>& d_feat) {
  const int F = channels();
  const int n_slabs = slabs.slabs();
  const int H = slabs.slab_micro;
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_slabs; ++j) {
    for (size_t li = 0; li < levels_.size(); ++li) {
      if (!level_active(li)) continue;
      PyramidLevel& L = levels_[li];
      auto& list = L.adam.touched_list[size_t(j)];
      const float inv = 1.f / float(1 << L.shift);
      // The vertex z layers this slab owns: those whose micro z lies in the slab
      // (the last layer, at micro_res, belongs to the last slab).
      const int vz_lo = (j * H) >> L.shift;
      const int vz_hi = j + 1 == n_slabs ? L.res : (((j + 1) * H) >> L.shift) - 1;
      // The samples of the previous slab and of this one, merged by id: every
      // vertex sums its contributions in sample order, as a serial loop would.
      int32_t ia = j > 0 ? slabs.begin[size_t(j - 1)] : slabs.begin[size_t(j)];
      const int32_t ea = slabs.begin[size_t(j)];
      int32_t ib = slabs.begin[size_t(j)];
      const int32_t eb = slabs.begin[size_t(j) + 1];
      {
        while (ia < ea || ib < eb) {
          const bool take_a = ib >= eb || (ia < ea && slabs.samples[size_t(ia)] < slabs.samples[size_t(ib)]);
          const size_t s = size_t(take_a ? slabs.samples[size_t(ia++)] : slabs.samples[size_t(ib++)]);
          // Prefetch the gradients the sample a few places ahead in this slab will add to.
          if (ib + 3 < eb) {
            const size_t q = size_t(slabs.samples[size_t(ib + 3)]);
            const size_t vq =
                L.vertex_index(micro[3 * q] >> L.shift, micro[3 * q + 1] >> L.shift, micro[3 * q + 2] >> L.shift);
            const size_t n = size_t(L.res) + 1;
            for (size_t off : {size_t(0), n, n * n, n * n + n}) __builtin_prefetch(&L.adam.grad[(vq + off) * 4], 1);
          }
          const int cx = micro[3 * s] >> L.shift, cy = micro[3 * s + 1] >> L.shift, cz = micro[3 * s + 2] >> L.shift;
          float w[8];
          trilinear_weights(pos[3 * s] * inv - float(cx), pos[3 * s + 1] * inv - float(cy),
                            pos[3 * s + 2] * inv - float(cz), w);
          const float* g = &d_feat[s * size_t(F) + li * kLevelChannels];
          for (int dz = 0; dz < 2; ++dz) {
            const int vz = cz + dz;
            if (vz < vz_lo || vz > vz_hi) continue;
            for (int c = 4 * dz; c < 4 * dz + 4; ++c) {
              const size_t vtx = L.vertex_index(cx + (c & 1), cy + ((c >> 1) & 1), vz);
              if (add_row4(&L.adam.grad[vtx * kLevelChannels], w[c], g)) list.push_back(int32_t(vtx));
            }
          }
        }
      }
    }
  }
}

namespace {
// Calls pull(u) with the values of each grid neighbour of vertex vtx of L.
template <class Pull>
void for_each_grid_neighbour(const PyramidLevel& L, int32_t vtx, Pull pull) {
  const int n = L.res + 1;
  const int coord[3] = {vtx % n, (vtx / n) % n, vtx / (n * n)};
  const int64_t stride[3] = {1, n, int64_t(n) * n};
  for (int a = 0; a < 3; ++a)
    for (int s = -1; s <= 1; s += 2) {
      const int c = coord[a] + s;
      if (c < 0 || c >= n) continue;
      pull(&L.value[size_t(vtx + s * stride[a]) * kLevelChannels]);
    }
}

// The decoupled smoothing step over the touched vertices of one array of
// `channels` values per vertex: deltas from the values before the step
// (parallel over the touched lists), then applied.
template <class Neighbours>
void smooth_touched(std::vector<float>& value, const std::vector<std::vector<int32_t>>& lists, int channels, float rate,
                    Neighbours neighbours) {
  const int n_lists = int(lists.size());
  // One buffer for all lists' deltas, kept from call to call (no allocation
  // per step): list j's at [offset[j], offset[j + 1]).
  static thread_local std::vector<float> delta;
  static thread_local std::vector<size_t> offset;
  offset.assign(size_t(n_lists) + 1, 0);
  for (int j = 0; j < n_lists; ++j)
    offset[size_t(j) + 1] = offset[size_t(j)] + lists[size_t(j)].size() * size_t(channels);
  if (delta.size() < offset.back()) delta.resize(offset.back());
  // The caller's buffers (thread_local: the OpenMP threads must not name them).
  float* const all = delta.data();
  const size_t* const at = offset.data();
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_lists; ++j) {
    const std::vector<int32_t>& list = lists[size_t(j)];
    float* d = all + at[j];
    for (size_t i = 0; i < list.size(); ++i) {
      const float* v = &value[size_t(list[i]) * size_t(channels)];
      float* di = d + i * size_t(channels);
      for (int k = 0; k < channels; ++k) di[k] = 0.f;
      neighbours(list[i], [&](const float* u) {
        for (int k = 0; k < channels; ++k) di[k] += rate * (v[k] - u[k]);
      });
    }
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_lists; ++j) {
    const std::vector<int32_t>& list = lists[size_t(j)];
    const float* d = all + at[j];
    for (size_t i = 0; i < list.size(); ++i) {
      float* v = &value[size_t(list[i]) * size_t(channels)];
      for (int k = 0; k < channels; ++k) v[k] -= d[i * size_t(channels) + size_t(k)];
    }
  }
}
}  // namespace

void FeaturePyramid::add_tv_gradient(float weight, int levels) {
  if (!(weight > 0.f)) return;
  for (int li = std::max(0, int(levels_.size()) - levels); li < int(levels_.size()); ++li) {
    PyramidLevel& L = levels_[size_t(li)];
    const int n_lists = int(L.adam.touched_list.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (int j = 0; j < n_lists; ++j) {
      for (int32_t vtx : L.adam.touched_list[size_t(j)]) {
        const float* v = &L.value[size_t(vtx) * kLevelChannels];
        float* g = &L.adam.grad[size_t(vtx) * kLevelChannels];
        for_each_grid_neighbour(L, vtx, [&](const float* u) {
          for (int k = 0; k < kLevelChannels; ++k) g[k] += 2.f * weight * (v[k] - u[k]);
        });
      }
    }
  }
}

void FeaturePyramid::smooth(float rate, int levels) {
  if (!(rate > 0.f)) return;
  for (int li = std::max(0, int(levels_.size()) - levels); li < int(levels_.size()); ++li) {
    PyramidLevel& L = levels_[size_t(li)];
    smooth_touched(L.value, L.adam.touched_list, kLevelChannels, rate,
                   [&](int32_t vtx, const auto& pull) { for_each_grid_neighbour(L, vtx, pull); });
  }
}

void FeaturePyramid::adam_step(const AdamStep& step) {
  for (auto& L : levels_) {
    const int n_lists = int(L.adam.touched_list.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (int j = 0; j < n_lists; ++j) {
      auto& list = L.adam.touched_list[size_t(j)];
      const size_t n_list = list.size();
      for (size_t j = 0; j < n_list; ++j) {
        if (j + 8 < n_list) {
          const size_t f = size_t(list[j + 8]) * kLevelChannels;
          __builtin_prefetch(&L.value[f], 1);
          __builtin_prefetch(&L.adam.m[f], 1);
          __builtin_prefetch(&L.adam.v[f], 1);
          __builtin_prefetch(&L.adam.grad[f], 1);
        }
        const size_t i = size_t(list[j]) * kLevelChannels;
        step.update4(&L.value[i], &L.adam.m[i], &L.adam.v[i], &L.adam.grad[i]);
      }
      list.clear();
    }
  }
}

// ---------------------------------------------------------------------------
// INT4

int Int4Channel::quantize(float x) const {
  // Round half to even by the 1.5 * 2^23 trick (exact for |t| < 2^22, and t is
  // clamped far inside that), the same as nearbyint without a library call.
  const float t = std::clamp(x * inv_scale, -64.f, 64.f);
  const float r = (t + 12582912.f) - 12582912.f;
  // The clamp written out so that a NaN (a diverged value) gives code 0
  // instead of an undefined conversion; every other value as std::clamp.
  const float v = r + float(zero_point);
  return v >= 15.f ? 15 : v > 0.f ? int(v) : 0;
}

Int4Channel int4_channel_for_range(float lo, float hi) {
  lo = std::min(lo, 0.f);
  hi = std::max(hi, 0.f);
  Int4Channel q;
  q.scale = (hi - lo) / 15.f;
  // (A range so small that 1 / scale overflows is as good as empty.)
  if (!(q.scale > 0.f) || !std::isfinite(q.scale) || !std::isfinite(1.f / q.scale)) q.scale = 1.f;
  q.inv_scale = 1.f / q.scale;
  // Clamped before the conversion: a huge or non-finite range (a corrupt
  // checkpoint) must not overflow the int. The same result for every other.
  const float zp = std::nearbyint(-lo * q.inv_scale);
  q.zero_point = zp >= 15.f ? 15 : zp > 0.f ? int(zp) : 0;
  return q;
}

Int4Channel fit_int4_channel(const float* values, size_t n, size_t stride, size_t error_stride) {
  float lo = 0.f, hi = 0.f;
  for (size_t v = 0; v < n; ++v) {
    lo = std::min(lo, values[v * stride]);
    hi = std::max(hi, values[v * stride]);
  }
  std::vector<float> sub;
  for (size_t v = 0; v < n; v += error_stride) sub.push_back(values[v * stride]);
  std::sort(sub.begin(), sub.end());
  auto quantile = [&](double q) { return sub.empty() ? 0.f : sub[size_t(q * double(sub.size() - 1))]; };
  // Candidates: the full range, then ranges that let the outermost tails saturate.
  std::vector<std::pair<float, float>> ranges = {{lo, hi}};
  for (double q : {1e-4, 1e-3, 3e-3, 1e-2, 3e-2}) ranges.emplace_back(quantile(q), quantile(1.0 - q));
  Int4Channel best = int4_channel_for_range(lo, hi);
  double best_err = INFINITY;
  for (const auto& [a, b] : ranges) {
    const Int4Channel q = int4_channel_for_range(a, b);
    double err = 0;
    for (float x : sub) {
      const float e = x - q.fake(x);
      err += double(e) * double(e);
    }
    if (err < best_err) {
      best_err = err;
      best = q;
    }
  }
  return best;
}

// ---------------------------------------------------------------------------
// BlockFeatures

BlockFeatures::BlockFeatures(int micro_res, int channels, std::vector<uint32_t> fine_index, std::vector<float> values)
    : micro_res_(micro_res), channels_(channels), fine_index_(std::move(fine_index)), value_(std::move(values)) {
  const int fr = micro_res / kMicroPerFine;
  if (value_.size() != fine_index_.size() * kBlockVerts * size_t(channels))
    fail("block features: {} values for {} blocks of {} channels", value_.size(), fine_index_.size(), channels);
  fine_to_block_.assign(size_t(fr) * fr * fr, -1);
  for (size_t b = 0; b < fine_index_.size(); ++b) {
    if (fine_index_[b] >= fine_to_block_.size() || (b && fine_index_[b] <= fine_index_[b - 1]))
      fail("block features: fine indices must be ascending and inside the grid");
    fine_to_block_[fine_index_[b]] = int32_t(b);
  }
  adam_.resize(fine_index_.size() * kBlockVerts, channels, fr);
}

std::vector<Int4Channel> BlockFeatures::fit_quantization() const {
  const size_t F = size_t(channels_);
  const size_t n = value_.size() / F;
  // Every value for the range, a subsample (at most ~64k per channel) for the error.
  const size_t stride = std::max<size_t>(1, n / 65536);
  std::vector<Int4Channel> q(F);
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t c = 0; c < F; ++c) q[c] = fit_int4_channel(&value_[c], n, F, stride);
  return q;
}

bool BlockFeatures::corner_vertices(const Vec3i& m, int32_t vtx[8]) const {
  const int fr = micro_res_ / kMicroPerFine;
  const int32_t b = fine_to_block_[linear_index(m.x >> 2, m.y >> 2, m.z >> 2, fr)];
  if (b < 0) return false;
  // Vertex ids in the 5^3 block (x fastest) of the corners, dx fastest.
  const int base = (m.x & 3) + kBlockVertsPerAxis * ((m.y & 3) + kBlockVertsPerAxis * (m.z & 3));
  constexpr int kOff[8] = {0, 1, 5, 6, 25, 26, 30, 31};
  for (int c = 0; c < 8; ++c) vtx[c] = b * kBlockVerts + base + kOff[c];
  return true;
}

void BlockFeatures::set_quantization(const std::vector<Int4Channel>& q) {
  if (q.size() != size_t(channels_)) fail("block features: {} channel quantizers for {} channels", q.size(), channels_);
  quant_ = q;
  quant_scale_.clear();
  quant_inv_scale_.clear();
  quant_zero_point_.clear();
  for (const Int4Channel& c : q) {
    quant_scale_.push_back(c.scale);
    quant_inv_scale_.push_back(c.inv_scale);
    quant_zero_point_.push_back(float(c.zero_point));
  }
}

void BlockFeatures::prefetch(const Vec3i& m) const {
  int32_t vtx[8];
  if (!corner_vertices(m, vtx)) return;
  for (int c = 0; c < 8; ++c) __builtin_prefetch(&value_[size_t(vtx[c]) * size_t(channels_)]);
}

bool BlockFeatures::interpolate(const Vec3f& p, const Vec3i& m, float* out) const {
  const int F = channels_;
  int32_t vtx[8];
  if (!corner_vertices(m, vtx)) {
    std::fill(out, out + F, 0.f);
    return false;
  }
  float w[8];
  trilinear_weights(p.x - float(m.x), p.y - float(m.y), p.z - float(m.z), w);
  const float* rows[8];
  for (int c = 0; c < 8; ++c) rows[c] = &value_[size_t(vtx[c]) * size_t(F)];
  if (quant_.empty()) {
    feature_blend_rows(rows, w, size_t(F), out);
  } else {
    feature_blend_rows_fake_quant(rows, w, size_t(F), quant_scale_.data(), quant_inv_scale_.data(),
                                  quant_zero_point_.data(), out);
  }
  return true;
}

void BlockFeatures::scatter_gradients(const GradientSlabs& slabs, const std::vector<float>& pos,
                                      const std::vector<int16_t>& micro, const std::vector<float>& d_feat) {
  const int F = channels_;
  if (slabs.slab_micro != kMicroPerFine) fail("block features: gradient slabs must be one fine voxel high");
  const int n_slabs = slabs.slabs();
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_slabs; ++j) {
    auto& list = adam_.touched_list[size_t(j)];
    const int32_t end = slabs.begin[size_t(j) + 1];
    for (int32_t i = slabs.begin[size_t(j)]; i < end; ++i) {
      int32_t vtx[8];
      if (i + 4 < end) {  // the gradient rows of the sample a few places ahead
        const size_t q = size_t(slabs.samples[size_t(i + 4)]);
        if (corner_vertices({micro[3 * q], micro[3 * q + 1], micro[3 * q + 2]}, vtx))
          for (int c = 0; c < 8; ++c) __builtin_prefetch(&adam_.grad[size_t(vtx[c]) * size_t(F)], 1);
      }
      const size_t s = size_t(slabs.samples[size_t(i)]);
      const Vec3i m{micro[3 * s], micro[3 * s + 1], micro[3 * s + 2]};
      if (!corner_vertices(m, vtx)) continue;
      float w[8];
      trilinear_weights(pos[3 * s] - float(m.x), pos[3 * s + 1] - float(m.y), pos[3 * s + 2] - float(m.z), w);
      const float* g = &d_feat[s * size_t(F)];
      float* rows[8];
      for (int c = 0; c < 8; ++c) rows[c] = &adam_.grad[size_t(vtx[c]) * size_t(F)];
      // A vertex goes on the list when its gradient row stops being all zeros.
      const uint32_t touched = feature_scatter_rows(rows, w, g, size_t(F));
      for (int c = 0; c < 8; ++c)
        if (touched >> c & 1) list.push_back(vtx[c]);
    }
  }
}

template <class Pull>
void BlockFeatures::for_each_neighbour(int32_t vtx, Pull pull) const {
  const int F = channels_;
  const int fr = micro_res_ / kMicroPerFine;
  constexpr int n = kBlockVertsPerAxis;
  const int stride[3] = {1, n, n * n};
  const int b = vtx / kBlockVerts, vid = vtx % kBlockVerts;
  const int local[3] = {vid % n, (vid / n) % n, vid / (n * n)};
  const float* v = &value_[size_t(vtx) * size_t(F)];
  const uint32_t fi = fine_index_[size_t(b)];
  const int fine[3] = {int(fi % uint32_t(fr)), int((fi / uint32_t(fr)) % uint32_t(fr)), int(fi / uint32_t(fr * fr))};
  for (int a = 0; a < 3; ++a) {
    if (local[a] > 0) pull(v - stride[a] * F);
    if (local[a] < n - 1) pull(v + stride[a] * F);
    // The same vertex in the block across the face it lies on.
    const int side = local[a] == 0 ? -1 : local[a] == n - 1 ? 1 : 0;
    if (side == 0) continue;
    int f[3] = {fine[0], fine[1], fine[2]};
    f[a] += side;
    if (f[a] < 0 || f[a] >= fr) continue;
    const int32_t nb = fine_to_block_[linear_index(f[0], f[1], f[2], fr)];
    if (nb < 0) continue;
    const int copy = vid - side * (n - 1) * stride[a];
    pull(&value_[(size_t(nb) * kBlockVerts + size_t(copy)) * size_t(F)]);
  }
}

void BlockFeatures::add_tv_gradient(float weight) {
  if (!(weight > 0.f)) return;
  const int F = channels_;
  const int n_lists = int(adam_.touched_list.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_lists; ++j) {
    for (int32_t vtx : adam_.touched_list[size_t(j)]) {
      const float* v = &value_[size_t(vtx) * size_t(F)];
      float* g = &adam_.grad[size_t(vtx) * size_t(F)];
      for_each_neighbour(vtx, [&](const float* u) {
        for (int k = 0; k < F; ++k) g[k] += 2.f * weight * (v[k] - u[k]);
      });
    }
  }
}

void BlockFeatures::smooth(float rate) {
  if (!(rate > 0.f)) return;
  smooth_touched(value_, adam_.touched_list, channels_, rate,
                 [&](int32_t vtx, const auto& pull) { for_each_neighbour(vtx, pull); });
}

void BlockFeatures::adam_step(const AdamStep& step) {
  const size_t F = size_t(channels_);
  const int n_lists = int(adam_.touched_list.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < n_lists; ++j) {
    auto& list = adam_.touched_list[size_t(j)];
    feature_adam_rows(value_.data(), adam_.m.data(), adam_.v.data(), adam_.grad.data(), list.data(), list.size(), F,
                      step);
    list.clear();
  }
}

}  // namespace edrnr::train
