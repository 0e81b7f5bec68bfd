// The .edrnr format: round trips, the documented byte layout, and rejection of
// corrupt input with a message that names what is wrong.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_io.h"
#include "model/footprint.h"
#include "model/model_io.h"

namespace edrnr {
namespace {

struct Forms {
  bool q4 = true, f32 = true, mlp_q8 = true, mlp_f32 = true;
};

// A small model built by hand: a few occupied micro voxels inside the object
// AABB, one block per occupied fine voxel, one MLP per occupied coarse voxel.
SceneModel small_model(int micro_res, int channels, Forms forms = {}) {
  SceneModel m;
  m.micro_res = micro_res;
  m.feature_channels = channels;
  m.scene_box = {{-1.f, -1.f, -1.f}, {1.f, 1.f, 1.f}};
  m.object_aabb = {{-0.5f, -0.5f, -0.5f}, {0.75f, 0.5f, 0.5f}};
  m.init_grids();
  const float points[][3] = {{-0.4f, -0.4f, -0.4f}, {-0.35f, -0.4f, -0.4f}, {0.1f, 0.0f, 0.2f},
                             {0.7f, 0.45f, -0.45f}, {0.3f, -0.2f, 0.4f},    {-0.1f, 0.3f, 0.0f}};
  for (const auto& p : points) {
    int v[3];
    for (int a = 0; a < 3; ++a) v[a] = int(std::floor((p[a] + 1.f) / 2.f * float(micro_res)));
    m.occupancy[int(Tier::Micro)].set(v[0], v[1], v[2]);
  }
  m.rebuild_upper_tiers();
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  for (size_t i = 0; i < fine.size(); ++i)
    if (fine.get(i)) m.block_fine_index.push_back(uint32_t(i));
  m.features_f32.resize(m.block_count() * kBlockVerts * size_t(channels));
  for (size_t i = 0; i < m.features_f32.size(); ++i) m.features_f32[i] = std::sin(0.37f * float(i)) * 2.f;
  if (forms.q4) m.quantize_features();
  if (!forms.f32) m.features_f32.clear();

  m.mlp_arch.dir_frequencies = 1;
  m.mlp_arch.density_widths = {channels, 8, 4};
  m.mlp_arch.color_widths = {4 + 9, 6, 3};
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i)) m.mlp_coarse_index.push_back(uint32_t(i));
  float x = 0.f;
  for (size_t k = 0; k < m.mlp_count(); ++k) {
    MlpF f;
    MlpQ q;
    for (auto [widths, fnet, qnet] : {std::tuple{&m.mlp_arch.density_widths, &f.density, &q.density},
                                      std::tuple{&m.mlp_arch.color_widths, &f.color, &q.color}})
      for (size_t l = 1; l < widths->size(); ++l) {
        int in = (*widths)[l - 1], out = (*widths)[l];
        DenseF df{in, out, std::vector<float>(size_t(in * out)), std::vector<float>(size_t(out))};
        DenseQ dq{in,
                  out,
                  std::vector<int8_t>(size_t(in * out)),
                  std::vector<float>(size_t(out)),
                  std::vector<float>(size_t(out)),
                  0.125f};
        for (size_t i = 0; i < df.w.size(); ++i, x += 1.f) {
          df.w[i] = std::cos(x);
          dq.w[i] = int8_t(int(x) % 255 - 127);
        }
        for (int o = 0; o < out; ++o, x += 1.f) {
          df.b[size_t(o)] = 0.01f * x;
          dq.b[size_t(o)] = -0.02f * x;
          dq.w_scale[size_t(o)] = 1.f / (1.f + x);
        }
        fnet->push_back(df);
        qnet->push_back(dq);
      }
    if (forms.mlp_f32) m.mlps_f32.push_back(f);
    if (forms.mlp_q8) m.mlps_q8.push_back(q);
  }
  m.metadata_json = R"({"scene": "hand-built", "seed": 7})";
  m.finalize();
  return m;
}

void expect_same_model(const SceneModel& a, const SceneModel& b) {
  EXPECT_EQ(a.scene_box, b.scene_box);
  EXPECT_EQ(a.object_aabb, b.object_aabb);
  EXPECT_EQ(a.micro_res, b.micro_res);
  for (int t = 0; t < kTierCount; ++t) EXPECT_TRUE(a.occupancy[t] == b.occupancy[t]) << tier_name(Tier(t));
  EXPECT_EQ(a.feature_channels, b.feature_channels);
  EXPECT_EQ(a.block_fine_index, b.block_fine_index);
  EXPECT_EQ(a.features_f32, b.features_f32);
  EXPECT_EQ(a.features_q4, b.features_q4);
  EXPECT_EQ(a.feature_quant, b.feature_quant);
  EXPECT_EQ(a.mlp_arch, b.mlp_arch);
  EXPECT_EQ(a.mlp_coarse_index, b.mlp_coarse_index);
  EXPECT_EQ(a.mlps_f32, b.mlps_f32);
  EXPECT_EQ(a.mlps_q8, b.mlps_q8);
  EXPECT_EQ(a.metadata_json, b.metadata_json);
  EXPECT_EQ(a.fine_to_block, b.fine_to_block);
  EXPECT_EQ(a.coarse_to_mlp, b.coarse_to_mlp);
}

