// libFuzzer harness for the .edrnr loader (scripts/fuzz.sh builds and runs it).
//
// Each input is parsed twice: as given (header, size and CRC checks), and with
// the header's total size and CRC-32 made to agree with the input, so that
// mutations reach the section checks behind the CRC. A parse may only end in
// edrnr::Error; anything else (a crash, a sanitizer report, another exception)
// is a finding. A model that parses must also save, and saving it again after
// a reload must give the same bytes.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness writes a few valid small
// models into DIR as the seed corpus and exits.
#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_io.h"
#include "model/model_io.h"

namespace {

using namespace edrnr;

// A hand-built valid model: a few occupied micro voxels, one block per
// occupied fine voxel, one MLP per occupied coarse voxel, in the forms asked for.
SceneModel seed_model(int micro_res, int channels, bool q4, bool f32, bool mlp_q8, bool mlp_f32) {
  SceneModel m;
  m.micro_res = micro_res;
  m.feature_channels = channels;
  m.scene_box = {{-1.f, -1.f, -1.f}, {1.f, 1.f, 1.f}};
  m.object_aabb = {{-0.5f, -0.5f, -0.5f}, {0.75f, 0.5f, 0.5f}};
  m.init_grids();
  const float points[][3] = {{-0.4f, -0.4f, -0.4f}, {0.1f, 0.0f, 0.2f}, {0.7f, 0.45f, -0.45f}, {0.3f, -0.2f, 0.4f}};
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
  for (size_t i = 0; i < m.features_f32.size(); ++i) m.features_f32[i] = std::sin(0.3f * float(i));
  if (q4) m.quantize_features();
  if (!f32) m.features_f32.clear();

  m.mlp_arch.dir_frequencies = 1;
  m.mlp_arch.density_widths = {channels, 4, 2};
  m.mlp_arch.color_widths = {2 + 9, 4, 3};
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i)) m.mlp_coarse_index.push_back(uint32_t(i));
  for (size_t k = 0; k < m.mlp_count(); ++k) {
    MlpF f;
    MlpQ q;
    for (int net = 0; net < 2; ++net) {
      const std::vector<int>& widths = net == 0 ? m.mlp_arch.density_widths : m.mlp_arch.color_widths;
      for (size_t l = 1; l < widths.size(); ++l) {
        size_t in = size_t(widths[l - 1]), out = size_t(widths[l]);
        DenseF df{int(in), int(out), std::vector<float>(in * out, 0.5f), std::vector<float>(out, 0.1f)};
        DenseQ dq{int(in),
                  int(out),
                  std::vector<int8_t>(in * out, -3),
                  std::vector<float>(out, 0.01f),
                  std::vector<float>(out, 0.2f),
                  0.05f};
        (net == 0 ? f.density : f.color).push_back(df);
        (net == 0 ? q.density : q.color).push_back(dq);
      }
    }
    if (mlp_f32) m.mlps_f32.push_back(f);
    if (mlp_q8) m.mlps_q8.push_back(q);
  }
  m.metadata_json = R"({"seed": "fuzz", "n": [1, 2.5, true, null]})";
  m.finalize();
  return m;
}

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  SceneModel empty;
  empty.micro_res = 32;
  empty.init_grids();
  empty.finalize();
  save_model(dir / "empty.edrnr", empty);
  save_model(dir / "all_forms_f2.edrnr", seed_model(32, 2, true, true, true, true));
  save_model(dir / "int4_int8_f3.edrnr", seed_model(32, 3, true, false, true, false));
  save_model(dir / "float_f1.edrnr", seed_model(32, 1, false, true, false, true));
  std::printf("wrote 4 seed models to %s\n", dir.c_str());
}

// A model that parsed must save, and reload and save to the same bytes.
void check_round_trip(const SceneModel& m) {
  std::vector<uint8_t> a, b;
  try {
    a = serialize_model(m);
    SceneModel again = parse_model(a.data(), a.size(), "fuzz round trip");
    b = serialize_model(again);
  } catch (const Error& e) {
    std::fprintf(stderr, "a parsed model fails to save or reload: %s\n", e.what());
    std::abort();
  }
  if (a != b) {
    std::fprintf(stderr, "save -> load -> save changed the bytes\n");
    std::abort();
  }
}

void parse_one(const uint8_t* data, size_t size) {
  try {
    SceneModel m = parse_model(data, size, "fuzz");
    check_round_trip(m);
  } catch (const Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  parse_one(data, size);
  if (size >= kModelHeaderBytes) {
    std::vector<uint8_t> b(data, data + size);
    for (int i = 0; i < 8; ++i) b[16 + size_t(i)] = uint8_t(uint64_t(size) >> (8 * i));
    uint32_t crc = uint32_t(crc32(crc32(0L, Z_NULL, 0), b.data() + kModelHeaderBytes, uInt(size - kModelHeaderBytes)));
    for (int i = 0; i < 4; ++i) b[24 + size_t(i)] = uint8_t(crc >> (8 * i));
    parse_one(b.data(), b.size());
  }
  return 0;
}
