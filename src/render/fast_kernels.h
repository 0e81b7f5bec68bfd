#pragma once
// SIMD kernels of the fast CPU renderer (Highway, runtime dispatch: the best
// target the CPU has, AVX-512 included, is picked on the first call).
//
// A batch is a list of samples that all use one coarse voxel's MLP. The
// kernels run it in chunks of one SIMD vector of samples (16 with AVX-512):
// the features of a chunk are interpolated from the fine-voxel blocks straight
// into a samples-in-lanes layout (one vector per channel), then every layer is
// a small matrix product over the chunk (each weight broadcast once per
// chunk), so the packed MLP (fast_model.h) stays in L1 for the whole batch.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "render/fast_model.h"

namespace edrnr {

// One sample as the traversal gathers it.
struct FastSample {
  uint32_t ray = 0;              // index of its ray in the tile
  uint32_t mlp = 0;              // packed MLP (coarse voxel)
  uint32_t vertex = 0;           // block * 125 + block vertex of its micro voxel's corner (0, 0, 0)
  float fx = 0, fy = 0, fz = 0;  // trilinear weights: position inside the micro voxel, 0..1
};

// What the compositor needs of a sample: its opacity, the transmittance
// factor exp(-sigma delta) (Float) or 1 - alpha (Int8), and its colour.
struct FastSampleOut {
  float alpha = 0, trans = 1;
  float rgb[3] = {0, 0, 0};
};

// Seconds spent per phase, summed over the calls that were given one.
struct FastKernelSeconds {
  double interpolation = 0, mlp = 0;
};

// A batch's samples field by field, in batch order: sample i's ray ray[i],
// block vertex vertex[i] and trilinear weights fx[i], fy[i], fz[i] (as in
// FastSample); its outputs go to out[order[i]]. Read as whole vectors, so
// the kernels load a chunk's fields instead of gathering them from records.
struct FastBatch {
  const uint32_t* ray = nullptr;
  const uint32_t* vertex = nullptr;
  const float* fx = nullptr;
  const float* fy = nullptr;
  const float* fz = nullptr;
  const uint32_t* order = nullptr;
};

// The INT8 path's activations by table: its raw outputs are integers in
// 1/256 steps within [-32768, 32767], so alpha (of the raw density, for one
// sample spacing) and the sigmoid (of a raw colour) take 65536 values each,
// computed once with the kernels' own functions (the same bits).
struct FastActivationTables {
  float delta = 0;             // the sample spacing alpha was made for
  std::vector<float> alpha;    // alpha[raw + 32768]
  std::vector<float> sigmoid;  // sigmoid[raw + 32768]
};
// The tables of fm (INT8 arithmetic) for sample spacing delta: about 0.3 ms.
FastActivationTables fast_activation_tables(const FastModel& fm, float delta);

// Evaluates samples i < n of `batch`, which all use MLP `mlp`, and writes
// out[batch.order[i]]. dir: the direction inputs of the tile's rays
// (fast_encode_directions), value d of ray r at dir[d * ray_stride + r].
// delta: sample spacing in scene units. seconds (optional) collects the
// time per phase. tables (optional; INT8 path, made for delta): the
// activations read from them, with the same results.
void fast_eval_batch(const FastModel& fm, uint32_t mlp, const FastBatch& batch, size_t n, const float* dir,
                     size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds,
                     const FastActivationTables* tables = nullptr);
// The same for the records samples[order[i]], i < n (made into a FastBatch).
void fast_eval_batch(const FastModel& fm, uint32_t mlp, const FastSample* samples, const uint32_t* order, size_t n,
                     const float* dir, size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds,
                     const FastActivationTables* tables = nullptr);

// The direction inputs of n rays with unit directions (dx[r], dy[r], dz[r]):
// encode_direction's values (Float), or those values as INT8 codes of step
// 1/127 (Int8). Writes value d of ray r to out[d * ray_stride + r]; with the
// byte form (FastModel::quads) also rows D + j, j < ceil(D / 4), of 32-bit
// words in the floats' place (codes 4 j .. 4 j + 3 plus fm.byte_offset, one per byte),
// which only the kernels read: out holds fast_direction_rows(fm) rows.
// n is a multiple of the vector length (16 floats covers every target).
void fast_encode_directions(const FastModel& fm, const float* dx, const float* dy, const float* dz, size_t n,
                            float* out, size_t ray_stride);

// The SIMD target the kernels dispatch to on this CPU (e.g. "AVX3_DL").
const char* fast_simd_target();

// Whether the dispatched batch kernel runs fm's MLPs through its fused
// chunk (the INT8 path's byte form for the default MLP shape, density
// 16-16-8 and colour 8 + D -> 16 -> 3, with every size fixed when compiled)
// rather than its general layers; both give the same bits.
bool fast_fused_shape(const FastModel& fm);

// What the dispatched kernels add to each input byte of the INT8 layers'
// byte form (FastModel::byte_offset): 128 (AVX-512 VNNI), 0 (AVX2), or -1
// when they have no byte form.
int fast_byte_form_offset();

}  // namespace edrnr
