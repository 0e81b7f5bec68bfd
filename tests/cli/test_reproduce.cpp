// `edrnr reproduce`: the quick run writes every report file, its numbers are
// the simulator's own, a rerun simulates nothing, a dataset scene without data
// is skipped, and bad input gets a clear error.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "cli_fixture.h"
#include "core/image.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

const char* const kFigureIds[] = {"table1", "table2", "fig3c", "fig4c", "fig5b", "fig6d",
                                  "fig7b",  "fig8",   "fig9",  "fig16", "fig17c"};
const char* const kCsvFiles[] = {"comparisons", "runs",  "table1", "table1_sram", "table2", "fig3c", "fig4c",
                                 "fig5b",       "fig6d", "fig7b",  "fig8",        "fig9",   "fig16", "fig17c"};

Json read_json(const fs::path& p) { return Json::parse(read_file_text(p)); }

double stat_of(const Json& run, const std::string& name) { return run.at("stats").at(name).at("value").get<double>(); }

// The comparison row of a figure, for a quantity and scene.
const Json& comparison(const Json& results, const std::string& figure, const std::string& quantity,
                       const std::string& scene) {
  for (const Json& f : results.at("figures"))
    if (f.at("id") == figure)
      for (const Json& c : f.at("comparisons"))
        if (c.at("quantity") == quantity && c.at("scene") == scene) return c;
  throw std::runtime_error("no comparison " + figure + " / " + quantity + " / " + scene);
}

// The cached JSON of every run, by (scene, view, variant), as results.json lists them.
std::map<std::tuple<std::string, int, std::string>, Json> runs_of(const fs::path& out, const Json& results) {
  std::map<std::tuple<std::string, int, std::string>, Json> runs;
  for (const Json& r : results.at("runs"))
    runs[{r.at("scene").get<std::string>(), r.at("view").get<int>(), r.at("variant").get<std::string>()}] =
        read_json(out / r.at("file").get<std::string>());
  return runs;
}

class ReproduceTest : public CliTest {
 protected:
  // Whether the report can have figures here: the python3 that `edrnr
  // reproduce` would use has matplotlib (the script's own --check).
  bool matplotlib_present() {
    const fs::path script = fs::path(EDRNR_SOURCE_DIR) / "scripts" / "report_figures.py";
    const fs::path log = dir_ / "check.txt";
    for (const char* python : {"python3", "/usr/bin/python3"}) {
      const std::string cmd = std::string(python) + " " + script.string() + " --check >" + log.string() + " 2>&1";
      const int status = std::system(cmd.c_str());
      if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return true;
    }
    return false;
  }

  // A Synthetic-NeRF-like dataset of one procedural scene: transforms_test.json
  // and `views` 40x40 test images rendered by the reference renderer from the
  // quantized model, which is saved as <models>/<name>.edrnr.
  void make_scene(const fs::path& data_root, const fs::path& models, const std::string& name, int views) {
    ProceduralOptions opt;
    opt.micro_res = 64;
    SceneModel model = make_procedural_model("sphere", procedural_shapes("sphere"), opt);
    fs::create_directories(models);
    save_model(models / (name + ".edrnr"), model);
    const fs::path root = data_root / name;
    fs::create_directories(root / "test");
    const double fov_x = 0.69111120700836;
    Json frames = Json::array();
    for (int v = 0; v < views; ++v) {
      Camera cam = orbit_camera(40, 40, 50.0 * v, 25.0, 4.0, fov_x * 180.0 / M_PI);
      RenderSettings s;
      s.form = ModelForm::Quantized;
      write_png(root / "test" / ("r_" + std::to_string(v) + ".png"), render_reference(model, cam, s));
      Json m = Json::array();
      for (int i = 0; i < 4; ++i)
        m.push_back({cam.c2w[4 * i], cam.c2w[4 * i + 1], cam.c2w[4 * i + 2], cam.c2w[4 * i + 3]});
      frames.push_back({{"file_path", "./test/r_" + std::to_string(v)}, {"transform_matrix", m}});
    }
    write_file_atomic(root / "transforms_test.json", Json{{"camera_angle_x", fov_x}, {"frames", frames}}.dump(2));
  }
};