// ---- the documented layout, read independently of the loader ----

uint32_t get_u32(const std::vector<uint8_t>& b, size_t at) {
  return uint32_t(b[at]) | uint32_t(b[at + 1]) << 8 | uint32_t(b[at + 2]) << 16 | uint32_t(b[at + 3]) << 24;
}
uint64_t get_u64(const std::vector<uint8_t>& b, size_t at) {
  return uint64_t(get_u32(b, at)) | uint64_t(get_u32(b, at + 4)) << 32;
}
void put_u32(std::vector<uint8_t>& b, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
void put_u64(std::vector<uint8_t>& b, size_t at, uint64_t v) {
  put_u32(b, at, uint32_t(v));
  put_u32(b, at + 4, uint32_t(v >> 32));
}

uint32_t zlib_crc(const std::vector<uint8_t>& b) {
  return uint32_t(crc32(crc32(0L, Z_NULL, 0), b.data() + 32, uInt(b.size() - 32)));
}
void fix_crc(std::vector<uint8_t>& b) { put_u32(b, 24, zlib_crc(b)); }

struct Entry {
  std::string tag;
  size_t table_at;  // byte offset of the table entry
  uint64_t offset, size;
};

std::vector<Entry> section_table(const std::vector<uint8_t>& b) {
  std::vector<Entry> out;
  for (uint32_t i = 0; i < get_u32(b, 12); ++i) {
    size_t at = 32 + 24 * size_t(i);
    out.push_back(
        {std::string(b.begin() + long(at), b.begin() + long(at) + 4), at, get_u64(b, at + 8), get_u64(b, at + 16)});
  }
  return out;
}

Entry find_section(const std::vector<uint8_t>& b, const std::string& tag) {
  for (const Entry& e : section_table(b))
    if (e.tag == tag) return e;
  ADD_FAILURE() << "no section " << tag;
  return {};
}

// Rebuilds a file from (tag, body) pairs, as docs/format.md lays it out.
std::vector<uint8_t> build_file(const std::vector<std::pair<std::string, std::vector<uint8_t>>>& sections,
                                uint32_t version = 1) {
  size_t table_end = 32 + 24 * sections.size();
  std::vector<uint8_t> b(table_end, 0);
  std::memcpy(b.data(), "EDRNRMDL", 8);
  put_u32(b, 8, version);
  put_u32(b, 12, uint32_t(sections.size()));
  for (size_t i = 0; i < sections.size(); ++i) {
    while (b.size() % 8) b.push_back(0);
    size_t at = 32 + 24 * i;
    std::memcpy(b.data() + at, sections[i].first.data(), 4);
    put_u64(b, at + 8, b.size());
    put_u64(b, at + 16, sections[i].second.size());
    b.insert(b.end(), sections[i].second.begin(), sections[i].second.end());
  }
  put_u64(b, 16, b.size());
  fix_crc(b);
  return b;
}

std::vector<std::pair<std::string, std::vector<uint8_t>>> split_file(const std::vector<uint8_t>& b) {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
  for (const Entry& e : section_table(b))
    out.push_back({e.tag, std::vector<uint8_t>(b.begin() + long(e.offset), b.begin() + long(e.offset + e.size))});
  return out;
}

std::vector<uint8_t>& body(std::vector<std::pair<std::string, std::vector<uint8_t>>>& s, const std::string& tag) {
  for (auto& [t, bytes] : s)
    if (t == tag) return bytes;
  throw std::runtime_error("no section " + tag);
}

void remove_section(std::vector<std::pair<std::string, std::vector<uint8_t>>>& s, const std::string& tag) {
  std::erase_if(s, [&](const auto& p) { return p.first == tag; });
}

std::string parse_error(const std::vector<uint8_t>& b, ModelLoadOptions options = {}) {
  try {
    parse_model(b.data(), b.size(), "t.edrnr", options);
  } catch (const Error& e) {
    return e.what();
  }
  return "(parsed without error)";
}

#define EXPECT_PARSE_ERROR(bytes, text)                                   \
  do {                                                                    \
    std::string msg_ = parse_error(bytes);                                \
    EXPECT_NE(msg_.find(text), std::string::npos) << "message: " << msg_; \
    EXPECT_EQ(msg_.rfind("t.edrnr: ", 0), 0u) << "message: " << msg_;     \
  } while (0)

// ---- round trips ----

TEST(ModelIo, RoundTripAllForms) {
  SceneModel m = small_model(64, 4);
  ASSERT_GT(m.block_count(), 3u);
  ASSERT_GT(m.mlp_count(), 1u);
  std::vector<uint8_t> bytes = serialize_model(m);
  expect_same_model(parse_model(bytes.data(), bytes.size()), m);
}

TEST(ModelIo, RoundTripSomeFormsAbsent) {
  for (Forms forms : {Forms{true, false, true, false}, Forms{false, true, false, true}, Forms{true, false, false, true},
                      Forms{false, true, true, false}}) {
    SceneModel m = small_model(32, 3, forms);  // 3 channels: an odd nibble count per block
    std::vector<uint8_t> bytes = serialize_model(m);
    SceneModel back = parse_model(bytes.data(), bytes.size());
    expect_same_model(back, m);
    EXPECT_EQ(back.features_q4.empty(), !forms.q4);
    EXPECT_EQ(back.mlps_f32.empty(), !forms.mlp_f32);
  }
}

TEST(ModelIo, RoundTripEmptyModel) {
  SceneModel m;
  m.micro_res = 32;
  m.init_grids();
  m.finalize();
  std::vector<uint8_t> bytes = serialize_model(m);
  SceneModel back = parse_model(bytes.data(), bytes.size());
  expect_same_model(back, m);
  // No optional sections: GRID, OCC0-3, BIDX, MIDX, META.
  EXPECT_EQ(section_table(bytes).size(), 8u);
}

TEST(ModelIo, SaveAndLoadFile) {
  SceneModel m = small_model(32, 2);
  auto path = std::filesystem::temp_directory_path() / ("edrnr_test_model_io_" + std::to_string(::getpid()));
  save_model(path, m);
  expect_same_model(load_model(path), m);
  std::filesystem::remove(path);
  EXPECT_THROW(load_model(path), Error);
}

TEST(ModelIo, SerializeIsDeterministicAndStable) {
  SceneModel m = small_model(64, 4);
  std::vector<uint8_t> a = serialize_model(m), b = serialize_model(m);
  EXPECT_EQ(a, b);
  SceneModel back = parse_model(a.data(), a.size());
  EXPECT_EQ(serialize_model(back), a);
}

// ---- the byte layout of docs/format.md ----

TEST(ModelIo, HeaderAndSectionLayout) {
  SceneModel m = small_model(32, 3, Forms{true, false, true, false});
  std::vector<uint8_t> b = serialize_model(m);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 8), "EDRNRMDL");
  EXPECT_EQ(get_u32(b, 8), kModelFormatVersion);
  EXPECT_EQ(get_u64(b, 16), b.size());
  EXPECT_EQ(get_u32(b, 24), zlib_crc(b));
  EXPECT_EQ(get_u32(b, 28), 0u);
  std::vector<std::string> tags;
  for (const Entry& e : section_table(b)) {
    tags.push_back(e.tag);
    EXPECT_EQ(e.offset % 8, 0u) << e.tag;
    EXPECT_LE(e.offset + e.size, b.size()) << e.tag;
  }
  EXPECT_EQ(tags, (std::vector<std::string>{"GRID", "OCC0", "OCC1", "OCC2", "OCC3", "BIDX", "MIDX", "FEQ4", "MARC",
                                            "MLQ8", "META"}));
  const uint64_t blocks = m.block_count(), mlps = m.mlp_count();
  EXPECT_EQ(find_section(b, "GRID").size, 64u);
  EXPECT_EQ(find_section(b, "OCC0").size, 1u);     // 1^3 bits
  EXPECT_EQ(find_section(b, "OCC1").size, 64u);    // 8^3 / 8
  EXPECT_EQ(find_section(b, "OCC2").size, 512u);   // 16^3 / 8
  EXPECT_EQ(find_section(b, "OCC3").size, 4096u);  // 32^3 / 8
  EXPECT_EQ(find_section(b, "BIDX").size, 4 * blocks);
  EXPECT_EQ(find_section(b, "MIDX").size, 4 * mlps);
  EXPECT_EQ(find_section(b, "FEQ4").size, 5 * 3 + (blocks * 375 + 1) / 2);
  EXPECT_EQ(find_section(b, "MARC").size, 12u + 4 * 6);
  // INT8 layer: in_scale + (w_scale, bias) per output + weights: 3->8, 8->4, 13->6, 6->3.
  uint64_t per_mlp = (4 + 8 * 8 + 24) + (4 + 8 * 4 + 32) + (4 + 8 * 6 + 78) + (4 + 8 * 3 + 18);
  EXPECT_EQ(find_section(b, "MLQ8").size, mlps * per_mlp);
  EXPECT_EQ(find_section(b, "META").size, m.metadata_json.size());

  // GRID fields.
  Entry grid = find_section(b, "GRID");
  EXPECT_EQ(std::bit_cast<float>(get_u32(b, grid.offset)), -1.f);        // scene box lo.x
  EXPECT_EQ(std::bit_cast<float>(get_u32(b, grid.offset + 36)), 0.75f);  // object AABB hi.x
  EXPECT_EQ(get_u32(b, grid.offset + 48), 32u);
  EXPECT_EQ(get_u32(b, grid.offset + 52), 3u);
  EXPECT_EQ(get_u32(b, grid.offset + 56), blocks);
  EXPECT_EQ(get_u32(b, grid.offset + 60), mlps);

  // Bit i of a bitmap is bit i % 8 of byte i / 8. The point (0.1, 0.0, 0.2) is micro voxel (17, 16, 19).
  Entry occ3 = find_section(b, "OCC3");
  size_t i = 17 + 32 * (16 + 32 * 19);
  EXPECT_TRUE((b[occ3.offset + i / 8] >> (i % 8)) & 1);
  EXPECT_FALSE((b[occ3.offset + (i + 1) / 8] >> ((i + 1) % 8)) & 1);
  // The block index lists fine voxel (4, 4, 4) (= micro (17, 16, 19) / 4) among its entries.
  Entry bidx = find_section(b, "BIDX");
  bool found = false;
  for (uint64_t k = 0; k < blocks; ++k) found |= get_u32(b, bidx.offset + 4 * k) == 4 + 8 * (4 + 8 * 4);
  EXPECT_TRUE(found);
}

