#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/error.h"
#include "core/stats.h"
#include "sim/energy.h"

namespace edrnr::sim {
namespace {

const char* kTable =
    "# a tiny table\n"
    "event,energy_pJ,reference_voltage_V,source\n"
    "add,2.0,1.0,test\n"
    "\n"
    "read,10,0.5,\"test, with a comma and \"\"quotes\"\"\"\n"
    "dram_bit,70,-,test\n";
const char* kLeakage =
    "block,leakage_mW,reference_voltage_V,source\n"
    "core,4.0,1.0,test\n";

EnergyModel tiny_model(double exponent = 1.0) {
  return EnergyModel(EnergyTable::parse(kTable, "tiny.csv"), LeakageTable::parse(kLeakage, "leak.csv"), exponent);
}

EnergyRun tiny_run() {
  EnergyRun run;
  run.event_counts = {{"add", 100}, {"read", 3}, {"dram_bit", 8}};
  run.cycles = 1000;
  run.pixels = 10;
  return run;
}

TEST(EnergyTable, ParsesRowsAndQuotedFields) {
  EnergyTable t = EnergyTable::parse(kTable, "tiny.csv");
  ASSERT_EQ(t.rows().size(), 3u);
  EXPECT_EQ(t.at("read").source, "test, with a comma and \"quotes\"");
  EXPECT_DOUBLE_EQ(t.at("read").reference_voltage_V, 0.5);
  EXPECT_TRUE(t.at("add").scales_with_core_voltage());
  EXPECT_FALSE(t.at("dram_bit").scales_with_core_voltage());
  EXPECT_FALSE(t.contains("mult"));
}

// Hand-computed at 100 MHz, 1.0 V: time = 1000 / 1e8 = 10 us.
//   dynamic = 100 x 2 x (1/1)^2 + 3 x 10 x (1/0.5)^2 = 200 + 120 = 320 pJ
//   off-chip = 8 x 70 = 560 pJ; static = 4 mW x 10 us = 40 nJ = 40000 pJ
TEST(EnergyModel, HandComputedTotalAtReferenceVoltage) {
  EnergyReport r = tiny_model().evaluate(tiny_run(), {100, 1.0});
  EXPECT_DOUBLE_EQ(r.time_s, 1e-5);
  EXPECT_DOUBLE_EQ(r.core_dynamic_pJ, 320.0);
  EXPECT_DOUBLE_EQ(r.offchip_pJ, 560.0);
  EXPECT_NEAR(r.static_pJ, 40000.0, 1e-9);
  EXPECT_NEAR(r.total_pJ, 40880.0, 1e-9);
  EXPECT_NEAR(r.nJ_per_pixel, 4.088, 1e-12);
  EXPECT_NEAR(r.average_power_W, 4.088e-3, 1e-15);
  ASSERT_EQ(r.by_event.size(), 3u);
  EXPECT_EQ(r.by_event[0].event, "add");  // name order
  EXPECT_DOUBLE_EQ(r.by_event[0].energy_pJ, 200.0);
  EXPECT_EQ(r.by_event[1].event, "dram_bit");
  EXPECT_EQ(r.by_event[2].event, "read");
  EXPECT_DOUBLE_EQ(r.by_event[2].energy_pJ, 120.0);
}

// At 0.5 V: dynamic = 100 x 2 x 0.25 + 3 x 10 x 1 = 80 pJ; off-chip unchanged;
// leakage 4 mW x 0.5 = 2 mW (linear) or 4 x 0.25 = 1 mW (exponent 2).
TEST(EnergyModel, DynamicScalesWithVoltageSquaredAndDramDoesNot) {
  EnergyReport r = tiny_model().evaluate(tiny_run(), {100, 0.5});
  EXPECT_DOUBLE_EQ(r.core_dynamic_pJ, 80.0);
  EXPECT_DOUBLE_EQ(r.offchip_pJ, 560.0);
  EXPECT_NEAR(r.static_pJ, 20000.0, 1e-9);
  ASSERT_EQ(r.by_block.size(), 1u);
  EXPECT_DOUBLE_EQ(r.by_block[0].power_mW, 2.0);
  EnergyReport r2 = tiny_model(2.0).evaluate(tiny_run(), {100, 0.5});
  EXPECT_NEAR(r2.static_pJ, 10000.0, 1e-9);
  // Twice the clock: same dynamic energy, half the run time, half the leakage energy.
  EnergyReport fast = tiny_model().evaluate(tiny_run(), {200, 1.0});
  EXPECT_DOUBLE_EQ(fast.core_dynamic_pJ, 320.0);
  EXPECT_NEAR(fast.static_pJ, 20000.0, 1e-9);
}

TEST(EnergyModel, DramModelEnergyIsAddedUnscaled) {
  EnergyRun run = tiny_run();
  run.event_counts.erase("dram_bit");
  run.dram_model_energy_pJ = 1234.5;
  EnergyReport r = tiny_model().evaluate(run, {100, 0.79});
  EXPECT_DOUBLE_EQ(r.offchip_pJ, 1234.5);
  run.dram_model_energy_pJ = -1;
  EXPECT_THROW(tiny_model().evaluate(run, {100, 1.0}), Error);
}

TEST(EnergyModel, ZeroPixelsAndCyclesGiveZeroRatesAndZeroCountsAreLeftOut) {
  EnergyRun run;
  run.event_counts = {{"add", 0}};
  EnergyReport r = tiny_model().evaluate(run, {100, 1.0});
  EXPECT_EQ(r.nJ_per_pixel, 0.0);
  EXPECT_EQ(r.average_power_W, 0.0);
  EXPECT_TRUE(r.by_event.empty());
}

std::string error_of(const std::string& csv) {
  try {
    EnergyTable::parse(csv, "bad.csv");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(EnergyTable, ErrorsNameTheLineAndTheProblem) {
  const std::string h = "event,energy_pJ,reference_voltage_V,source\n";
  EXPECT_NE(error_of("event,energy,reference_voltage_V,source\n").find("line 1: the header must be"),
            std::string::npos);
  EXPECT_NE(error_of(h + "add,abc,1.0,x\n").find("line 2: energy_pJ 'abc' is not a number"), std::string::npos);
  EXPECT_NE(error_of(h + "add,1.0,1.0\n").find("line 2: expected 4 fields"), std::string::npos);
  EXPECT_NE(error_of(h + "\n# c\nadd,-1,1.0,x\n").find("line 4: energy_pJ -1 is negative"), std::string::npos);
  EXPECT_NE(error_of(h + "add,1,0,x\n").find("line 2: reference_voltage_V 0 must be > 0"), std::string::npos);
  EXPECT_NE(error_of(h + "add,1,1,\n").find("line 2: event 'add' has no source"), std::string::npos);
  EXPECT_NE(error_of(h + "add,1,1,x\nadd,2,1,y\n").find("line 3: event 'add' is already defined on line 2"),
            std::string::npos);
  EXPECT_NE(error_of(h + "add,1,1,\"open\n").find("line 2: a quoted field has no closing quote"), std::string::npos);
  EXPECT_NE(error_of(h + "add,1.5x,1,x\n").find("'1.5x' is not a number"), std::string::npos);
  EXPECT_NE(error_of("").find("no header"), std::string::npos);
  EXPECT_EQ(error_of(h + "add,1,1,x\r\n"), "");  // CRLF line ends are accepted
  EXPECT_THROW(EnergyTable::load("/nonexistent/energy.csv"), Error);
}

TEST(EnergyModel, UnknownEventAndBadOperatingPoint) {
  EnergyRun run;
  run.event_counts = {{"mul", 1}};
  try {
    tiny_model().evaluate(run, {100, 1.0});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("energy table 'tiny.csv': unknown event 'mul'"), std::string::npos);
  }
  EXPECT_THROW(tiny_model().evaluate(tiny_run(), {0, 1.0}), Error);
  EXPECT_THROW(tiny_model().evaluate(tiny_run(), {100, -1.0}), Error);
  EXPECT_THROW(tiny_model(-1.0), Error);
  EXPECT_THROW(LeakageTable::parse("block,leakage_mW,reference_voltage_V,source\ncore,1,-,x\n", "l.csv"), Error);
}

TEST(EnergyModel, ReportJsonAndStats) {
  EnergyReport r = tiny_model().evaluate(tiny_run(), {100, 1.0});
  nlohmann::json j = energy_report_json(r);
  EXPECT_DOUBLE_EQ(j["core_dynamic_pJ"].get<double>(), 320.0);
  EXPECT_EQ(j["by_event"].size(), 3u);
  EXPECT_EQ(j["by_block"][0]["block"], "core");
  StatsRegistry reg;
  export_stats(r, reg, "energy");
  EXPECT_DOUBLE_EQ(reg.get("energy.event.read_pJ"), 120.0);
  EXPECT_NEAR(reg.get("energy.nJ_per_pixel"), 4.088, 1e-12);
  EXPECT_NE(format_energy_report(r).find("nJ/pixel"), std::string::npos);
}

TEST(EnergyModel, Table1OperatingPointsAreSelfConsistent) {
  // Power = energy per pixel x pixels per second, 800 x 800 pixels a frame
  // (the paper rounds, so within 2 %).
  const auto& points = table1_operating_points();
  EXPECT_DOUBLE_EQ(points.front().point.frequency_MHz, 50);
  EXPECT_DOUBLE_EQ(points.back().point.voltage_V, 1.21);
  for (const PaperOperatingPoint& p : points) {
    double power_mW = p.nJ_per_pixel * p.fps * 800 * 800 * 1e-6;
    EXPECT_NEAR(power_mW / p.power_mW, 1.0, 0.02) << p.point.frequency_MHz << " MHz";
  }
}

// The shipped table: every derived row matches the derivation its source states.
TEST(EnergyTable, ShippedTableFollowsItsSources) {
  std::string dir = std::string(EDRNR_SOURCE_DIR) + "/configs/energy/";
  EnergyTable t = EnergyTable::load(dir + "events.csv");
  LeakageTable leak = LeakageTable::load(dir + "leakage.csv");
  for (const EnergyEvent& e : t.rows()) EXPECT_FALSE(e.source.empty()) << e.event;
  const double tech = 40.0 / 45.0;  // 45 nm -> 40 nm
  EXPECT_NEAR(t.at("int8_mult").energy_pJ, 0.2 * tech, 0.001);
  EXPECT_NEAR(t.at("int32_mult").energy_pJ, 3.1 * tech, 0.01);
  EXPECT_NEAR(t.at("fp32_mult").energy_pJ, 3.7 * tech, 0.01);
  EXPECT_NEAR(t.at("int16_mult").energy_pJ, 3.1 * 0.25 * tech, 0.001);
  EXPECT_NEAR(t.at("mlp_sram_read").energy_pJ, 5.0 * std::pow(8.25 / 8.0, 0.78), 0.01);
  EXPECT_NEAR(t.at("other_sram_read").energy_pJ, 12.0 * std::pow(43.2 / 32.0, 0.78), 0.05);
  for (const char* sram : {"micro_grid", "feature", "mlp", "other"}) {
    std::string s = sram;
    EXPECT_NEAR(t.at(s + "_sram_write").energy_pJ / t.at(s + "_sram_read").energy_pJ, 1.1, 0.01) << s;
  }
  EXPECT_EQ(t.at("dram_bit").energy_pJ, 70.0);
  EXPECT_FALSE(t.at("dram_bit").scales_with_core_voltage());
  ASSERT_FALSE(leak.rows().empty());
  // 1 ms at 380 MHz / 1.21 V: leakage energy = P_leak(1.21 V) x 1 ms.
  EnergyModel model(t, leak);
  EnergyRun run;
  run.cycles = 380000;
  double leak_mW = 0;
  for (const LeakageBlock& b : leak.rows()) leak_mW += b.leakage_mW * 1.21 / b.reference_voltage_V;
  EXPECT_NEAR(model.evaluate(run, {380, 1.21}).static_pJ, leak_mW * 1e-3 * 1e-3 * 1e12, 1e-3);
}

}  // namespace
}  // namespace edrnr::sim
