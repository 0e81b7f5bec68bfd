#pragma once
// TME, the tiny MLP engine (paper Section IV-A): evaluates the current coarse
// voxel's MLP on an interpolated feature, in integers.
//
// The chip form of a model MLP (MlpQ) is what the MLP cache holds: per layer
// the INT8 weights and, per output neuron, an INT32 bias (in accumulator
// units) and a fixed-point requantization multiplier (fx::Requant with
// requant_multiplier_bits), as MlpArch::q8_bytes counts; plus the input-stage
// multipliers of the two nets: one per feature channel (interpolated feature
// to the density net's INT8 input), one for the density outputs (to the
// colour net's INT8 input) and one for the direction partial sums (below).
// With DenseQ's meaning (weight = w_q * w_scale[row], input step in_scale):
//   acc       = bias + sum w_q x_q   (accumulator_bits, saturating each add)
//   hidden    x'_q = sat(round(relu(acc) * w_scale in_scale / in_scale_next))
//   outputs   raw  = sat(round(acc * w_scale in_scale * 2^out_frac)), mlp_output_bits
// The raw density goes through the alpha LUT (alpha = 1 - exp(-exp(raw)
// delta): delta is constant, so one table on the raw density), the raw
// colours through the sigmoid LUT. The MLP cache holds one MLP: switching to
// another coarse voxel's MLP is one load.
//
// The direction encoding (|d| <= 1) does not share the colour net's input
// step, which the density outputs set (|x| up to tens): it enters as INT8
// with its own fixed step 1 / (2^(activation_bits-1) - 1), and the first
// colour layer sums its direction products apart, then brings that partial
// sum to accumulator units with the MLP's multiplier dir_in
// (= direction step / in_scale) before adding it: one more requantization per
// first-layer neuron, and the direction keeps 8 bits of resolution.
#include <array>
#include <cstdint>
#include <vector>

#include "chip/activation_lut.h"
#include "chip/numerics.h"
#include "chip/tme_kernel.h"
#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr::chip {

struct TmeLayer {
  int in = 0, out = 0;
  std::vector<int8_t> w;                // out * in, row-major
  std::vector<int64_t> bias;            // out, INT32 in accumulator units
  std::vector<fx::Requant> requant;     // out: to the next layer's input, or to the raw output format
  std::vector<int64_t> abs_weight_sum;  // out: sum of |w| of each row (bounds the accumulator)
  // The same layer arranged for the batched GEMM (tme_kernel.h):
  int out_pad = 0;                 // out rounded up to a multiple of tme_lane_pad()
  std::vector<int32_t> wt;         // in x out_pad: the weights transposed, padding zero
  std::vector<int16_t> wt_pairs;   // wt in tme_dot_columns_pairs' layout; empty when inputs may exceed int16
  std::vector<int64_t> bias_sat;   // out: the bias saturated to the accumulator
  std::vector<uint8_t> sum_exact;  // out: 1 if no partial sum can reach the accumulator's limits
  uint64_t bias_saturations = 0;   // neurons whose bias_sat differs from bias (counted per evaluation)
  // A hidden layer whose neurons are all sum_exact, with multipliers below
  // 2^31 and shifts in [0, 62] (the exact 64-bit requantization), with an
  // accumulator of at most 32 bits and floor or half-up rounding: its
  // requantization runs as tme_requant_relu on these out_pad arrays
  // (padding zero).
  bool requant_vector = false;
  fx::Rounding requant_rounding = fx::Rounding::Floor;  // the rounding half64 was made for
  std::vector<int32_t> bias32;
  std::vector<uint32_t> mult32;
  std::vector<uint64_t> shift64;
  std::vector<uint64_t> half64;  // 2^shift / 2 for half-up rounding, 0 for floor
  // An output layer under the same conditions: its requantization runs as
  // tme_requant_signed on the same arrays.
  bool requant_signed = false;
  // Every multiplier below 2^31 with a shift in [0, 62], an accumulator of at
  // most 32 bits and floor or half-up rounding (requant_rounding): once the
  // accumulators are formed, whatever their sums, the requantization runs in
  // the kernels with zero biases (mult32, shift64, half64 set, zero32 zeros).
  bool requant_kernel = false;
  std::vector<int32_t> zero32;
  // Some neuron is not sum_exact: the weights' magnitudes, transposed as wt,
  // bound each sample's partial sums (|bias| + sum |w| |x|).
  bool needs_bound = false;
  std::vector<int32_t> wt_abs;
};