TEST(ModelIo, DramFootprintByDataType) {
  SceneModel m = small_model(64, 4);
  DramFootprint f = dram_footprint(m);
  EXPECT_EQ(f.coarse_bitmap_bytes, 1u);  // 2^3 bits
  EXPECT_EQ(f.fine_bitmap_bytes, 512u);  // 16^3 bits
  size_t fine_occupied = m.occupancy[int(Tier::Fine)].count();
  EXPECT_EQ(f.micro_grid_bytes, 8 * fine_occupied);
  EXPECT_EQ(f.feature_bytes, m.block_count() * 250);  // 125 vertices x 4 nibbles
  // density 4->8->4, colour 13->6->3: 32 + 32 + 78 + 18 = 160 weights, 8+4+6+3 = 21 outputs,
  // 4 + 2 input-stage multipliers.
  EXPECT_EQ(f.mlp_weight_bytes, m.mlp_count() * (160 + 8 * 21 + 4 * 6));
  EXPECT_EQ(f.total_bytes(), 1 + 512 + 8 * fine_occupied + m.block_count() * 250 + m.mlp_count() * 352);
  EXPECT_EQ(feature_block_q4_bytes(16), 1000u);
  EXPECT_EQ(feature_block_q4_bytes(3), 188u);  // 375 nibbles
}

