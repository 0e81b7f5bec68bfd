// load_dataset refuses a split whose images would not fit in memory together
// (limits::kMaxDatasetPixels) before it decodes any of them, and names the
// split's file and the limit.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "data/dataset.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

TEST(DatasetLimits, ASplitTooLargeForMemoryIsRefusedBeforeDecoding) {
  const fs::path dir = fs::temp_directory_path() / fmt::format("edrnr_test_split_limit_{}", getpid());
  fs::remove_all(dir);
  fs::create_directories(dir);
  // 17 views of 4096 x 4096: 285 M pixels, over the 268 M limit; no image exists.
  nlohmann::json doc = {{"fl_x", 100}, {"w", 4096}, {"h", 4096}, {"frames", nlohmann::json::array()}};
  for (int i = 0; i < 17; ++i)
    doc["frames"].push_back({{"file_path", fmt::format("./test/r_{}", i)},
                             {"transform_matrix", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 4}, {0, 0, 0, 1}}}});
  write_file_atomic(dir / "transforms_test.json", doc.dump());
  DatasetOptions o;
  o.split = "test";
  try {
    load_dataset(dir, o);
    ADD_FAILURE() << "a split of 17 views of 4096x4096 was accepted";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("transforms_test.json"), std::string::npos) << what;
    EXPECT_NE(what.find(fmt::format("over the limit of {} pixels for one split", limits::kMaxDatasetPixels)),
              std::string::npos)
        << what;
  }
  // 16 views are within the limit: the error is then the first missing image.
  doc["frames"].erase(16);
  write_file_atomic(dir / "transforms_test.json", doc.dump());
  try {
    load_dataset(dir, o);
    ADD_FAILURE() << "missing images were accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("image not found"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace edrnr
