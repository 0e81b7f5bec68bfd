#pragma once
// The CFIU's feature cache state (paper Sections III-C, IV-F, Fig. 9, Fig. 15):
// lines, the MSHR and the reservation monitor, and the balanced bank
// allocation. Pure state and decisions, no time: the functional model calls it
// directly, the cycle simulator adds the DRAM latency between a miss and its
// fill.
//
// One cache line holds one fine-voxel feature block (125 vertices x F INT4
// channels). The line's 125 vertex vectors are spread over 8 feature banks
// (FSRAMs) so that the 8 corners of any micro voxel of the block sit in 8
// different banks and are fetched in one cycle.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "model/scene_model.h"

namespace edrnr::chip {

inline constexpr int kFeatureBanks = 8;

// How vertex vectors map to banks.
//   Balanced: bank = vertex type XOR (line % 8). The vertex type (i&1) |
//     (j&1)<<1 | (k&1)<<2 of vertex (i,j,k) differs between the 8 corners of a
//     micro voxel, and XOR with a constant is a bijection, so fetches are
//     conflict free; the rotation from line to line makes every aligned group
//     of 8 lines use exactly 125 rows in every bank (the type counts
//     27/18/18/18/12/12/12/8 summed over all 8 rotations).
//   Direct: bank = vertex type (conflict free, but bank depths 27:8 per line).
//   Linear: bank = vertex index % 8 (a naive layout, with conflicts).
enum class BankMapping { Balanced, Direct, Linear };

const char* bank_mapping_name(BankMapping m);
// Parses "balanced", "direct" or "linear"; throws Error naming `what` otherwise.
BankMapping parse_bank_mapping(const std::string& name, const std::string& what);

// Vertex index v = i + 5 (j + 5 k) of vertex (i, j, k) of a 5x5x5 block.
constexpr int block_vertex(int i, int j, int k) { return i + kBlockVertsPerAxis * (j + kBlockVertsPerAxis * k); }
// The vertex type (i&1) | (j&1)<<1 | (k&1)<<2, 0..7.
int vertex_type(int vertex);

// Where each vertex vector of each line lives in the banks.
class BankLayout {
 public:
  BankLayout(BankMapping mapping, int lines);

  BankMapping mapping() const { return mapping_; }
  int lines() const { return lines_; }
  int bank(int line, int vertex) const;
  int row(int line, int vertex) const;
  // Rows a bank must have to hold all lines (the same for every bank with
  // Balanced when lines is a multiple of 8).
  int bank_depth(int bank) const { return depth_[size_t(bank)]; }
  // Rows of `bank` used by the vertices of one line.
  int rows_used(int line, int bank) const;
  // The bank of each of the 8 corners (corner c = dx | dy<<1 | dz<<2) of micro
  // voxel (a, b, c), 0..3 each, of a line's block.
  std::array<int, 8> corner_banks(int line, const Vec3i& micro_in_fine) const;
  // Extra cycles a fetch of those 8 corners needs: (most corners in one bank) - 1.
  static int conflict_cycles(const std::array<int, 8>& banks);
  // True when every micro voxel's 8 corners lie in 8 different banks, one
  // each (balanced and direct: the corners' vertex types differ in their axis
  // parities), so a fetch reads each bank once and never conflicts.
  bool corners_one_per_bank() const { return mapping_ != BankMapping::Linear; }

 private:
  BankMapping mapping_;
  int lines_;
  std::array<int, kFeatureBanks> depth_{};
  std::array<int, kBlockVerts> rank_{};          // index of a vertex among the vertices of its type
  std::array<int, kFeatureBanks> type_count_{};  // vertices per type: 27, 18, 18, 12, 18, 12, 12, 8
  std::array<std::array<int, kFeatureBanks>, kFeatureBanks> group_offset_{};  // [rotation][bank]
};

// Outcome of a feature-cache request.
enum class CacheAccess {
  Hit,            // the line is present
  MissMerged,     // the line is already being fetched; the MSHR merged this request
  MissAllocated,  // a line was allocated (a victim evicted if needed) and an MSHR entry opened
  Stall,          // no MSHR entry free or every line reserved or pending: nothing changed
};

struct FeatureCacheConfig {
  int lines = 256;
  int mshr_entries = 16;
  BankMapping mapping = BankMapping::Balanced;
};

struct FeatureCacheCounters {
  uint64_t requests = 0;
  uint64_t hits = 0;
  uint64_t misses = 0;         // MSHR entries opened (one DRAM block fetch each)
  uint64_t merged_misses = 0;  // requests merged into an open MSHR entry
  uint64_t stalls = 0;
  uint64_t evictions = 0;
  uint64_t fills = 0;
  uint64_t peak_reserved_lines = 0;
  uint64_t peak_mshr_used = 0;
};

// Line state, LRU replacement, MSHR and reservation monitor.
//   request(block)  looks the block up and reserves its line for the
//                   requester (also on a merged miss); see CacheAccess.
//   fill(block)     the block's data arrived: the line becomes valid and its
//                   MSHR entry closes.
//   use(block)      a reserved, valid line is read: it becomes most recently used.
//   release(block)  the requester is done: one reservation is dropped.
// A victim is the least recently used line that is neither reserved nor
// pending; invalid lines are taken first, lowest index first.
class FeatureCache {
 public:
  // Throws Error if lines < 1 or mshr_entries < 1.
  explicit FeatureCache(const FeatureCacheConfig& config);

  CacheAccess request(uint32_t block);
  void fill(uint32_t block);  // throws std::logic_error unless an MSHR entry is open for it
  int use(uint32_t block);    // returns the line; throws std::logic_error unless valid and reserved
  void release(uint32_t block);

  bool present(uint32_t block) const;  // valid (not pending)
  bool pending(uint32_t block) const;
  std::optional<int> line_of(uint32_t block) const;
  int reservations(uint32_t block) const;
  // Open MSHR entries, oldest first (block indices).
  const std::vector<uint32_t>& mshr() const { return mshr_; }
  const BankLayout& layout() const { return layout_; }
  const FeatureCacheCounters& counters() const { return counters_; }
  int lines() const { return int(lines_.size()); }

 private:
  enum class State : uint8_t { Invalid, Pending, Valid };
  struct Line {
    State state = State::Invalid;
    uint32_t block = 0;
    int reserved = 0;
    uint64_t last_use = 0;
  };
  int find(uint32_t block) const;
  Line& line_for(uint32_t block, const char* op);

  FeatureCacheConfig config_;
  BankLayout layout_;
  std::vector<Line> lines_;
  std::vector<int32_t> line_of_;  // block -> line for pending and valid lines, -1 for none (grown to the largest block)
  std::vector<uint32_t> mshr_;
  uint64_t clock_ = 0;
  FeatureCacheCounters counters_;
};

}  // namespace edrnr::chip