// ---- model checks ----

std::vector<std::string> failing_checks(const SceneModel& m) {
  std::vector<std::string> out;
  for (const ModelCheck& c : model_checks(m))
    if (!c.passed) {
      out.push_back(c.name);
      EXPECT_FALSE(c.detail.empty()) << c.name;
    }
  return out;
}

TEST(ModelChecks, EachViolationFailsItsCheck) {
  using Names = std::vector<std::string>;
  SceneModel m = small_model(64, 2);  // occupied CVs (linear index): 0, 3, 5, 6, 7
  EXPECT_EQ(model_checks(m).size(), 8u);
  EXPECT_EQ(failing_checks(m), Names{});

  SceneModel t = m;
  t.occupancy[int(Tier::Coarse)].set(size_t(1));
  EXPECT_EQ(failing_checks(t),
            (Names{"coarse tier is the OR of the fine tier", "every occupied coarse voxel has an MLP"}));
  EXPECT_FALSE(t.check_invariants().empty());

  t = m;  // an MLP in the empty CV 1: not an invariant of SceneModel, but a corrupt file
  t.mlp_coarse_index.insert(t.mlp_coarse_index.begin() + 1, 1);
  t.mlps_f32.insert(t.mlps_f32.begin() + 1, t.mlps_f32[0]);
  t.mlps_q8.insert(t.mlps_q8.begin() + 1, t.mlps_q8[0]);
  t.finalize();
  EXPECT_EQ(failing_checks(t), Names{"every MLP lies in an occupied coarse voxel"});
  EXPECT_TRUE(t.check_invariants().empty());
  std::vector<uint8_t> b = serialize_model(t);
  EXPECT_PARSE_ERROR(b, "1 MLPs lie in empty coarse voxels");

  t = m;
  t.block_fine_index.erase(t.block_fine_index.begin());
  t.features_f32.erase(t.features_f32.begin(), t.features_f32.begin() + kBlockVerts * 2);
  t.features_q4.clear();
  t.feature_quant = {};
  t.finalize();
  EXPECT_EQ(failing_checks(t), Names{"every occupied fine voxel has a feature block"});
  EXPECT_FALSE(t.check_invariants().empty());

  t = m;
  t.object_aabb.hi.x = 0.5f;  // the micro voxel at x = 0.7 is now outside
  EXPECT_EQ(failing_checks(t), Names{"no occupied micro voxel lies outside the object AABB"});
  EXPECT_FALSE(t.check_invariants().empty());
}

