// The engine's results: chip counters, statistics, energy events and the
// SimResult of a finished frame.
#include <algorithm>

#include "sim/engine.h"

namespace edrnr::sim::engine {

namespace {

// The RP state a traversal unit reads and writes back per visit: four rays of
// origin and direction (3 x 25-bit traversal floats each) and two 22-bit
// candidate indices, 776 bits, in 64-bit words of the "others" SRAM.
constexpr uint64_t kRpTraversalStateWords = 13;

}  // namespace

void Engine::count_per_access(AccessCount& a, bool hit, size_t samples) {
  if (samples == 0) return;
  a.hits += hit ? samples : samples - 1;
  a.misses += hit ? 0 : 1;
}

ChipCounters Engine::chip_counters() const {
  ChipCounters c =
      unit_counters({zorg_, front_, ctu_, ftu_, rob_, ooo_, cfiu_, arithmetic_.tme(), arithmetic_.vru(), buffer_});
  c.ftu = ftu_counts_;
  if (ftu_ahead_) {  // two threads (the worker has stopped by now)
    c.tme.mlp_loads = mlp_loads_;
    c.tme.mlp_load_bytes = mlp_load_bytes_;
    // The batches the engine made itself (their MLP loads are counted above).
    const TmeCounters& t = main_arithmetic_->tme().counters();
    c.tme.samples += t.samples;
    c.tme.macs += t.macs;
    c.tme.saturations += t.saturations;
    const VruCounters& v = main_arithmetic_->vru().counters();
    c.vru.samples += v.samples;
    c.vru.samples_skipped += v.samples_skipped;
    c.vru.rays_terminated += v.rays_terminated;
  }
  c.packets_dropped = packets_dropped_;
  c.cv_transitions = cv_transitions_;
  c.fine_reschedules = fine_reschedules_;
  c.rps_finished = rps_finished_;
  c.fill_waits = ooo_.counters().waits;
  return c;
}

EnergyRun Engine::energy_run(const ChipCounters& c) const {
  EnergyRun run;
  run.cycles = cycles_;
  run.pixels = uint64_t(image_.width) * uint64_t(image_.height);
  auto& e = run.event_counts;
  const uint64_t F = uint64_t(model_.feature_channels);
  const uint64_t position_evals = c.tsps_position_evals + c.ctu.position_evals + c.ftu.position_evals;
  // Ray generation: a rotation (9 multiplies, 6 adds) and a normalisation
  // (6 multiplies, 3 adds); ABT: a slab test, 6 multiply-adds and 6 compares
  // per ray. Position evaluations: one fused multiply-add in the traversal float.
  e["fp32_mult"] = c.rays * (15 + 6) + position_evals;
  e["fp32_add"] = c.rays * (9 + 6) + position_evals;
  e["int32_compare"] = c.rays * 6 + c.ctu.coarse_checks + c.ftu.leaf_checks + c.ftu.micro_checks;
  // Interpolation: per corner and channel one multiply-accumulate; the TME:
  // one INT8 multiply and INT20 add per MAC, one 16-bit requantization
  // multiply per neuron; the VRU: 5 multiplies and 4 adds per sample.
  e["int8_mult"] = c.tme.macs;
  e["int20_add"] = c.tme.macs + c.cfiu.samples * 8 * F;
  e["int16_mult"] = c.cfiu.samples * 8 * F + c.tme.samples * neurons_per_sample_ + c.vru.samples * 5;
  e["int16_add"] = c.vru.samples * 4;
  // SRAMs, per 64-bit word.
  e["micro_grid_sram_read"] = c.ftu.micro_word_reads;
  e["micro_grid_sram_write"] = fill_words_micro_;
  e["feature_sram_read"] = c.cfiu.corner_reads;
  e["feature_sram_write"] = feature_fills_ * ceil_div(map_.feature_block_bytes, 8);
  e["mlp_sram_read"] = mlp_switches_ * ceil_div(mlp_bytes_, 8);
  e["mlp_sram_write"] = fill_words_mlp_;
  // Others: the fine bitmap, the RP buffer (traversal state per CTU/FTU
  // visit; transmittance and colour per sample) and the computation SRAM
  // (one sample position per half word, written by the FTU, read by the SCC).
  e["other_sram_read"] =
      c.ftu.fine_checks + (ctu_runs_ + ftu_runs_) * kRpTraversalStateWords + c.vru.samples + ceil_div(c.ftu.samples, 2);
  e["other_sram_write"] = (uint64_t(zorg_.packet_count()) + ctu_runs_ + ftu_runs_) * kRpTraversalStateWords +
                          c.vru.samples + ceil_div(c.ftu.samples, 2);
  // Clock distribution, control and pipeline registers, which the
  // per-operation rows leave out: one event per core cycle (its energy is
  // fitted, docs/energy.md).
  e["core_cycle"] = cycles_;
  // Registers: the MLP copied into the MAC array; each sample's interpolated
  // feature (CFIU -> TME) and its alpha and colour (TME -> VRU).
  e["register_bit"] = mlp_switches_ * mlp_bytes_ * 8 +
                      c.cfiu.samples * (F * uint64_t(n_.interp_feature_bits) + 4 * uint64_t(n_.alpha_bits));
  const uint64_t dram_bytes = uint64_t(stats_.get("dram.read_bytes")) + uint64_t(stats_.get("dram.write_bytes"));
  if (cfg_.energy.dram == DramEnergySource::Events) {
    e["dram_bit"] = dram_bytes * 8;
  } else if (cfg_.energy.dram == DramEnergySource::Model) {
    run.dram_model_energy_pJ = mem_.dram().energy().total_pJ();
  } else {
    const DramEnergy d = mem_.dram().energy();
    run.dram_model_energy_pJ = d.activate_pJ + d.read_pJ + d.write_pJ;
    e["dram_io_bit"] = dram_bytes * 8;
  }
  return run;
}

void Engine::finish_result() {
  mem_.update_stats();
  res_.image = std::move(image_);
  res_.chip = chip_counters();
  const ChipCounters& cc = res_.chip;
  SimSummary& s = res_.summary;
  s.cycles = cycles_;
  s.clock_MHz = cfg_.clock_MHz;
  s.frame_time_s = double(cycles_) / (cfg_.clock_MHz * 1e6);
  s.fps = 1.0 / s.frame_time_s;
  s.pixels = uint64_t(res_.image.width) * uint64_t(res_.image.height);
  s.samples = cc.cfiu.samples;
  s.samples_per_cycle = ratio(double(s.samples), double(cycles_));
  const uint64_t slowest = std::max<uint64_t>(
      {uint64_t(t_.cfiu_cycles_per_sample), tme_cycles_per_sample_, uint64_t(t_.vru_cycles_per_sample)});
  s.peak_samples_per_cycle = 1.0 / double(slowest);
  s.micro_grid_hit_rate = micro_cache_.stats().hit_rate();
  uint64_t fhits = 0, faccesses = 0;
  for (const HitRateWindow& w : feature_series_.series()) fhits += w.hits, faccesses += w.accesses;
  s.feature_hit_rate = ratio(double(fhits), double(faccesses));
  uint64_t mhits = 0, maccesses = 0;
  for (const HitRateWindow& w : mlp_series_.series()) mhits += w.hits, maccesses += w.accesses;
  s.mlp_hit_rate = ratio(double(mhits), double(maccesses));
  s.feature_hit_rate_per_access =
      ratio(double(feature_access_.hits), double(feature_access_.hits + feature_access_.misses));
  s.mlp_hit_rate_per_access = ratio(double(mlp_access_.hits), double(mlp_access_.hits + mlp_access_.misses));
  s.dram_read_bytes = uint64_t(stats_.get("dram.read_bytes"));
  s.dram_write_bytes = uint64_t(stats_.get("dram.write_bytes"));
  s.coarse_rays_per_iteration = cc.coarse_rays_per_iteration();
  s.fine_rays_per_iteration = cc.fine_rays_per_iteration();
  s.rps_per_tag_switch = cc.rps_per_tag_switch();

  StatsRegistry& r = stats_;
  auto cnt = [&](const std::string& name, const char* unit, const char* what, uint64_t v) {
    r.counter(name, unit, what).value = v;
  };
  auto val = [&](const std::string& name, const char* unit, const char* what, double v) {
    r.value(name, unit, what).set(v);
  };
  cnt("sim.cycles", "cycles", "core cycles to render the frame", s.cycles);
  val("sim.clock_MHz", "MHz", "core clock", s.clock_MHz);
  val("sim.frame_time_s", "s", "frame time at the core clock", s.frame_time_s);
  val("sim.fps", "frames/s", "frames per second at the core clock", s.fps);
  cnt("sim.pixels", "pixels", "pixels in the frame", s.pixels);
  cnt("sim.samples", "samples", "samples interpolated", s.samples);
  val("sim.samples_per_cycle", "samples", "samples per cycle, averaged over the frame", s.samples_per_cycle);
  val("sim.peak_samples_per_cycle", "samples", "samples per cycle the slowest of CFIU, TME and VRU allows",
      s.peak_samples_per_cycle);
  val("sim.coarse_rays_per_iteration", "rays", "rays advancing together per RP in coarse traversal (paper 3.89)",
      s.coarse_rays_per_iteration);
  val("sim.fine_rays_per_iteration", "rays", "rays advancing together per RP in fine traversal (paper 3.48)",
      s.fine_rays_per_iteration);
  val("sim.rps_per_tag_switch", "CCRPs", "CCRPs scheduled per CV tag switch", s.rps_per_tag_switch);
  cnt("sim.mlp_switches", "switches", "MLPs copied into the TME's MAC array", mlp_switches_);
  cnt("sim.tme_cycles_per_sample", "cycles", "TME cycles per sample (MACs per sample / MACs per cycle)",
      tme_cycles_per_sample_);
  cnt("sim.macs_per_sample", "MACs", "multiply-accumulates per sample of one MLP", macs_per_sample_);
  cnt("host.skipped_cycles", "cycles", "cycles counted in bulk, not stepped: no unit could act in them",
      skipped_cycles_);
  for (uint32_t u = 0; u < kUnits; ++u)
    for (int st = 0; st < kUnitStates; ++st) {
      const std::string name =
          std::string("sim.unit.") + kUnitNames[u] + "." + unit_state_name(UnitState(st)) + "_cycles";
      static const char* const what[kUnitStates] = {
          "cycles working", "cycles holding a result the next unit cannot take",
          "cycles waiting for data from memory (or a feature cache MSHR entry)", "cycles with nothing to do"};
      cnt(name, "cycles", what[st], activity_.cycles(u, UnitState(st)));
    }
  fe_out_.account_until(cycles_);  // the cycles since each FIFO last changed
  retire_q_.account_until(cycles_);
  tme_in_.account_until(cycles_);
  vru_in_.account_until(cycles_);
  fe_out_.export_stats(r, "sim.fifo.front_end_to_ctu");
  retire_q_.export_stats(r, "sim.fifo.retire_to_ctu");
  tme_in_.export_stats(r, "sim.fifo.cfiu_to_tme");
  vru_in_.export_stats(r, "sim.fifo.tme_to_vru");
  micro_cache_.export_stats(r, "cache.micro_grid");
  mlp_cache_.export_stats(r, "cache.mlp_weights");
  const FeatureCacheCounters& fc = cfiu_.cache().counters();
  cnt("cache.features.accesses", "requests", "block requests served (retries after a stall excluded)", faccesses);
  cnt("cache.features.hits", "requests", "requests whose block was on chip", fhits);
  cnt("cache.features.misses", "requests", "requests whose block was not (fetched or merged)", faccesses - fhits);
  val("cache.features.hit_rate", "ratio", "hits / accesses", s.feature_hit_rate);
  cnt("cache.features.misses_issued", "blocks", "blocks fetched from DRAM", fc.misses);
  cnt("cache.features.misses_merged", "requests", "misses merged by the MSHR", fc.merged_misses);
  cnt("cache.features.stall_cycles", "cycles", "requests refused: no MSHR entry or no unreserved line", fc.stalls);
  cnt("cache.features.evictions", "lines", "lines evicted", fc.evictions);
  cnt("cache.mlp.batches", "batches", "batches reaching the TME", maccesses);
  cnt("cache.mlp.batch_hits", "batches", "batches whose MLP was on chip (in the MAC array or the MLP cache)", mhits);
  val("cache.mlp.hit_rate", "ratio", "batch_hits / batches (the MLP hit rate of the report)", s.mlp_hit_rate);
  for (auto [name, a] : {std::pair{"features", feature_access_}, std::pair{"mlp", mlp_access_}}) {
    const std::string p = std::string("cache.") + name + ".per_access.";
    cnt(p + "accesses", "samples", "samples reading the data (a missed batch: its first sample misses)",
        a.hits + a.misses);
    cnt(p + "hits", "samples", "samples that found the data on chip", a.hits);
    cnt(p + "misses", "samples", "samples that waited for it", a.misses);
    val(p + "hit_rate", "ratio", "hits / accesses, per sample (the paper's Fig. 8 counts per access)",
        ratio(double(a.hits), double(a.hits + a.misses)));
  }
  res_.sram_budget = compute_sram_budget(cfg_, {model_.micro_res, model_.feature_channels, mlp_bytes_});
  for (const SramBuffer& b : res_.sram_budget.buffers)
    cnt("sram." + b.name + "_bytes", "bytes", "on-chip buffer size (docs/simulator.md, SRAM budget)", b.bytes);
  for (int k = 0; k < kSramClasses; ++k)
    cnt(std::string("sram.class.") + sram_class_name(SramClass(k)) + "_bytes", "bytes", "buffers of this Table I class",
        res_.sram_budget.class_bytes[k]);
  cnt("cache.features.bank_reads", "reads", "vertex vectors read from the 8 banks", cc.cfiu.corner_reads);
  cnt("cache.features.bank_conflict_cycles", "cycles", "extra CFIU cycles from two corners in one bank",
      cc.cfiu.conflict_cycles);
  export_chip_stats(cc, r, "chip");

  res_.hit_rate_series = {
      {"micro_grid", hit_rate_series_json(micro_cache_.hit_rate_series(), cfg_.hit_rate_window_cycles)},
      {"features", hit_rate_series_json(feature_series_.series(), cfg_.hit_rate_window_cycles)},
      {"mlp_weights", hit_rate_series_json(mlp_series_.series(), cfg_.hit_rate_window_cycles)},
      {"mlp_weight_lines", hit_rate_series_json(mlp_cache_.hit_rate_series(), cfg_.hit_rate_window_cycles)}};
  if (opt_.trace_cycles > 0) res_.trace = activity_.chrome_trace(cfg_.clock_MHz);
  res_.energy_run = energy_run(cc);
  if (!cfg_.energy.events_csv.empty()) {
    const OperatingPoint point = operating_point_at(cfg_, cfg_.clock_MHz, &res_.voltage_extrapolated);
    res_.energy = evaluate_energy(cfg_, res_.energy_run, point);
    export_stats(*res_.energy, r, "energy");
    val("energy.voltage_V", "V", "core supply at the configured clock (from the operating points)", point.voltage_V);
  }
}

}  // namespace edrnr::sim::engine