// The quick run writes every file of the report; every number it reports is
// the one in the simulator's JSON of that run (and the averages are the means
// of those); a rerun simulates nothing; more views run only the new ones.
TEST_F(ReproduceTest, QuickRunWritesTheReportFromTheSimulatorsJsonAndResumes) {
  const fs::path out = dir_ / "rep";
  RunResult r = run("reproduce --quick --jobs 2 --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  // Two procedural scenes, two views, 12 configurations each: 48 distinct simulations.
  EXPECT_NE(r.out.find("simulations: 48 distinct, 0 cached, 48 run"), std::string::npos) << r.out;

  for (const char* f : {"report.md", "report.html", "results.json"}) EXPECT_TRUE(fs::is_regular_file(out / f)) << f;
  for (const char* f : kCsvFiles) EXPECT_TRUE(fs::is_regular_file(out / (std::string(f) + ".csv"))) << f;
  const bool figures = matplotlib_present();
  for (const char* id : kFigureIds)
    for (const char* ext : {".png", ".svg"}) {
      const fs::path p = out / "figures" / (std::string(id) + ext);
      if (figures)
        EXPECT_TRUE(fs::is_regular_file(p) && fs::file_size(p) > 1000) << p;
      else
        EXPECT_FALSE(fs::exists(p)) << p;
    }
  const std::string md = read_file_text(out / "report.md"), html = read_file_text(out / "report.html");
  for (const char* title : {"## Table I", "## Table II", "## Fig. 3(c)", "## Fig. 8", "## Fig. 17(c)"})
    EXPECT_NE(md.find(title), std::string::npos) << title;
  if (figures) {
    EXPECT_NE(md.find("](figures/fig8.png)"), std::string::npos);
    EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);  // self-contained
  }

  const Json results = read_json(out / "results.json");
  EXPECT_EQ(results.at("mode"), "quick");
  ASSERT_EQ(results.at("scenes").size(), 2u);
  EXPECT_EQ(results.at("simulations").at("distinct"), 48);
  // Every run entry: its numbers are its JSON's statistics, bit for bit.
  ASSERT_EQ(results.at("runs").size(), 48u);
  std::set<std::string> keys;
  for (const Json& e : results.at("runs")) {
    const Json run = read_json(out / e.at("file").get<std::string>());
    keys.insert(e.at("key"));
    EXPECT_EQ(run.at("key"), e.at("key"));
    EXPECT_EQ(e.at("fps").get<double>(), stat_of(run, "sim.fps"));
    EXPECT_EQ(e.at("cycles").get<double>(), stat_of(run, "sim.cycles"));
    EXPECT_EQ(e.at("dram_read_bytes").get<double>(), stat_of(run, "dram.read_bytes"));
    EXPECT_EQ(e.at("power_mW").get<double>(), 1e3 * run.at("energy").at("average_power_W").get<double>());
    // An operating point runs at its own clock.
    EXPECT_EQ(stat_of(run, "sim.clock_MHz"), e.at("clock_MHz").get<double>());
    if (e.at("variant") == "point_50MHz") {
      EXPECT_EQ(stat_of(run, "sim.clock_MHz"), 50.0);
    }
    if (e.at("variant") == "full") {
      EXPECT_EQ(stat_of(run, "sim.clock_MHz"), 380.0);
    }
  }
  EXPECT_EQ(keys.size(), 48u);

  // The figures are the means of the runs' own values, recomputed here.
  auto runs = runs_of(out, results);
  for (const std::string scene : {"several", "torus"}) {
    double fps = 0, gain = 0, mw50 = 0, aabb = 0;
    for (int v : {0, 1}) {
      const Json& full = runs.at({scene, v, "full"});
      fps += stat_of(full, "sim.fps") / 2;
      gain += stat_of(full, "sim.fps") / stat_of(runs.at({scene, v, "all_off"}), "sim.fps") / 2;
      mw50 += 1e3 * runs.at({scene, v, "point_50MHz"}).at("energy_table1").at("average_power_W").get<double>() / 2;
      aabb += 100 *
              (stat_of(full, "chip.ctu.coarse_checks") /
                   stat_of(runs.at({scene, v, "off_aabb"}), "chip.ctu.coarse_checks") -
               1) /
              2;
      // Every technique changes the timing only: the same image in every variant.
      for (const auto& [k, run] : runs)
        if (std::get<0>(k) == scene && std::get<1>(k) == v) {
          EXPECT_EQ(run.at("image").at("hash"), full.at("image").at("hash")) << std::get<2>(k);
        }
    }
    EXPECT_NEAR(comparison(results, "table1", "FPS at 380 MHz", scene).at("ours").get<double>(), fps, 1e-9 * fps);
    EXPECT_EQ(comparison(results, "table1", "FPS at 380 MHz", scene).at("paper").get<double>(), 85.9);
    EXPECT_NEAR(comparison(results, "table1", "power at 50 MHz", scene).at("ours").get<double>(), mw50, 1e-9 * mw50);
    EXPECT_NEAR(comparison(results, "fig17c", "throughput gain, all techniques", scene).at("ours").get<double>(), gain,
                1e-9 * gain);
    EXPECT_NEAR(comparison(results, "fig3c", "coarse load change with the AABB", scene).at("ours").get<double>(), aabb,
                1e-9 * std::abs(aabb));
  }
  // Balanced banks: 125 vertex vectors per block over 8 banks, none deeper than the mean.
  EXPECT_NEAR(comparison(results, "fig9", "largest / mean bank depth, balanced", "all scenes").at("ours").get<double>(),
              1.0, 1e-9);
  EXPECT_NEAR(comparison(results, "fig9", "largest / mean bank depth, direct", "all scenes").at("ours").get<double>(),
              27.0 / (125.0 / 8), 1e-9);
  const std::string csv = read_file_text(out / "comparisons.csv");
  EXPECT_EQ(csv.rfind("figure,quantity,scene,ours,paper,ratio,unit\n", 0), 0u) << csv.substr(0, 80);
  for (const char* id : kFigureIds) EXPECT_NE(csv.find(std::string("\n") + id + ","), std::string::npos) << id;

  // A rerun finds every simulation done.
  r = run("reproduce --quick --jobs 2 --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("simulations: 48 distinct, 48 cached, 0 run"), std::string::npos) << r.out;
  const Json again = read_json(out / "results.json");
  EXPECT_EQ(again.at("simulations").at("cached"), 48);
  EXPECT_EQ(again.at("simulations").at("ran"), 0);
  EXPECT_EQ(again.at("runs"), results.at("runs"));

  // One more view: only its 12 configurations per scene are simulated.
  r = run("reproduce --quick --jobs 2 --views 0,1,2 --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("simulations: 72 distinct, 48 cached, 24 run"), std::string::npos) << r.out;
}

// Dataset scenes: a scene with a model but no data (and those with no model)
// are skipped with a line and named in the report; the PSNR and FPS of a view
// are what `edrnr simulate` reports for it; a changed preset runs again.
TEST_F(ReproduceTest, DatasetScenesSkipWhatIsMissingAndMatchSimulate) {
  const fs::path data = dir_ / "data", models = dir_ / "models", out = dir_ / "rep";
  make_scene(data, models, "lego", 2);
  // A model for mic, but no data for it.
  fs::copy_file(models / "lego.edrnr", models / "mic.edrnr");
  RunResult r = run("reproduce --data " + data.string() + " --models " + models.string() +
                    " --views 0,1 --jobs 2 --figures none -q --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("skipping mic: no data"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("skipping chair: no model"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("skipping hotdog: no model"), std::string::npos) << r.out;

  const Json results = read_json(out / "results.json");
  ASSERT_EQ(results.at("scenes").size(), 1u);
  EXPECT_EQ(results.at("scenes")[0].at("name"), "lego");
  EXPECT_EQ(results.at("scenes")[0].at("width"), 40);
  std::set<std::string> skipped;
  for (const Json& s : results.at("skipped")) skipped.insert(s.at("name"));
  EXPECT_EQ(skipped, (std::set<std::string>{"chair", "mic", "hotdog"}));
  const std::string md = read_file_text(out / "report.md");
  EXPECT_NE(md.find("**Scenes covered:** lego"), std::string::npos);
  EXPECT_NE(md.find("- mic: no data"), std::string::npos);
  EXPECT_TRUE(fs::is_regular_file(out / "ground_truth" / "lego_view1.png"));
  EXPECT_TRUE(fs::is_regular_file(out / "report.html"));  // --figures none: the page, without figures
  EXPECT_FALSE(fs::exists(out / "figures" / "fig8.png"));

  // The chip renders the quantized model within the product's 40 dB of the
  // reference renderer that made the ground truth.
  const Json& psnr = comparison(results, "fig16", "PSNR", "lego");
  EXPECT_GT(psnr.at("ours").get<double>(), 40.0);
  EXPECT_EQ(psnr.at("paper").get<double>(), 33.75);

  // `edrnr simulate` on the same model and view measures the same frame.
  r = run("simulate " + (models / "lego.edrnr").string() + " --dataset " + (data / "lego").string() +
          " --view 1 -q -o " + (dir_ / "sim").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json sim = read_json(dir_ / "sim" / "stats.json");
  const Json run_json = runs_of(out, results).at({"lego", 1, "full"});
  for (const char* name : {"sim.fps", "sim.cycles", "dram.read_bytes", "quality.psnr_vs_ground_truth"})
    EXPECT_EQ(stat_of(run_json, name), stat_of(sim, name)) << name;

  // Another preset (a larger "others" budget changes nothing but the config) runs everything again.
  const fs::path preset = dir_ / "roomy.yaml";
  write_file_atomic(preset, "simulator:\n  sram_budget_bytes:\n    others: 50000\n");
  r = run("reproduce --data " + data.string() + " --models " + models.string() + " --views 0 --chip " +
          preset.string() + " --figures none -q --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("simulations: 12 distinct, 0 cached, 12 run"), std::string::npos) << r.out;
}

TEST_F(ReproduceTest, BadInputGetsAClearErrorAndNonZeroExit) {
  const fs::path data = dir_ / "data", models = dir_ / "models", out = dir_ / "rep";
  make_scene(data, models, "lego", 1);
  const std::string base = " --models " + models.string() + " --figures none -q --out " + out.string();

  // A data folder given explicitly that is not there.
  RunResult r = run("reproduce --data " + (dir_ / "nowhere").string() + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--data"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("nowhere"), std::string::npos) << r.err;

  r = run("reproduce --quick --data " + data.string() + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--quick"), std::string::npos) << r.err;

  // An unknown preset, and a preset file that is not valid.
  r = run("reproduce --data " + data.string() + " --views 0 --chip no_such_chip" + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no_such_chip"), std::string::npos) << r.err;
  const fs::path bad_preset = dir_ / "bad.yaml";
  write_file_atomic(bad_preset, "simulator:\n  no_such_key: 3\n");
  r = run("reproduce --data " + data.string() + " --views 0 --chip " + bad_preset.string() + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad.yaml"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no_such_key"), std::string::npos) << r.err;

  // A view the dataset does not have.
  r = run("reproduce --data " + data.string() + " --views 0,7" + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--views"), std::string::npos) << r.err;
  r = run("reproduce --data " + data.string() + " --views 0,x" + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--views"), std::string::npos) << r.err;

  // A corrupt model: named, and nothing is simulated.
  std::vector<uint8_t> bytes = read_file_bytes(models / "lego.edrnr");
  bytes.resize(bytes.size() / 2);
  write_file_atomic(models / "lego.edrnr", bytes);
  r = run("reproduce --data " + data.string() + " --views 0" + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("lego.edrnr"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out / "runs"));

  // No scene with both a model and data.
  fs::remove(models / "lego.edrnr");
  r = run("reproduce --data " + data.string() + " --views 0" + base);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("nothing to reproduce"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace edrnr