// ---- rejection ----

TEST(ModelIoReject, BadMagic) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  b[3] = 'X';
  EXPECT_PARSE_ERROR(b, "magic");
  EXPECT_PARSE_ERROR(std::vector<uint8_t>{}, "magic");
}

TEST(ModelIoReject, NewerVersion) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  put_u32(b, 8, kModelFormatVersion + 1);
  EXPECT_PARSE_ERROR(b, "format version 2 is newer than this edrnr supports (1)");
  put_u32(b, 8, 0);
  EXPECT_PARSE_ERROR(b, "format version 0 is not valid");
}

TEST(ModelIoReject, CrcMismatch) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  b[b.size() / 2] ^= 0x10;
  EXPECT_PARSE_ERROR(b, "CRC-32 mismatch");
  fix_crc(b);  // with the CRC fixed up the flip may or may not be valid, but must not pass the CRC check
  EXPECT_EQ(parse_error(b).find("CRC"), std::string::npos);
}

TEST(ModelIoReject, EveryTruncationAndExtension) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 1, Forms{true, false, true, false}));
  for (size_t n = 0; n < b.size(); ++n) {
    std::vector<uint8_t> prefix(b.begin(), b.begin() + long(n));
    EXPECT_THROW(parse_model(prefix.data(), prefix.size()), Error) << "prefix of " << n << " bytes";
  }
  std::vector<uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_PARSE_ERROR(longer, "truncated or padded");
}

TEST(ModelIoReject, TruncationWithFixedUpHeader) {
  // Cut the file inside the last section but make the header agree: the table must catch it.
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  b.resize(b.size() - 5);
  put_u64(b, 16, b.size());
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "lies outside the data area");
}

TEST(ModelIoReject, SectionOutsideFile) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  Entry occ3 = find_section(b, "OCC3");
  put_u64(b, occ3.table_at + 8, b.size() + 64);
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "section OCC3 (micro occupancy) at offset");
  put_u64(b, occ3.table_at + 8, occ3.offset);
  put_u64(b, occ3.table_at + 16, std::numeric_limits<uint64_t>::max());  // offset + size wraps around
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "lies outside the data area");
  put_u64(b, occ3.table_at + 16, occ3.size);
  put_u64(b, occ3.table_at + 8, 40);  // inside the section table
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "lies outside the data area");
}

TEST(ModelIoReject, OverlappingSections) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  Entry bidx = find_section(b, "BIDX"), occ3 = find_section(b, "OCC3");
  put_u64(b, bidx.table_at + 8, occ3.offset + 8);
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "overlap");
}

TEST(ModelIoReject, TableProblems) {
  auto s = split_file(serialize_model(small_model(32, 2)));
  auto dup = s;
  dup[6].first = "BIDX";  // MIDX renamed: BIDX twice
  EXPECT_PARSE_ERROR(build_file(dup), "section BIDX (block index) appears twice");
  auto unknown = s;
  unknown[1].first = "OCCX";
  EXPECT_PARSE_ERROR(build_file(unknown), "unknown tag \"OCCX\"");
  auto missing = s;
  remove_section(missing, "OCC2");
  EXPECT_PARSE_ERROR(build_file(missing), "required section OCC2 (leaf occupancy) is missing");
  EXPECT_PARSE_ERROR(build_file({}), "section count 0");
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  put_u32(b, 12, 1u << 31);
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "section count 2147483648");
}

TEST(ModelIoReject, MetadataIsOptionalButMustBeAnObject) {
  auto s = split_file(serialize_model(small_model(32, 2)));
  auto no_meta = s;
  remove_section(no_meta, "META");
  std::vector<uint8_t> b = build_file(no_meta);
  EXPECT_EQ(parse_model(b.data(), b.size()).metadata_json, "{}");
  std::string bad = R"({"scene": )";
  body(s, "META").assign(bad.begin(), bad.end());
  EXPECT_PARSE_ERROR(build_file(s), "section META (metadata): the text is not a JSON object");
  std::string array = "[1, 2]";
  body(s, "META").assign(array.begin(), array.end());
  EXPECT_PARSE_ERROR(build_file(s), "not a JSON object");
}

