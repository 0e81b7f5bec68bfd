// The error map: its cells, the probabilities of its draws, and a training
// run that samples from it (deterministic, resumable).
#include "train/error_map.h"

#include <gtest/gtest.h>

#include <vector>

#include "model/model_io.h"
#include "train/trainer.h"
#include "train_fixture.h"

namespace edrnr::train {
namespace {

// Two frames, 40 x 30 and 17 x 5, in cells of 16: 3 x 2 and 2 x 1 cells.
ErrorMap two_frames() { return ErrorMap({40, 17}, {30, 5}, 16, 1.f); }

TEST(ErrorMap, CellsTileEachImageWithPartCellsAtItsEdges) {
  const ErrorMap m = two_frames();
  ASSERT_EQ(m.cells(), 8u);
  EXPECT_EQ(m.cell_of(0, 0, 0), 0u);
  EXPECT_EQ(m.cell_of(0, 39, 29), 5u);
  EXPECT_EQ(m.cell_of(1, 16, 4), 7u);
  EXPECT_EQ(m.cell_pixels(0), 256);
  EXPECT_EQ(m.cell_pixels(5), 8 * 14);
  EXPECT_EQ(m.cell_pixels(6), 16 * 5);
  EXPECT_EQ(m.cell_pixels(7), 1 * 5);
  int pixels = 0;
  for (uint32_t c = 0; c < m.cells(); ++c) pixels += m.cell_pixels(c);
  EXPECT_EQ(pixels, 40 * 30 + 17 * 5);
}

TEST(ErrorMap, DrawsPixelsInProportionToTheirCellsError) {
  ErrorMap m = two_frames();
  std::vector<float> v{0, 1, 0, 0, 0, 3, 0, 0};
  m.values() = v;
  m.rebuild();
  EXPECT_DOUBLE_EQ(m.total(), 4.0);
  // Per pixel: a cell's share of the error over its pixels; over all pixels they sum to 1.
  EXPECT_DOUBLE_EQ(m.probability(1), 0.25 / 256);
  EXPECT_DOUBLE_EQ(m.probability(5), 0.75 / 112);
  EXPECT_DOUBLE_EQ(m.probability(0), 0.0);
  // Evenly spaced u: a quarter of the draws in cell 1, the rest in cell 5,
  // each pixel inside its cell.
  const int n = 4000;
  int in1 = 0, in5 = 0;
  for (int k = 0; k < n; ++k) {
    const MapPixel p = m.draw((k + 0.5) / n, 0x9e3779b97f4a7c15ull * uint64_t(k + 1));
    EXPECT_EQ(p.frame, 0u);
    EXPECT_EQ(m.cell_of(p.frame, p.x, p.y), p.cell);
    ASSERT_TRUE(p.cell == 1 || p.cell == 5) << p.cell;
    (p.cell == 1 ? in1 : in5)++;
  }
  EXPECT_EQ(in1, n / 4);
  EXPECT_EQ(in5, 3 * n / 4);
  // The one cell of frame 1's right edge (one pixel across).
  m.values() = {0, 0, 0, 0, 0, 0, 0, 2};
  m.rebuild();
  for (int k = 0; k < 20; ++k) {
    const MapPixel p = m.draw(k / 20.0, uint64_t(k) * 12345u);
    EXPECT_EQ(p.frame, 1u);
    EXPECT_EQ(p.x, 16);
    EXPECT_GE(p.y, 0);
    EXPECT_LT(p.y, 5);
  }
}

TEST(ErrorMap, ACellMovesHalfwayToEachError) {
  ErrorMap m = two_frames();
  m.update(3, 0.2f);
  EXPECT_FLOAT_EQ(m.values()[3], 0.6f);
  m.update(3, 0.2f);
  EXPECT_FLOAT_EQ(m.values()[3], 0.4f);
  EXPECT_FLOAT_EQ(m.values()[2], 1.f);
}

TEST(ErrorMap, TrainingFromTheMapIsDeterministicAndResumes) {
  const Dataset data = load("train");
  TrainConfig c = short_config();
  c.error_map_share = 0.5f;
  c.error_map_cell = 8;
  Trainer whole(data, c);
  ASSERT_TRUE(whole.run({}));
  std::vector<uint8_t> ckpt;
  {
    Trainer a(data, c);
    TrainOptions o;
    o.threads = 1;
    o.stop_after = 50;
    ASSERT_FALSE(a.run(o));
    ckpt = a.checkpoint();
  }
  Trainer b(data, ckpt, "checkpoint");
  ASSERT_TRUE(b.run({}));
  const auto bytes = serialize_model(whole.export_model(true));
  EXPECT_EQ(serialize_model(b.export_model(true)), bytes);
  // The map changes which rays train: not the uniform run's model.
  Trainer uniform(data, short_config());
  ASSERT_TRUE(uniform.run({}));
  EXPECT_NE(serialize_model(uniform.export_model(true)), bytes);
}

}  // namespace
}  // namespace edrnr::train