// An input-stage requantization of `count` values as tme_requant_signed runs
// it (zero biases); vector false when a multiplier, shift or the rounding
// needs the scalar path.
struct TmeRequantRow {
  bool vector = false;
  std::vector<int32_t> bias;
  std::vector<uint32_t> mult;
  std::vector<uint64_t> half, shift;
};

struct TmeMlp {
  std::vector<TmeLayer> density, color;
  std::vector<fx::Requant> feature_in;  // F: interpolated feature -> density net input
  fx::Requant geo_in;                   // raw density-net output -> colour net input
  fx::Requant dir_in;                   // first colour layer: direction partial sum -> accumulator units
  size_t stored_bytes = 0;              // q8_bytes + 4 bytes per input-stage multiplier
  TmeRequantRow feature_row;            // feature_in, one per channel
  TmeRequantRow geo_row;                // geo_in, once per density output
};

// The widest layer (inputs or outputs) the TME evaluates.
inline constexpr int kMaxLayerWidth = 256;

// The chip form of MLP `index` of the model. Throws Error naming the MLP,
// net, layer and neuron when a layer is wider than kMaxLayerWidth, a scale is
// negative or not finite, or a multiplier cannot be expressed with
// requant_multiplier_bits.
TmeMlp compile_tme_mlp(const SceneModel& model, size_t index, const ChipNumerics& numerics);

struct TmeOutput {
  int64_t raw_density = 0;       // mlp_output_frac_bits fraction bits
  int64_t alpha = 0;             // Q1.(alpha_bits-1)
  std::array<int64_t, 3> rgb{};  // Q1.(color_bits-1)
};

struct TmeCounters {
  uint64_t samples = 0;
  uint64_t macs = 0;
  uint64_t mlp_loads = 0;  // MLP cache fills
  uint64_t mlp_load_bytes = 0;
  uint64_t saturations = 0;  // accumulator or output values clipped
};

// What a ray's direction adds to each neuron of the first colour layer: the
// direction products summed in an accumulator of their own, saturated and
// brought to accumulator units. The same for every sample of the ray in one
// MLP, so it is computed once per ray and MLP.
struct TmeDirTerms {
  std::vector<int64_t> term;  // per neuron of the first colour layer
  uint64_t saturations = 0;   // partial sums clipped (counted again per sample)
};

// A ray's direction as the colour net's INT8 inputs: computed once per ray
// (Tme::direction_input) and used by each of its samples. It also keeps the
// direction terms of the MLP that last evaluated it (Tme::eval_batch), so a
// ray whose samples in one coarse voxel come in several batches has them
// made once; direction_input() drops them.
class Tme;

struct TmeDirection {
  std::vector<int32_t> x;    // dir_dims activation codes
  uint64_t saturations = 0;  // codes clipped on the way (counted again per sample)
  // The terms and whose they are: the Tme and the index of its MLP.
  TmeDirTerms terms;
  const Tme* terms_tme = nullptr;
  int32_t terms_mlp = -1;
};

class Tme {
 public:
  // delta: sample spacing in scene units. Throws Error if the model has no
  // INT8 MLPs or one does not fit mlp_cache_bytes.
  Tme(const SceneModel& model, const ChipNumerics& numerics, double delta, size_t mlp_cache_bytes);