TEST(ModelIoReject, GridValues) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  Entry grid = find_section(b, "GRID");
  for (auto [res, ok] : {std::pair{48, false}, std::pair{0, false}, std::pair{-32, false}, std::pair{2048, false}}) {
    std::vector<uint8_t> c = b;
    put_u32(c, grid.offset + 48, uint32_t(res));
    fix_crc(c);
    EXPECT_PARSE_ERROR(c, fmt::format("micro_res {} is not a positive multiple of 32 up to 1024", res));
  }
  for (int channels : {0, 65}) {
    std::vector<uint8_t> c = b;
    put_u32(c, grid.offset + 52, uint32_t(channels));
    fix_crc(c);
    EXPECT_PARSE_ERROR(c, fmt::format("feature_channels {} is not in 1..64", channels));
  }
  std::vector<uint8_t> c = b;
  put_u32(c, grid.offset + 4, std::bit_cast<uint32_t>(std::numeric_limits<float>::quiet_NaN()));
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "scene box y range");
  c = b;
  put_u32(c, grid.offset + 24, std::bit_cast<uint32_t>(2.f));  // object AABB lo.x above hi.x
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "object AABB x range [2, 0.75]");
}

TEST(ModelIoReject, HugeCounts) {
  SceneModel m = small_model(32, 2);
  std::vector<uint8_t> b = serialize_model(m);
  Entry grid = find_section(b, "GRID");
  std::vector<uint8_t> c = b;
  put_u32(c, grid.offset + 56, 1u << 31);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "block count 2147483648 exceeds the 512 fine voxels of micro_res 32");
  c = b;
  put_u32(c, grid.offset + 60, 1u << 31);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "MLP count 2147483648 exceeds the 1 coarse voxels");
  // A plausible count that does not match the section.
  c = b;
  put_u32(c, grid.offset + 56, uint32_t(m.block_count() + 1));
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, fmt::format("section BIDX (block index) is {} bytes, expected {} for {} blocks",
                                    4 * m.block_count(), 4 * (m.block_count() + 1), m.block_count() + 1));
  // Width counts of the MLP shape.
  c = b;
  Entry marc = find_section(b, "MARC");
  put_u32(c, marc.offset + 4, 1u << 31);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "the density net has 2147483648 widths, expected 2..9");
}

TEST(ModelIoReject, SectionSizeForResolution) {
  auto s = split_file(serialize_model(small_model(32, 2)));
  body(s, "OCC3").resize(1000);
  EXPECT_PARSE_ERROR(build_file(s), "section OCC3 (micro occupancy) is 1000 bytes, expected 4096 for micro_res 32");
}

TEST(ModelIoReject, UnsortedAndOutOfRangeBlockIndices) {
  SceneModel m = small_model(32, 2);
  ASSERT_GE(m.block_count(), 3u);
  std::vector<uint8_t> b = serialize_model(m);
  Entry bidx = find_section(b, "BIDX");
  std::vector<uint8_t> c = b;
  put_u32(c, bidx.offset, m.block_fine_index[1]);
  put_u32(c, bidx.offset + 4, m.block_fine_index[0]);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section BIDX (block index): entry 1");
  EXPECT_PARSE_ERROR(c, "strictly ascending");
  c = b;
  put_u32(c, bidx.offset + 4, m.block_fine_index[0]);  // a duplicate
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "strictly ascending");
  c = b;
  put_u32(c, bidx.offset + 4 * (m.block_count() - 1), 512);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "is fine voxel 512, but there are only 512");
  Entry midx = find_section(b, "MIDX");
  c = b;
  put_u32(c, midx.offset, 1);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section MIDX (MLP index): entry 0 is coarse voxel 1, but there are only 1");
}

TEST(ModelIoReject, TierOrViolation) {
  SceneModel m = small_model(32, 2);
  std::vector<uint8_t> b = serialize_model(m);
  // Clear the micro voxel of (0.1, 0.0, 0.2), alone in its fine voxel: the upper tiers no longer match.
  Entry occ3 = find_section(b, "OCC3");
  size_t i = 17 + 32 * (16 + 32 * 19);
  b[occ3.offset + i / 8] &= uint8_t(~(1u << (i % 8)));
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "the model is corrupt");
  EXPECT_PARSE_ERROR(b, "leaf tier is not the OR of the micro tier");
  // Without the checks it loads, and model_checks names the failing tiers.
  SceneModel loose = parse_model(b.data(), b.size(), "t", ModelLoadOptions{false});
  int failed = 0;
  for (const ModelCheck& c : model_checks(loose))
    if (!c.passed) {
      ++failed;
      EXPECT_TRUE(c.name == "leaf tier is the OR of the micro tier" || c.name == "fine tier is the OR of the leaf tier")
          << c.name;
    }
  EXPECT_EQ(failed, 2);
}

