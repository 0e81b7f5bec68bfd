// libFuzzer harness for the training checkpoint reader: the container
// (CheckpointReader), the settings in it, and a Trainer resumed from it on a
// tiny dataset, as `edrnr train --resume` does (scripts/fuzz.sh).
//
// Each input is read twice: as given (magic, version and CRC checks), and with
// its CRC made to agree, so that mutations reach the sections behind it. A
// read may only end in edrnr::Error; anything else is a finding. A trainer
// that resumes must report its state, take one more step if it is not done,
// and (after the freeze) export models that serialize.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness writes checkpoints of a
// tiny run in each phase into DIR as the seed corpus and exits.
#include <unistd.h>
#include <zlib.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_io.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "train/checkpoint_io.h"
#include "train/config.h"
#include "train/images.h"
#include "train/synthetic.h"
#include "train/trainer.h"

namespace {

using namespace edrnr;
using namespace edrnr::train;

// Two 8 x 8 views of a sphere, written once per process.
const Dataset& dataset() {
  static const Dataset d = [] {
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("edrnr_fuzz_ckpt_" + std::to_string(::getpid()));
    ProceduralOptions po;
    po.micro_res = 32;
    po.feature_channels = 4;
    SyntheticViews v;
    v.train_views = 2;
    v.test_views = 1;
    v.width = v.height = 8;
    write_synthetic_dataset(make_procedural_model("sphere", procedural_shapes("sphere"), po), dir, v);
    DatasetOptions o;
    o.load_images = false;
    Dataset ds = load_dataset(dir, o);
    load_premultiplied_rgba(ds, 1);
    std::filesystem::remove_all(dir);
    return ds;
  }();
  return d;
}

TrainConfig tiny() {
  TrainConfig c;
  c.micro_res = 32;
  c.levels = {8};
  c.density_hidden = {4};
  c.color_hidden = {4};
  c.geo_features = 2;
  c.dir_frequencies = 0;
  c.iters = 20;
  c.batch_samples = 1024;
  c.min_rays = 8;
  c.max_rays = 64;
  c.occupancy_every = 2;
  c.aabb_start = 2;
  c.aabb_every = 2;
  c.lr_warmup = 1;
  c.plan_step = 10;
  return c;
}

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  TrainOptions o;
  o.threads = 1;
  for (int64_t stop : {1, 17, 19, 20}) {  // main, per-CV, quantization-aware, done
    Trainer t(dataset(), tiny());
    o.stop_after = stop;
    t.run(o);
    write_file_atomic(dir / ("step" + std::to_string(stop) + ".ckpt"), t.checkpoint());
  }
  std::printf("wrote 4 seed checkpoints to %s\n", dir.c_str());
}

void read_one(const std::vector<uint8_t>& bytes) {
  std::unique_ptr<Trainer> t;
  try {
    CheckpointReader r(bytes, "fuzz.ckpt");
    (void)Trainer::checkpoint_config(bytes, "fuzz.ckpt");
    t = std::make_unique<Trainer>(dataset(), bytes, "fuzz.ckpt");
  } catch (const Error&) {
    return;
  }
  try {
    const TrainStats s = t->stats();
    if (!t->done()) {
      TrainOptions o;
      o.threads = 1;
      o.stop_after = s.step + 1;
      t->run(o);
    }
    if (t->stats().phase != Phase::Main)
      for (bool quantized : {true, false}) (void)serialize_model(t->export_model(quantized));
  } catch (const Error&) {
    // A resumed state may still be refused with a message (e.g. at export).
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  dataset();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  read_one(bytes);
  if (size >= 24) {
    const uint32_t crc = uint32_t(crc32(crc32(0L, Z_NULL, 0), bytes.data() + 24, uInt(size - 24)));
    for (int i = 0; i < 4; ++i) bytes[16 + size_t(i)] = uint8_t(crc >> (8 * i));
    read_one(bytes);
  }
  return 0;
}
