#include "chip/ftu.h"

#include <bit>

#include "chip/ctu.h"
#include "chip/lfau.h"
#include "core/error.h"

namespace edrnr::chip {

namespace {
constexpr int kLeafCellMicro = 2;

// Voxel indices here are never negative (micro indices are clamped to
// [0, Rm)), so unsigned division (a shift) gives the signed quotient.
Vec3i coarse_of(const Vec3i& fine) {
  return {int(unsigned(fine.x) / kFinePerCoarse), int(unsigned(fine.y) / kFinePerCoarse),
          int(unsigned(fine.z) / kFinePerCoarse)};
}
Vec3i leaf_cell_of(const Vec3i& micro) {
  return {int(unsigned(micro.x) / kLeafCellMicro), int(unsigned(micro.y) / kLeafCellMicro),
          int(unsigned(micro.z) / kLeafCellMicro)};
}

int micro_bit(int lx, int ly, int lz) { return lx + kMicroPerFine * (ly + kMicroPerFine * lz); }

// Whether any of the 8 micro bits of leaf voxel (leaf_x, leaf_y, leaf_z) is set.
bool leaf_occupied(uint64_t word, int leaf_x, int leaf_y, int leaf_z) {
  // The leaf's bits, at its corner (0, 0, 0): x + 4 y + 16 z for x, y, z in {0, 1}.
  constexpr uint64_t kLeafBits = 0x330033;
  return (word & (kLeafBits << micro_bit(2 * leaf_x, 2 * leaf_y, 2 * leaf_z))) != 0;
}
}  // namespace

Ftu::Ftu(const SceneModel& model, const RayMath& math, bool lag_first, size_t micro_grid_cache_words)
    : model_(model), math_(math), lag_first_(lag_first), micro_grid_cache_(micro_grid_cache_words) {
  const Bitmap3& fine = model.occupancy[int(Tier::Fine)];
  if (model.fine_to_block.size() != fine.size()) fail("model lookups are missing (call finalize())");
  // Every occupied fine voxel has a block; the micro-grid word of each
  // block's fine voxel is gathered once.
  block_words_.assign(model.block_count(), 0);
  for (size_t f = 0; f < fine.size(); ++f) {
    const int32_t b = model.fine_to_block[f];
    if (b >= 0)
      block_words_[size_t(b)] = gather_micro_word(uint32_t(f));
    else if (fine.get(f))
      fail("model: occupied fine voxel {} has no feature block", f);
  }
}

uint64_t Ftu::micro_word(uint32_t fine_index) const {
  const int32_t b = model_.fine_to_block[fine_index];
  return b >= 0 ? block_words_[size_t(b)] : gather_micro_word(fine_index);
}

uint64_t Ftu::gather_micro_word(uint32_t fine_index) const {
  // Each row of 4 micro voxels along x is 4 aligned bits of the micro bitmap
  // (4 * fine x is a multiple of 4, and so is the resolution).
  const Bitmap3& micro = model_.occupancy[int(Tier::Micro)];
  const int fr = model_.fine_res();
  const int fx = int(fine_index % uint32_t(fr)), fy = int(fine_index / uint32_t(fr) % uint32_t(fr)),
            fz = int(fine_index / uint32_t(fr * fr));
  uint64_t w = 0;
  for (int lz = 0; lz < kMicroPerFine; ++lz)
    for (int ly = 0; ly < kMicroPerFine; ++ly) {
      const size_t i = micro.index(kMicroPerFine * fx, kMicroPerFine * fy + ly, kMicroPerFine * fz + lz);
      const uint64_t row = (micro.words()[i >> 6] >> (i & 63)) & 0xF;
      w |= row << micro_bit(0, ly, lz);
    }
  return w;
}

bool Ftu::run(RayPacket& rp, uint32_t rp_pointer, uint32_t cv_tag, SampleBatch& batch) {
  const Bitmap3& fine = model_.occupancy[int(Tier::Fine)];
  const int cr = model_.coarse_res();
  // Each ray's fine voxel at candidate known_k (a ray the LFAU did not
  // select keeps its candidate, and its point depends on (ray, k) only).
  std::array<int64_t, kRaysPerPacket> known_k{};
  std::array<Vec3i, kRaysPerPacket> known_f{};
  uint8_t known = 0;
  // Each ray's face crossings, shared by its fine-voxel and leaf exits and
  // kept with the ray for its next traversals while its k_end stays.
  for (RayState& ray : rp.rays)
    if (ray.exit_memo_limit != ray.k_end) {
      ray.exit_memo = {};
      ray.exit_memo_limit = ray.k_end;
    }
  auto in_cv = [&](const Vec3i& f) {
    const Vec3i c = coarse_of(f);
    return linear_index(c.x, c.y, c.z, cr) == cv_tag;
  };
  for (;;) {
    // The live rays inside the CV, and their fine voxels.
    uint8_t active = 0;
    std::array<Vec3i, kRaysPerPacket> fv{};
    for (int r = 0; r < kRaysPerPacket; ++r) {
      const RayState& ray = rp.rays[size_t(r)];
      if (!ray.live()) continue;
      Vec3i f;
      if (!(known >> r & 1) || known_k[size_t(r)] != ray.k) {
        f = math_.cell_at(ray.ray, ray.k, kMicroPerFine);
        known_f[size_t(r)] = f;
        known_k[size_t(r)] = ray.k;
        known |= uint8_t(1u << r);
      } else {
        f = known_f[size_t(r)];
      }
      if (!in_cv(f)) continue;
      active |= uint8_t(1u << r);
      fv[size_t(r)] = f;
    }
    if (!active) return false;
    LfauSelection sel;
    uint32_t fine_index;
    if ((active & (active - 1)) == 0) {
      // One ray in the CV: the LFAU selects it (both orders). It walks the
      // empty fine voxels alone; no other ray's voxel changes meanwhile.
      const int r = std::countr_zero(unsigned(active));
      RayState& ray = rp.rays[size_t(r)];
      Vec3i f = fv[size_t(r)];
      for (;;) {
        ++counters_.iterations;
        ++counters_.rays_advanced;
        ++counters_.fine_checks;
        fine_index = uint32_t(fine.index(f.x, f.y, f.z));
        if (fine.get(fine_index)) break;
        ray.k = math_.cell_exit(ray.ray, ray.k, ray.k_end, f, kMicroPerFine, &counters_.position_evals, ray.exit_memo,
                                ray.k_end);
        if (!ray.live()) return false;
        f = math_.cell_at(ray.ray, ray.k, kMicroPerFine);
        known_f[size_t(r)] = f;
        known_k[size_t(r)] = ray.k;
        if (!in_cv(f)) return false;
      }
      sel.selected_mask = uint8_t(active);
      sel.voxel = f;
    } else {
      sel = lfau_select(fv, active, rp.travel_sign, lag_first_);
      ++counters_.iterations;
      counters_.rays_advanced += uint64_t(sel.selected_rays());
      ++counters_.fine_checks;
      fine_index = uint32_t(fine.index(sel.voxel.x, sel.voxel.y, sel.voxel.z));
    }
    if (!fine.get(fine_index)) {
      for (int r = 0; r < kRaysPerPacket; ++r) {
        if (!(sel.selected_mask >> r & 1)) continue;
        RayState& ray = rp.rays[size_t(r)];
        ray.k = math_.cell_exit(ray.ray, ray.k, ray.k_end, sel.voxel, kMicroPerFine, &counters_.position_evals,
                                ray.exit_memo, ray.k_end);
      }
      continue;
    }
    // Occupied fine voxel: one micro-grid word serves the leaf and micro checks.
    const uint64_t word = micro_word(fine_index);
    ++counters_.micro_word_reads;
    counters_.micro_word_hits += micro_grid_cache_.access(fine_index);
    if (micro_read_log_) micro_read_log_->push_back(fine_index);
    batch.rp = rp_pointer;
    batch.cv_tag = cv_tag;
    batch.fine_index = fine_index;
    batch.block = model_.fine_to_block[fine_index];
    batch.ray_mask = sel.selected_mask;
    batch.samples.clear();
    const Vec3i base{kMicroPerFine * sel.voxel.x, kMicroPerFine * sel.voxel.y, kMicroPerFine * sel.voxel.z};
    for (int r = 0; r < kRaysPerPacket; ++r) {
      if (!(sel.selected_mask >> r & 1)) continue;
      RayState& ray = rp.rays[size_t(r)];
      RayMath::ExitMemo& memo = ray.exit_memo;
      const int64_t k_exit = math_.cell_exit(ray.ray, ray.k, ray.k_end, sel.voxel, kMicroPerFine,
                                             &counters_.position_evals, memo, ray.k_end);
      int64_t k = ray.k;
      Vec3i m;
      bool m_known = false;  // m is already the micro voxel of candidate k (evaluated again, counted again)
      while (k < k_exit) {
        if (!m_known) m = math_.micro_voxel_at(ray.ray, k);
        m_known = false;
        ++counters_.position_evals;
        const Vec3i leaf = leaf_cell_of(m - base);
        ++counters_.leaf_checks;
        if (!leaf_occupied(word, leaf.x, leaf.y, leaf.z)) {
          const Vec3i leaf_cell = leaf_cell_of(m);
          k = math_.cell_exit(ray.ray, k, k_exit, leaf_cell, kLeafCellMicro, &counters_.position_evals, memo,
                              ray.k_end);
          continue;
        }
        // Occupied leaf: test each candidate until the ray leaves the leaf.
        const Vec3i leaf_cell = leaf_cell_of(m);
        Vec3i last_micro{-1, -1, -1};
        bool last_occupied = false;
        for (bool first = true; k < k_exit; ++k, first = false) {
          const Vec3i mk = first ? m : math_.micro_voxel_at(ray.ray, k);
          ++counters_.position_evals;
          if (leaf_cell_of(mk) != leaf_cell) {
            m = mk;
            m_known = true;
            break;
          }
          ++counters_.candidate_tests;
          if (mk != last_micro) {
            ++counters_.micro_checks;
            last_micro = mk;
            last_occupied = word >> micro_bit(mk.x - base.x, mk.y - base.y, mk.z - base.z) & 1;
          }
          if (last_occupied) batch.samples.push_back({uint8_t(r), k});
        }
      }
      ray.k = k_exit;
    }
    if (batch.samples.empty()) continue;
    counters_.samples += batch.samples.size();
    ++counters_.batches;
    return true;
  }
}

}  // namespace edrnr::chip