TEST(ModelIoReject, BlockInEmptyFineVoxel) {
  SceneModel m = small_model(32, 2);
  std::vector<uint8_t> b = serialize_model(m);
  Entry bidx = find_section(b, "BIDX");
  uint32_t last = m.block_fine_index.back();
  ASSERT_LT(last + 1, 512u);
  ASSERT_FALSE(m.occupancy[int(Tier::Fine)].get(size_t(last + 1)));
  put_u32(b, bidx.offset + 4 * (m.block_count() - 1), last + 1);
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "1 occupied fine voxels have no feature block");
  EXPECT_PARSE_ERROR(b, "1 feature blocks lie in empty fine voxels");
}

TEST(ModelIoReject, FeatureValues) {
  SceneModel m = small_model(32, 2);
  std::vector<uint8_t> b = serialize_model(m);
  Entry feq4 = find_section(b, "FEQ4");
  std::vector<uint8_t> c = b;
  c[feq4.offset + 8 + 1] = 16;  // zero point of channel 1
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section FEQ4 (INT4 features): channel 1 zero point 16 is not in 0..15");
  c = b;
  put_u32(c, feq4.offset, std::bit_cast<uint32_t>(std::numeric_limits<float>::infinity()));
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "channel 0 scale inf is not finite and positive");
  c = b;
  put_u32(c, feq4.offset + 4, 0);
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "channel 1 scale 0 is not finite and positive");
  Entry fe32 = find_section(b, "FE32");
  c = b;
  put_u32(c, fe32.offset + 4 * 253, std::bit_cast<uint32_t>(std::numeric_limits<float>::quiet_NaN()));
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section FE32 (float features): value 253 (block 1, vertex 1, channel 1) is not finite");
}

TEST(ModelIoReject, OddNibblePadding) {
  SceneModel m = small_model(32, 1, Forms{true, false, true, false});  // 125 nibbles per block
  ASSERT_EQ(m.block_count() % 2, 1u);
  std::vector<uint8_t> b = serialize_model(m);
  Entry feq4 = find_section(b, "FEQ4");
  b[feq4.offset + feq4.size - 1] |= 0x50;
  fix_crc(b);
  EXPECT_PARSE_ERROR(b, "unused high nibble");
}

TEST(ModelIoReject, MissingForms) {
  auto s = split_file(serialize_model(small_model(32, 2)));
  auto t = s;
  remove_section(t, "FEQ4");
  remove_section(t, "FE32");
  EXPECT_PARSE_ERROR(build_file(t), "feature blocks but neither section FEQ4 (INT4 features) nor section FE32");
  t = s;
  remove_section(t, "MLQ8");
  remove_section(t, "ML32");
  EXPECT_PARSE_ERROR(build_file(t), "MLPs but neither section MLQ8 (INT8 MLPs) nor section ML32 (float MLPs)");
  t = s;
  remove_section(t, "MARC");
  EXPECT_PARSE_ERROR(build_file(t), "MLPs but no section MARC (MLP shape)");
  // One form of each is enough.
  t = s;
  remove_section(t, "FEQ4");
  remove_section(t, "ML32");
  std::vector<uint8_t> b = build_file(t);
  SceneModel back = parse_model(b.data(), b.size());
  EXPECT_TRUE(back.features_q4.empty());
  EXPECT_FALSE(back.features_f32.empty());
}

TEST(ModelIoReject, MlpShape) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  Entry marc = find_section(b, "MARC");
  // Widths: density at +12 (2, 8, 4), colour at +24 (13, 6, 3).
  auto patched = [&](size_t at, uint32_t v) {
    std::vector<uint8_t> c = b;
    put_u32(c, marc.offset + at, v);
    fix_crc(c);
    return c;
  };
  EXPECT_PARSE_ERROR(patched(12, 3), "the density net's input width 3 differs from feature_channels 2");
  EXPECT_PARSE_ERROR(patched(16, 300), "the density net's width 1 is 300, expected 1..256");
  EXPECT_PARSE_ERROR(patched(32, 4), "the colour net's output width 4 is not 3");
  EXPECT_PARSE_ERROR(patched(24, 12), "the colour net's input width 12 differs from 13");
  EXPECT_PARSE_ERROR(patched(0, 9), "dir_frequencies 9 is not in 0..8");
  EXPECT_PARSE_ERROR(patched(4, 10), "the density net has 10 widths, expected 2..9");
  EXPECT_PARSE_ERROR(patched(4, 4), "section MARC (MLP shape) is 36 bytes, expected 40");
}

