// The engine's memory side: fills and their retries, MLP loads and prefetches.
#include "sim/engine.h"

namespace edrnr::sim::engine {

// Starts copying the MLP of CV `tag` into the free weight buffer.
void Engine::start_mlp_load(uint32_t tag, uint64_t c) {
  TmeShell& s = tme_s_;
  if (t_.tme_weight_buffers == 1) s.active = false;  // the single buffer is overwritten
  s.loading = true;
  s.shadow_ready = false;
  s.load_tag = tag;
  s.load_end = c + ceil_div(mlp_bytes_, uint64_t(t_.tme_weight_load_bytes_per_cycle));
  s.next_line = 0;
  s.waiting.clear();
  const uint32_t mlp = uint32_t(model_.coarse_to_mlp[tag]);
  s.lines.clear();
  bool on_chip = true;
  for (uint64_t i = 0; i < mlp_lines_; ++i) {
    s.lines.push_back(map_.mlp(mlp) + i * cfg_.memory.mlp_cache.line_bytes);
    on_chip = on_chip && mlp_cache_.lookup(s.lines.back());
  }
  s.load_on_chip = on_chip;
  ++mlp_switches_;
}

// With a shadow buffer: the OoO-SI issued a batch of CV `tag`; load its MLP
// now unless it is active, loaded, or the shadow buffer is taken.
void Engine::early_mlp_load(uint32_t tag) {
  TmeShell& s = tme_s_;
  if (t_.tme_weight_buffers < 2 || s.loading || s.shadow_ready) return;
  if (s.active && s.active_tag == tag) return;
  start_mlp_load(tag, cycle_);
}

// The RP-ROB switched to `tag`: its MLP's lines are fetched ahead of the TME.
void Engine::start_mlp_prefetch(uint32_t tag) {
  prefetch_started_ = true;
  prefetch_tag_ = tag;
  prefetch_lines_.clear();
  prefetch_next_ = 0;
  const int32_t mlp = model_.coarse_to_mlp[tag];
  if (mlp < 0) return;
  for (uint64_t i = 0; i < mlp_lines_; ++i)
    prefetch_lines_.push_back(map_.mlp(uint32_t(mlp)) + i * cfg_.memory.mlp_cache.line_bytes);
}

void Engine::issue_next_mlp_prefetch(uint64_t c) {
  const uint64_t addr = prefetch_lines_[prefetch_next_];
  const CacheOutcome o = mlp_cache_.prefetch(addr, c);
  if (o == CacheOutcome::MissStalled) return;
  if (o == CacheOutcome::MissIssued)
    mem_.read(DataType::MlpWeights, addr, uint32_t(cfg_.memory.mlp_cache.line_bytes), addr, c);
  ++prefetch_next_;
}

void Engine::deliver(const MemoryCompletion& m) {
  switch (m.type) {
    case DataType::Bitmaps:
      bitmaps_ready_ = true;
      break;
    case DataType::MicroGrid:
      if (!micro_cache_.fill(m.tag, cycle_).filled) retry_micro_.push_back(m.tag);
      fill_words_micro_ += cfg_.memory.micro_grid_cache.line_bytes / 8;
      break;
    case DataType::MlpWeights:
      if (!mlp_cache_.fill(m.tag, cycle_).filled) retry_mlp_.push_back(m.tag);
      fill_words_mlp_ += cfg_.memory.mlp_cache.line_bytes / 8;
      break;
    case DataType::Features:
      cfiu_.cache().fill(uint32_t(m.tag));
      ++feature_fills_;
      break;
    case DataType::RpOutput:
      break;
  }
}

void Engine::retry_refused_fills() {
  for (auto* pair : {&retry_micro_, &retry_mlp_}) {
    if (pair->empty()) continue;
    Cache& cache = pair == &retry_micro_ ? micro_cache_ : mlp_cache_;
    std::vector<uint64_t> still;
    for (uint64_t a : *pair)
      if (!cache.fill(a, cycle_).filled) still.push_back(a);
    pair->swap(still);
  }
}

}  // namespace edrnr::sim::engine
