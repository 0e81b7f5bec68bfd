#include "sim/sram_budget.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "chip/rp_buffer.h"
#include "chip/zorg.h"
#include "model/scene_model.h"

namespace edrnr::sim {

namespace {

// Bits to tell n values apart (at least 1).
uint64_t bits_for(uint64_t n) {
  uint64_t b = 1;
  while (b < 64 && (uint64_t(1) << b) < n) ++b;
  return b;
}

uint64_t bytes_of_bits(uint64_t bits) { return (bits + 7) / 8; }

uint64_t float_bits(const FloatFormat& f) { return uint64_t(f.total_bits()); }

}  // namespace

const char* sram_class_name(SramClass c) {
  switch (c) {
    case SramClass::MicroGrid:
      return "micro_grid";
    case SramClass::Feature:
      return "feature";
    case SramClass::Mlp:
      return "mlp";
    case SramClass::Others:
      return "others";
  }
  return "?";
}

uint64_t SramBudget::total_bytes() const {
  uint64_t t = 0;
  for (uint64_t b : class_bytes) t += b;
  return t;
}

bool SramBudget::over_budget() const { return !violations().empty(); }

std::vector<std::string> SramBudget::violations() const {
  std::vector<std::string> out;
  for (int c = 0; c < kSramClasses; ++c) {
    if (class_bytes[c] <= class_budget[c]) continue;
    std::vector<const SramBuffer*> in;
    for (const SramBuffer& b : buffers)
      if (int(b.sram_class) == c) in.push_back(&b);
    std::sort(in.begin(), in.end(), [](auto* a, auto* b) { return a->bytes > b->bytes; });
    std::string largest;
    for (size_t i = 0; i < in.size() && i < 3; ++i)
      largest += fmt::format("{}{} {} B", i ? ", " : "", in[i]->name, in[i]->bytes);
    out.push_back(fmt::format("SRAM class '{}' needs {} bytes, {} over its budget of {} bytes (largest: {})",
                              sram_class_name(SramClass(c)), class_bytes[c], class_bytes[c] - class_budget[c],
                              class_budget[c], largest));
  }
  return out;
}

std::string SramBudget::format() const {
  std::string s = fmt::format("{:<28} {:>10}  {:<10}  {}\n", "buffer", "bytes", "class", "from");
  for (const SramBuffer& b : buffers)
    s += fmt::format("{:<28} {:>10}  {:<10}  {}\n", b.name, b.bytes, sram_class_name(b.sram_class), b.formula);
  for (int c = 0; c < kSramClasses; ++c)
    s += fmt::format("{:<28} {:>10}  of {:>8} ({:5.1f} %){}\n", std::string("class ") + sram_class_name(SramClass(c)),
                     class_bytes[c], class_budget[c],
                     class_budget[c] ? 100.0 * double(class_bytes[c]) / double(class_budget[c]) : 0.0,
                     class_bytes[c] > class_budget[c] ? "  OVER BUDGET" : "");
  return s;
}

nlohmann::json SramBudget::to_json() const {
  nlohmann::json j;
  j["buffers"] = nlohmann::json::array();
  for (const SramBuffer& b : buffers)
    j["buffers"].push_back(
        {{"name", b.name}, {"class", sram_class_name(b.sram_class)}, {"bytes", b.bytes}, {"formula", b.formula}});
  for (int c = 0; c < kSramClasses; ++c)
    j["classes"][sram_class_name(SramClass(c))] = {{"bytes", class_bytes[c]}, {"budget_bytes", class_budget[c]}};
  j["total_bytes"] = total_bytes();
  j["over_budget"] = over_budget();
  return j;
}

SramBudget compute_sram_budget(const SimConfig& config, const SramModelShape& shape) {
  const ChipConfig& chip = config.chip;
  const ChipNumerics& n = chip.numerics;
  const SimTiming& t = config.timing;
  SramBudget b;
  b.class_budget[int(SramClass::MicroGrid)] = config.sram_budget.micro_grid_bytes;
  b.class_budget[int(SramClass::Feature)] = config.sram_budget.feature_bytes;
  b.class_budget[int(SramClass::Mlp)] = config.sram_budget.mlp_bytes;
  b.class_budget[int(SramClass::Others)] = config.sram_budget.others_bytes;
  auto add = [&](std::string name, SramClass c, uint64_t bytes, std::string formula) {
    b.buffers.push_back({std::move(name), c, bytes, std::move(formula)});
    b.class_bytes[int(c)] += bytes;
  };

  const uint64_t rm = uint64_t(std::max(32, shape.micro_res));
  const uint64_t rf = rm / 4, rc = rm / 32;
  const uint64_t F = uint64_t(std::max(1, shape.feature_channels));
  // Widths every buffer shares.
  const uint64_t rp_ptr_bits = bits_for(uint64_t(chip.rp_buffer_capacity));
  const uint64_t cv_tag_bits = 3 * bits_for(rc);
  const uint64_t block_bits = bits_for(rf * rf * rf);  // a feature block (fine voxel) index
  // Candidates per ray: the scene box diagonal over the step, plus the ends.
  const uint64_t max_candidates = uint64_t(std::ceil(double(rm) * std::sqrt(3.0) / double(chip.step_micro))) + 2;
  const uint64_t k_bits = bits_for(max_candidates);
  const uint64_t fbits = float_bits(n.traversal_float);
  const uint64_t block_bytes = (uint64_t(kBlockVerts) * F * uint64_t(n.feature_bits) + 7) / 8;
  const uint64_t feature_lines = uint64_t(feature_cache_lines(chip, int(F)));

  // ---- the three caches of Table I (data arrays).
  add("micro_grid_cache", SramClass::MicroGrid, uint64_t(chip.micro_grid_cache_bytes),
      "micro_grid_cache_bytes (64-bit words of occupied fine voxels)");
  add("feature_cache", SramClass::Feature, feature_lines * block_bytes,
      fmt::format("{} lines x {} B blocks (125 vertices x {} channels x {} bits), 8 banks", feature_lines, block_bytes,
                  F, n.feature_bits));
  add("mlp_cache", SramClass::Mlp, uint64_t(chip.mlp_cache_bytes), "mlp_cache_bytes");

  // ---- others: occupancy bitmaps.
  add("coarse_bitmap", SramClass::Others, bytes_of_bits(rc * rc * rc), fmt::format("{}^3 bits", rc));
  add("fine_bitmap", SramClass::Others, bytes_of_bits(rf * rf * rf), fmt::format("{}^3 bits", rf));

  // ---- the global RP buffer: one shared origin, four rays, the packet's place.
  const uint64_t ray_bits = 2 /* valid, terminated */ + 3 * fbits /* direction */ + 2 * k_bits /* k, k_end */ +
                            uint64_t(n.transmittance_bits) + 3 * uint64_t(n.color_bits);
  const uint64_t packet_bits = 3 * fbits /* origin */ + 4 * ray_bits + 2 * 11 /* pixel quad x, y */ +
                               4 /* valid pixels */ + 3 /* travel signs */ + cv_tag_bits;
  add("rp_buffer", SramClass::Others, uint64_t(chip.rp_buffer_capacity) * bytes_of_bits(packet_bits),
      fmt::format("{} RPs x {} bits (origin, 4 x (direction, k, k_end, T, rgb, flags), quad, CV tag)",
                  chip.rp_buffer_capacity, packet_bits));

  // ---- RP-ROB: placeholders (RP pointer, ready bit), entry labels and counts, recorder.
  const uint64_t entries = uint64_t(chip.rp_rob.entries), depth = uint64_t(chip.rp_rob.entry_depth);
  const uint64_t rob_bits = entries * depth * (rp_ptr_bits + 1) + entries * (cv_tag_bits + bits_for(depth + 1)) +
                            uint64_t(chip.rp_rob.recent_tags) * cv_tag_bits;
  add("rp_rob", SramClass::Others, bytes_of_bits(rob_bits),
      fmt::format("{} entries x {} placeholders x {} bits + labels + {} recent tags", entries, depth, rp_ptr_bits + 1,
                  chip.rp_rob.recent_tags));

  // ---- OoO-SI: the location shifter and the computation SRAM.
  const uint64_t slots = uint64_t(chip.ooo_queue_depth) + 1;
  const uint64_t ls_bits = uint64_t(chip.ooo_queue_depth) * (1 + rp_ptr_bits + block_bits + bits_for(slots));
  add("location_shifter", SramClass::Others, bytes_of_bits(ls_bits),
      fmt::format("{} entries x (valid, RP pointer, block, base address)", chip.ooo_queue_depth));
  // A CCRP_SP holds the samples of one RP in one fine voxel: per ray at most
  // the candidates along a fine voxel's diagonal (4 sqrt 3 micro edges).
  const uint64_t per_ray = uint64_t(std::ceil(4.0 * std::sqrt(3.0) / double(chip.step_micro))) + 1;
  const uint64_t max_batch = 4 * per_ray;
  add("computation_sram", SramClass::Others, bytes_of_bits(slots * max_batch * (2 + k_bits)),
      fmt::format("{} batch slots x {} samples x (ray, k: {} bits)", slots, max_batch, 2 + k_bits));

  // ---- TME: the MLP held in the MAC array's weight registers.
  add("tme_weights", SramClass::Others, uint64_t(t.tme_weight_buffers) * shape.mlp_bytes,
      fmt::format("{} x one MLP as stored (weights, biases, multipliers)", t.tme_weight_buffers));

  // ---- queues between units (pipeline registers included).
  const uint64_t token_bits = rp_ptr_bits + 2;
  add("fifo_cfiu_to_tme", SramClass::Others,
      bytes_of_bits(uint64_t(t.cfiu_latency_cycles + t.cfiu_fifo_slots) *
                    (F * uint64_t(n.interp_feature_bits) + token_bits)),
      "slots x (interpolated feature, sample token)");
  add("fifo_tme_to_vru", SramClass::Others,
      bytes_of_bits(uint64_t(t.tme_latency_cycles + t.tme_fifo_slots) *
                    (uint64_t(n.alpha_bits) + 3 * uint64_t(n.color_bits) + token_bits)),
      "slots x (alpha, rgb, sample token)");
  add("fifo_rp_pointers", SramClass::Others,
      bytes_of_bits((uint64_t(t.front_end_latency_cycles) + 1 + 2 * uint64_t(chip.rp_buffer_capacity)) * rp_ptr_bits),
      "front end -> CTU, retire -> CTU and VRU decision queues of RP pointers");

  // ---- cache tags and MSHRs (tag arrays are SRAM beside the data arrays).
  const uint64_t micro_lines = uint64_t(chip.micro_grid_cache_bytes) / config.memory.micro_grid_cache.line_bytes;
  const uint64_t mlp_lines = uint64_t(chip.mlp_cache_bytes) / config.memory.mlp_cache.line_bytes;
  const uint64_t dram_line_bits = 32;  // a DRAM line address
  add("cache_tags", SramClass::Others,
      bytes_of_bits(feature_lines * (block_bits + 1 + 4) + micro_lines * (dram_line_bits + 1) +
                    mlp_lines * (dram_line_bits + 1)),
      "feature lines x (block, valid, 4-bit reservation count); micro-grid and MLP lines x (address, valid)");
  add("mshrs", SramClass::Others,
      bytes_of_bits(uint64_t(chip.mshr_entries) * block_bits +
                    (config.memory.micro_grid_cache.mshr_entries + config.memory.mlp_cache.mshr_entries) *
                        dram_line_bits),
      "feature, micro-grid and MLP miss registers");
  return b;
}

}  // namespace edrnr::sim
