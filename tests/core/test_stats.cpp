#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>

#include "core/error.h"
#include "core/stats.h"

namespace edrnr {
namespace {

TEST(Distribution, PercentilesOfOneToHundred) {
  Distribution d;
  for (uint64_t v = 100; v >= 1; --v) d.add(v);  // order must not matter
  EXPECT_EQ(d.count(), 100u);
  EXPECT_EQ(d.sum(), 5050u);
  EXPECT_DOUBLE_EQ(d.mean(), 50.5);
  EXPECT_EQ(d.min(), 1u);
  EXPECT_EQ(d.max(), 100u);
  // Nearest rank: the ceil(p/100 * 100)-th smallest sample.
  EXPECT_EQ(d.percentile(50), 50u);
  EXPECT_EQ(d.percentile(95), 95u);
  EXPECT_EQ(d.percentile(99), 99u);
  EXPECT_EQ(d.percentile(99.5), 100u);
  EXPECT_EQ(d.percentile(100), 100u);
  EXPECT_EQ(d.percentile(0), 1u);
}

TEST(Distribution, LargeSamplesAndTies) {
  Distribution d;
  // 7 samples: 3, 3, 3, 70000, 70000, 1000000, 5
  for (uint64_t v : {3u, 70000u, 3u, 1000000u, 5u, 70000u, 3u}) d.add(v);
  EXPECT_EQ(d.count(), 7u);
  EXPECT_EQ(d.sum(), 3u * 3 + 5 + 2 * 70000 + 1000000);
  EXPECT_EQ(d.percentile(40), 3u);        // rank ceil(2.8) = 3 -> third smallest = 3
  EXPECT_EQ(d.percentile(50), 5u);        // rank ceil(3.5) = 4 -> 5
  EXPECT_EQ(d.percentile(60), 70000u);    // rank ceil(4.2) = 5
  EXPECT_EQ(d.percentile(99), 1000000u);  // rank 7
  EXPECT_EQ(d.max(), 1000000u);
  EXPECT_EQ(d.min(), 3u);
}

TEST(Distribution, EmptyIsZeroAndBadPercentileThrows) {
  Distribution d;
  EXPECT_EQ(d.count(), 0u);
  EXPECT_EQ(d.percentile(50), 0u);
  EXPECT_EQ(d.min(), 0u);
  EXPECT_EQ(d.max(), 0u);
  EXPECT_DOUBLE_EQ(d.mean(), 0.0);
  EXPECT_THROW(d.percentile(101), Error);
  EXPECT_THROW(d.percentile(-1), Error);
}

TEST(StatsRegistry, HandlesUpdateTheRegisteredStatistics) {
  StatsRegistry stats;
  Counter& reads = stats.counter("dram.reads", "requests", "read requests");
  Value& energy = stats.value("dram.energy_pJ", "pJ", "total energy");
  // Registering more must not move what earlier handles point at.
  for (int i = 0; i < 100; ++i) stats.counter("filler." + std::to_string(i), "events", "filler");
  ++reads;
  reads += 4;
  reads.add(2);
  energy.set(1.5);
  energy += 2.0;
  EXPECT_EQ(stats.get("dram.reads"), 7.0);
  EXPECT_EQ(stats.get("dram.energy_pJ"), 3.5);
  EXPECT_EQ(stats.size(), 102u);
  EXPECT_TRUE(stats.contains("filler.99"));
  EXPECT_FALSE(stats.contains("filler.100"));
}

TEST(StatsRegistry, RejectsDuplicateAndMalformedNames) {
  StatsRegistry stats;
  stats.counter("a.b", "events", "x");
  EXPECT_THROW(stats.counter("a.b", "events", "again"), Error);
  EXPECT_THROW(stats.value("a.b", "pJ", "again as value"), Error);
  EXPECT_THROW(stats.counter("", "events", "no name"), Error);
  EXPECT_THROW(stats.counter("has space", "events", "x"), Error);
  EXPECT_THROW(stats.counter("no.unit", "", "x"), Error);
  EXPECT_THROW(stats.get("missing"), Error);
  stats.distribution("lat", "cycles", "x");
  EXPECT_THROW(stats.get("lat"), Error);
  try {
    stats.counter("a.b", "events", "again");
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("a.b"), std::string::npos);
  }
}

TEST(StatsRegistry, TableListsEveryStatisticInRegistrationOrder) {
  StatsRegistry stats;
  stats.counter("z.first", "bytes", "registered first") += 4096;
  stats.value("a.second", "GB/s", "registered second").set(12.8);
  Distribution& lat = stats.distribution("m.latency", "cycles", "read latency");
  for (uint64_t v = 1; v <= 100; ++v) lat.add(v);
  std::ostringstream out;
  stats.print_table(out);
  std::string t = out.str();
  size_t first = t.find("z.first");
  size_t second = t.find("a.second");
  ASSERT_NE(first, std::string::npos);
  ASSERT_NE(second, std::string::npos);
  EXPECT_LT(first, second);
  EXPECT_NE(t.find("4096"), std::string::npos);
  EXPECT_NE(t.find("12.800"), std::string::npos);
  EXPECT_NE(t.find("GB/s"), std::string::npos);
  EXPECT_NE(t.find("registered second"), std::string::npos);
  // The distribution's rows, each with its value.
  for (const char* row :
       {"m.latency.count", "m.latency.mean", "m.latency.p50", "m.latency.p95", "m.latency.p99", "m.latency.max"}) {
    EXPECT_NE(t.find(row), std::string::npos) << row;
  }
  EXPECT_NE(t.find("50.500"), std::string::npos);
  // One header, one rule and 2 + 6 rows.
  EXPECT_EQ(std::count(t.begin(), t.end(), '\n'), 10);
}

TEST(StatsRegistry, JsonCarriesUnitDescriptionAndValues) {
  StatsRegistry stats;
  stats.counter("dram.read_bytes", "bytes", "bytes read") += 640;
  stats.value("dram.hit_rate", "ratio", "row-buffer hit rate").set(0.25);
  Distribution& lat = stats.distribution("dram.read_latency", "cycles", "read latency");
  for (uint64_t v : {10u, 20u, 30u, 40u}) lat.add(v);
  nlohmann::json j = stats.to_json();
  ASSERT_EQ(j.size(), 3u);
  EXPECT_EQ(j["dram.read_bytes"]["value"], 640);
  EXPECT_EQ(j["dram.read_bytes"]["unit"], "bytes");
  EXPECT_EQ(j["dram.read_bytes"]["description"], "bytes read");
  EXPECT_DOUBLE_EQ(j["dram.hit_rate"]["value"].get<double>(), 0.25);
  const auto& d = j["dram.read_latency"];
  EXPECT_EQ(d["count"], 4);
  EXPECT_DOUBLE_EQ(d["mean"].get<double>(), 25.0);
  EXPECT_EQ(d["min"], 10);
  EXPECT_EQ(d["p50"], 20);  // rank ceil(2) = 2
  EXPECT_EQ(d["p95"], 40);  // rank ceil(3.8) = 4
  EXPECT_EQ(d["max"], 40);
  EXPECT_EQ(d["unit"], "cycles");
}

}  // namespace
}  // namespace edrnr
