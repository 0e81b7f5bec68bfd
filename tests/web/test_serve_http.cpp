// edrnr serve over HTTP on a loopback port: renders against the engine called
// directly, ground truth and PSNR, the simulation queue, and a 4xx with a JSON
// error for every kind of bad request.
#include <gtest/gtest.h>
#include <httplib.h>

#include <chrono>
#include <cstring>
#include <thread>

#include "core/metrics.h"
#include "data/dataset.h"
#include "engines.h"
#include "serve_image.h"
#include "serve_server.h"
#include "serve_sim.h"
#include "serve_validate.h"
#include "web_fixture.h"

namespace edrnr::serve {
namespace {

class ServeHttp : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions o;
    o.catalog = fx.options();
    o.chip_preset_dirs = WebFixture::chip_presets();
    o.dram_preset_dirs = WebFixture::dram_presets();
    o.port = 0;
    o.render_threads = 2;
    server = std::make_unique<Server>(o);
    server->bind();
    thread = std::thread([this] { server->serve(); });
    client = std::make_unique<httplib::Client>("127.0.0.1", server->port());
    client->set_read_timeout(60, 0);
    for (int i = 0; i < 200 && !client->Get("/api/health"); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  void TearDown() override {
    server->stop();
    thread.join();
    server.reset();
  }

  // Status and parsed JSON body of a GET that must fail.
  std::pair<int, nlohmann::json> get_error(const std::string& path) {
    auto res = client->Get(path.c_str());
    if (!res) return {0, {}};
    return {res->status, nlohmann::json::parse(res->body, nullptr, false)};
  }

  Image engine_render(const Camera& cam) {
    const SceneModel model = load_model(fx.dir / "models" / "tiny.edrnr");
    RenderSettings s;
    s.threads = 2;
    return cli::find_engine(server->engine_name()).render(model, cam, s, nullptr);
  }

  WebFixture fx;
  std::unique_ptr<Server> server;
  std::thread thread;
  std::unique_ptr<httplib::Client> client;
};

TEST_F(ServeHttp, CatalogListsModelsDatasetsAndPresets) {
  auto res = client->Get("/api/catalog");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  const nlohmann::json j = nlohmann::json::parse(res->body);
  std::vector<std::string> names;
  for (const auto& m : j["models"]) names.push_back(m["name"]);
  EXPECT_NE(std::find(names.begin(), names.end(), "tiny"), names.end());
  EXPECT_EQ(j["datasets"].size(), 1u);
  EXPECT_EQ(j["datasets"][0]["test_views"].size(), 2u);
  EXPECT_FALSE(j["presets"].empty());
  EXPECT_TRUE(j["engine"] == "fast" || j["engine"] == "reference");
}

TEST_F(ServeHttp, OrbitRenderIsTheEngineImage) {
  auto res = client->Get("/api/render?model=tiny&az=40&el=20&radius=3.5&fov=45&w=48&h=40");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(res->get_header_value("X-Width"), "48");
  EXPECT_EQ(res->get_header_value("X-Height"), "40");
  EXPECT_GE(std::stod(res->get_header_value("X-Render-Ms")), 0.0);
  EXPECT_FALSE(res->has_header("X-PSNR-dB"));  // an orbit has no ground truth
  const Image direct = engine_render(orbit_camera(48, 40, 40, 20, 3.5, 45));
  EXPECT_EQ(res->body, to_rgba8(direct));
  // The background is white in the corners; the sphere covers the centre.
  EXPECT_EQ(uint8_t(res->body[0]), 255);
  const size_t centre = (20 * 48 + 24) * 4;
  EXPECT_LT(uint8_t(res->body[centre]) + uint8_t(res->body[centre + 1]) + uint8_t(res->body[centre + 2]), 3 * 250);

  auto png = client->Get("/api/render?model=tiny&az=40&el=20&radius=3.5&fov=45&w=48&h=40&format=png");
  ASSERT_TRUE(png);
  EXPECT_EQ(png->get_header_value("Content-Type"), "image/png");
  const std::filesystem::path file = fx.dir / "render.png";
  write_file_atomic(file, png->body);
  const Image decoded = read_png_rgba(file);
  std::string rgba(decoded.data.size(), '\0');
  for (size_t i = 0; i < decoded.data.size(); ++i) rgba[i] = char(std::lround(decoded.data[i] * 255));
  EXPECT_EQ(rgba, res->body);
}

TEST_F(ServeHttp, TestViewRenderCarriesItsPsnr) {
  auto res = client->Get("/api/render?model=tiny&view=1");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  // The test view's ground truth is the reference render stored as 8-bit PNG.
  Frame f;
  f.camera = fx.catalog().dataset("tiny").views[1].camera;
  f.image_path = fx.dir / "data" / "tiny" / "r_1.png";
  const float white[3] = {1, 1, 1};
  const Image gt = composite_rgba(read_frame_rgba(f, 1), white);
  const Image img = engine_render(f.camera);
  EXPECT_NEAR(std::stod(res->get_header_value("X-PSNR-dB")), psnr(img, gt), 1e-3);
  if (server->engine_name() == "reference") {
    EXPECT_GT(psnr(img, gt), 54.0);  // 8-bit rounding only
  }

  auto png = client->Get("/api/groundtruth?dataset=tiny&view=1&w=16");
  ASSERT_TRUE(png);
  ASSERT_EQ(png->status, 200) << png->body;
  write_file_atomic(fx.dir / "gt.png", png->body);
  const Image small = read_png_rgba(fx.dir / "gt.png");
  EXPECT_EQ(small.width, 16);
  const Image expected = downscale(gt, 2);
  for (size_t p = 0; p < 16 * 16; ++p)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(small.data[p * 4 + c], expected.data[p * 3 + c], 0.5 / 255 + 1e-6);
}

TEST_F(ServeHttp, EveryBadRequestIsA4xxWithAJsonError) {
  const std::vector<std::pair<std::string, int>> cases = {
      {"/api/render", 400},                           // no model
      {"/api/render?model=../models/tiny", 400},      // path traversal
      {"/api/render?model=..%2Fmodels%2Ftiny", 400},  // encoded traversal
      {"/api/render?model=%2Fetc%2Fpasswd", 400},     // absolute path
      {"/api/render?model=bad%20name!", 400},         // a file the catalog left out
      {"/api/render?model=nothere", 404},             // unknown model
      {"/api/render?model=tiny&w=100000", 400},       // too large
      {"/api/render?model=tiny&w=0", 400},            // too small
      {"/api/render?model=tiny&w=-5", 400},           // negative
      {"/api/render?model=tiny&az=nan", 400},         // not finite
      {"/api/render?model=tiny&el=95", 400},          // out of range
      {"/api/render?model=tiny&radius=1e308", 400},   // out of range
      {"/api/render?model=tiny&view=7", 400},         // view index out of range
      {"/api/render?model=tiny&view=0&w=31", 400},    // not a whole fraction
      {"/api/render?model=tiny&format=gif", 400},     // unknown format
      {"/api/render?model=tiny&model=nothere", 400},  // repeated
      {"/api/render?model=tiny&bogus=1", 400},        // unknown parameter
      {"/api/groundtruth?dataset=../../etc&view=0", 400},
      {"/api/groundtruth?dataset=tiny&view=99", 400},
      {"/api/groundtruth?dataset=none&view=0", 404},
      {"/api/catalog?x=1", 400},
      {"/api/sim/abc", 400},
      {"/api/sim/99999", 404},
      {"/api/sim/1/image/0", 404},
      {"/api/sim/1/trace/99", 400},
      {"/api/nothing", 404},
  };
  for (const auto& [path, status] : cases) {
    const auto [got, body] = get_error(path);
    EXPECT_EQ(got, status) << path;
    EXPECT_TRUE(body.is_object() && body.contains("error")) << path << ": " << body.dump();
  }
  // Methods and bodies.
  auto post = [&](const std::string& body) { return client->Post("/api/sim", body, "application/json"); };
  for (const std::string& body : {std::string("not json"), std::string("[]"), std::string(R"({"model": "tiny"})"),
                                  std::string(R"({"client": "abcdefgh", "model": "tiny", "w": 5000})"),
                                  std::string(R"({"client": "abcdefgh", "model": "tiny", "preset": "../x"})"),
                                  std::string(R"({"client": "abcdefgh", "model": "tiny", "compare": "nope"})"),
                                  std::string(R"({"client": "abcdefgh", "model": "tiny", "unknown": 1})")}) {
    auto res = post(body);
    ASSERT_TRUE(res);
    EXPECT_GE(res->status, 400) << body;
    EXPECT_LT(res->status, 500) << body;
    EXPECT_TRUE(nlohmann::json::parse(res->body, nullptr, false).contains("error")) << body;
  }
  auto huge = post("{\"a\": \"" + std::string(2 * kMaxBodyBytes, 'x') + "\"}");
  ASSERT_TRUE(huge);
  EXPECT_EQ(huge->status, 413);
  auto del = client->Delete("/api/sim/1?client=short");
  ASSERT_TRUE(del);
  EXPECT_EQ(del->status, 400);
  auto put = client->Put("/api/render", "x", "text/plain");
  ASSERT_TRUE(put);
  EXPECT_GE(put->status, 400);
  EXPECT_LT(put->status, 500);
}

TEST_F(ServeHttp, SimulationRunsOncePerClientAndReports) {
  const std::string body = R"({"client": "test-client-1", "model": "procedural-sphere", "w": 24})";
  auto first = client->Post("/api/sim", body, "application/json");
  ASSERT_TRUE(first);
  ASSERT_EQ(first->status, 202) << first->body;
  const uint64_t id = nlohmann::json::parse(first->body)["id"];
  // A second job of the same client while the first is queued or running: 429
  // (unless the first already finished).
  auto second = client->Post("/api/sim", body, "application/json");
  ASSERT_TRUE(second);
  nlohmann::json st;
  for (int i = 0; i < 600; ++i) {
    st = nlohmann::json::parse(client->Get(("/api/sim/" + std::to_string(id)).c_str())->body);
    if (st["state"] != "queued" && st["state"] != "running") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  if (second->status != 202) {
    EXPECT_EQ(second->status, 429);
  }
  ASSERT_EQ(st["state"], "done") << st.dump();
  const nlohmann::json& report = st["results"][0]["report"];
  const nlohmann::json& s = report["summary"];
  EXPECT_GT(s["cycles"].get<double>(), 0);
  EXPECT_NEAR(s["fps"].get<double>(), s["clock_MHz"].get<double>() * 1e6 / s["cycles"].get<double>(),
              1e-6 * s["fps"].get<double>());
  EXPECT_EQ(report["image"]["width"], 24);
  EXPECT_DOUBLE_EQ(st["progress"]["fraction"].get<double>(), 1.0);
  auto img = client->Get(st["results"][0]["image_url"].get<std::string>().c_str());
  ASSERT_TRUE(img);
  EXPECT_EQ(img->status, 200);
  EXPECT_EQ(img->body.substr(1, 3), "PNG");
  auto trace = client->Get(st["results"][0]["trace_url"].get<std::string>().c_str());
  ASSERT_TRUE(trace);
  EXPECT_NE(trace->get_header_value("Content-Disposition").find("attachment"), std::string::npos);
  EXPECT_TRUE(nlohmann::json::parse(trace->body).contains("traceEvents"));
  // A finished job cannot be cancelled; another client's job not at all.
  auto del = client->Delete(("/api/sim/" + std::to_string(id) + "?client=other-client").c_str());
  ASSERT_TRUE(del);
  EXPECT_EQ(del->status, 409);
}

TEST_F(ServeHttp, SurvivesAClientThatLeavesMidRender) {
  {
    httplib::Client impatient("127.0.0.1", server->port());
    impatient.set_read_timeout(0, 1000);  // gives up after 1 ms, before the frame is ready
    auto res = impatient.Get("/api/render?model=procedural-several&w=256");
    EXPECT_FALSE(res);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  auto res = client->Get("/api/render?model=tiny&w=16");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
}

TEST(ServeSimQueue, BoundedQueue) {
  WebFixture fx;
  Catalog catalog = fx.catalog();
  SimQueueOptions qo;
  qo.max_queued = 1;
  SimQueue q(catalog, WebFixture::dram_presets(), qo);
  auto request = [&](const std::string& client) {
    SimRequest r;
    r.client = client;
    r.model = "procedural-several";
    r.presets = {"edr_nr_40nm"};
    r.camera = orbit_camera(400, 400, 30, 30, 4, 40);  // long enough to still run below
    return r;
  };
  const uint64_t a = q.submit(request("client-a-1"));
  for (int i = 0; i < 400 && q.status(a)["state"] == "queued"; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(q.status(a)["state"], "running");
  const uint64_t b = q.submit(request("client-b-1"));  // waits behind a
  try {
    q.submit(request("client-c-1"));
    ADD_FAILURE() << "a full queue accepted a job";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.status(), 503);
  }
  try {
    q.submit(request("client-b-1"));
    ADD_FAILURE() << "a client with a queued job got a second one";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.status(), 429);
  }
  q.cancel(b, "client-b-1");
  EXPECT_EQ(q.status(b)["state"], "cancelled");
  q.cancel(a, "client-a-1");
  for (int i = 0; i < 400 && q.status(a)["state"] != "cancelled"; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  EXPECT_EQ(q.status(a)["state"], "cancelled");
}

}  // namespace
}  // namespace edrnr::serve