  // Makes the MLP of CV `cv_tag` current (a load when it is not already).
  void load(uint32_t cv_tag);
  // The index of CV cv_tag's MLP. Throws Error when it has none.
  int32_t mlp_of(uint32_t cv_tag) const;
  // The current MLP's index (-1 before the first load).
  int32_t current_mlp() const { return current_; }
  // Makes MLP `index` current without counting a load: for evaluating work
  // out of order whose loads were counted in the hardware's order.
  void select(int32_t index);
  // Evaluates the current MLP. feature: F interpolated features (CFIU
  // format); dir_code: the ray's direction encoding (encode_direction).
  TmeOutput eval(const int32_t* feature, const std::vector<int32_t>& dir_code);
  // The direction inputs of a ray (the requantization eval() does per sample),
  // into `out` (its storage reused).
  void direction_input(const std::vector<int32_t>& dir_code, TmeDirection& out) const;
  // Evaluates the current MLP on `samples` samples at once, as that many
  // eval() calls would (same outputs, same counters): features holds F values
  // per sample, dirs[s] the direction inputs of sample s's ray (their
  // direction terms for this MLP are made there when missing, and kept).
  void eval_batch(size_t samples, const int32_t* features, TmeDirection* const* dirs, TmeOutput* out);

  // Direction encoding [d, sin(2^k d), cos(2^k d) for k < L] as signed
  // direction_code_bits codes with direction_code_frac_bits fraction bits.
  static std::vector<int32_t> encode_direction(const Vec3d& dir, int frequencies, const ChipNumerics& numerics);
  // The same into `out` (resized; its storage reused).
  static void encode_direction(const Vec3d& dir, int frequencies, const ChipNumerics& numerics,
                               std::vector<int32_t>& out);

  const TmeMlp& mlp(size_t i) const { return mlps_[i]; }
  size_t mlp_count() const { return mlps_.size(); }
  const ActivationLut& alpha_lut() const { return alpha_lut_; }
  const ActivationLut& sigmoid_lut() const { return sigmoid_lut_; }
  const TmeCounters& counters() const { return counters_; }

 private:
  template <fx::Rounding M>
  void eval_batch_as(size_t samples, const int32_t* features, TmeDirection* const* dirs, TmeOutput* out);
  // One layer for every sample (kMaxLayerWidth values per sample in x and y).
  // split >= 0: inputs from `split` on are direction inputs, whose part of
  // each sample's sums is dir_terms[sample] (x holds only the first `split`).
  template <fx::Rounding M>
  void layer_batch(const TmeLayer& L, size_t samples, const int32_t* x, int32_t* y, bool hidden, int out_bits,
                   int split, const TmeDirTerms* const* dir_terms);
  // The direction terms of `d` for layer L, whose inputs from `split` on are
  // the direction inputs, brought to accumulator units by q.
  template <fx::Rounding M>
  void direction_terms(const TmeLayer& L, int split, const fx::Requant& q, const TmeDirection& d, TmeDirTerms& t);

  const SceneModel& model_;
  ChipNumerics n_;
  // Scratch of eval_batch: activations and sums, kMaxLayerWidth per sample.
  std::vector<int32_t> act_a_, act_b_, sum_main_, abs_x_, abs_sum_;
  std::vector<const TmeDirTerms*> term_of_sample_;  // per sample: its ray's direction terms
  std::vector<const int64_t*> term_rows_;           // per sample: term_of_sample_[s]->term.data()
  TmeDirection eval_dir_;                           // eval()'s direction inputs
  std::vector<TmeMlp> mlps_;
  ActivationLut alpha_lut_, sigmoid_lut_;
  fx::Requant dir_code_;  // direction code -> INT8 direction input (step 1 / (2^(activation_bits-1) - 1))
  int32_t current_ = -1;
  TmeCounters counters_;
};

}  // namespace edrnr::chip