TEST(ModelIoReject, MlpValues) {
  SceneModel m = small_model(32, 2);
  std::vector<uint8_t> b = serialize_model(m);
  Entry mlq8 = find_section(b, "MLQ8");
  std::vector<uint8_t> c = b;
  put_u32(c, mlq8.offset, std::bit_cast<uint32_t>(-1.f));  // first layer's in_scale
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section MLQ8 (INT8 MLPs): MLP 0: input scale -1 is not finite and positive");
  Entry ml32 = find_section(b, "ML32");
  c = b;
  put_u32(c, ml32.offset + 4 * 2 * 8, std::bit_cast<uint32_t>(std::numeric_limits<float>::infinity()));
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section ML32 (float MLPs): MLP 0: bias value 0 is not finite");
}

TEST(ModelIoReject, ReservedFields) {
  std::vector<uint8_t> b = serialize_model(small_model(32, 2));
  std::vector<uint8_t> c = b;
  c[28] = 1;
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "reserved field");
  c = b;
  c[find_section(b, "GRID").table_at + 4] = 1;
  fix_crc(c);
  EXPECT_PARSE_ERROR(c, "section GRID (grid): the table entry's reserved field");
}

TEST(ModelIo, SerializeRejectsInconsistentModels) {
  SceneModel m = small_model(32, 2);
  m.features_f32.pop_back();
  EXPECT_THROW(serialize_model(m), Error);
  m = small_model(32, 2);
  m.mlps_q8[0].color[0].w_scale.pop_back();
  EXPECT_THROW(serialize_model(m), Error);
  m = small_model(32, 2);
  std::swap(m.block_fine_index[0], m.block_fine_index[1]);
  try {
    serialize_model(m);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("strictly ascending"), std::string::npos) << e.what();
  }
}

// ---- limits (issue #16) ----

// Metadata nested deeper than the limit is refused when loading (inspect
// printed it recursively and crashed at 100 000 levels).
TEST(ModelIoReject, MetadataNestedPastTheLimit) {
  auto s = split_file(serialize_model(small_model(32, 2)));
  const int depth = 100000;
  std::string deep = R"({"a": )" + std::string(size_t(depth), '[') + std::string(size_t(depth), ']') + "}";
  body(s, "META").assign(deep.begin(), deep.end());
  EXPECT_PARSE_ERROR(build_file(s), "the JSON nests 100001 levels deep, over the limit of 64");
  // Brackets inside strings do not count; the limit itself is accepted.
  std::string ok = R"({"s": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[", "d": )" +
                   std::string(63, '[') + std::string(63, ']') + "}";
  body(s, "META").assign(ok.begin(), ok.end());
  std::vector<uint8_t> b = build_file(s);
  EXPECT_EQ(parse_model(b.data(), b.size()).metadata_json, ok);
}

class ModelFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("edrnr_model_file_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
            std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string load_error(const std::filesystem::path& p) {
    try {
      load_model(p);
    } catch (const Error& e) {
      return e.what();
    }
    return "(loaded without error)";
  }
  std::filesystem::path dir_;
};

// The header is checked before the rest is read: a file that is not a model
// (/dev/zero, a folder), claims more than the limit, or whose size differs
// from its header's total, is refused without reading it all.
TEST_F(ModelFile, HeaderIsCheckedBeforeTheFileIsRead) {
  std::vector<uint8_t> good = serialize_model(small_model(32, 2));
  write_file_atomic(dir_ / "good.edrnr", good);
  EXPECT_NO_THROW(load_model(dir_ / "good.edrnr"));
  EXPECT_NE(load_error("/dev/zero").find("not an edrnr model"), std::string::npos);
  EXPECT_NE(load_error(dir_).find("is a folder, not a file"), std::string::npos) << load_error(dir_);
  std::vector<uint8_t> huge = good;
  put_u64(huge, 16, uint64_t{1} << 40);
  write_file_atomic(dir_ / "huge.edrnr", huge);
  const std::string m = load_error(dir_ / "huge.edrnr");
  EXPECT_NE(m.find("total size of 1099511627776 bytes, over the limit of 4294967296"), std::string::npos) << m;
  std::vector<uint8_t> cut(good.begin(), good.begin() + 100);
  write_file_atomic(dir_ / "cut.edrnr", cut);
  EXPECT_NE(load_error(dir_ / "cut.edrnr").find("but there are 100 (truncated or padded file)"), std::string::npos);
  std::vector<uint8_t> tiny(good.begin(), good.begin() + 12);
  write_file_atomic(dir_ / "tiny.edrnr", tiny);
  EXPECT_NE(load_error(dir_ / "tiny.edrnr").find("shorter than the 32-byte header"), std::string::npos);
}

}  // namespace
}  // namespace edrnr
