// The request validation of edrnr serve: parameter readers, names, bodies and
// view requests, each against the limits they document.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "serve_catalog.h"
#include "serve_validate.h"
#include "serve_view.h"
#include "web_fixture.h"

namespace edrnr::serve {
namespace {

int status_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const RequestError& e) {
    return e.status();
  }
  return 0;
}

TEST(ServeValidate, NumbersInRange) {
  const Params p = {{"a", "12.5"}, {"b", "-3"}, {"c", "1e3"}};
  EXPECT_DOUBLE_EQ(number_param(p, "a", 0, 100), 12.5);
  EXPECT_DOUBLE_EQ(number_param(p, "b", -5, 5), -3);
  EXPECT_DOUBLE_EQ(number_param(p, "c", 0, 1000), 1000);
  EXPECT_DOUBLE_EQ(number_param(p, "missing", 0, 1, 0.25), 0.25);
  EXPECT_EQ(status_of([&] { number_param(p, "missing", 0, 1); }), 400);
  EXPECT_EQ(status_of([&] { number_param(p, "c", 0, 999.5); }), 400);
  for (const char* bad : {"nan", "inf", "-inf", "1e400", "", "12abc", "0x10", " 1", "+1", "1,5"})
    EXPECT_EQ(status_of([&] { number_param({{"x", bad}}, "x", -1e9, 1e9); }), 400) << bad;
}

TEST(ServeValidate, WholeNumbers) {
  EXPECT_EQ(int_param({{"w", "400"}}, "w", 8, 1024), 400);
  EXPECT_EQ(int_param({}, "w", 8, 1024, 64), 64);
  for (const char* bad : {"7", "1025", "400.5", "-0x1", "99999999999999999999", "4e2", ""})
    EXPECT_EQ(status_of([&] { int_param({{"w", bad}}, "w", 8, 1024); }), 400) << bad;
}

TEST(ServeValidate, NamesStayInsideTheServedFolders) {
  EXPECT_TRUE(is_safe_name("lego"));
  EXPECT_TRUE(is_safe_name("procedural-several"));
  EXPECT_TRUE(is_safe_name("edr_nr_40nm.v2"));
  for (const char* bad :
       {"", ".", "..", "../lego", "a/b", "a\\b", ".hidden", "a..b", "%2e%2e", "lego\n", "le go", "/etc/passwd"})
    EXPECT_FALSE(is_safe_name(bad)) << bad;
  EXPECT_FALSE(is_safe_name(std::string("lego\0x", 6)));
  EXPECT_TRUE(is_safe_name(std::string(kMaxNameBytes, 'a')));
  EXPECT_FALSE(is_safe_name(std::string(kMaxNameBytes + 1, 'a')));

  const std::vector<std::string> known = {"lego", "mic"};
  EXPECT_EQ(name_param({{"model", "mic"}}, "model", known), "mic");
  EXPECT_EQ(status_of([&] { name_param({{"model", "chair"}}, "model", known); }), 404);
  EXPECT_EQ(status_of([&] { name_param({{"model", "../mic"}}, "model", known); }), 400);
  EXPECT_EQ(status_of([&] { name_param({}, "model", known); }), 400);
}

TEST(ServeValidate, ParameterSets) {
  EXPECT_NO_THROW(check_params({{"a", "1"}, {"b", "2"}}, {"a", "b", "c"}));
  EXPECT_EQ(status_of([] { check_params({{"z", "1"}}, {"a"}); }), 400);
  EXPECT_EQ(status_of([] { check_params({{"a", "1"}, {"a", "2"}}, {"a"}); }), 400);
  EXPECT_EQ(status_of([] { check_params({{"a", std::string(kMaxParamBytes + 1, '1')}}, {"a"}); }), 400);
  EXPECT_NO_THROW(check_params({{"a", std::string(kMaxParamBytes, '1')}}, {"a"}));
  Params many;
  for (size_t i = 0; i <= kMaxParams; ++i) {
    std::string key = std::to_string(i);
    key.insert(key.begin(), 'p');  // not "p" + ...: GCC 12 warns (falsely) of an overlapping copy there
    many.emplace(key, "1");
  }
  EXPECT_EQ(status_of([&] { check_params(many, {}); }), 400);
  EXPECT_EQ(choice_param({}, "format", {"rgba", "png"}, "rgba"), "rgba");
  EXPECT_EQ(status_of([] { choice_param({{"format", "gif"}}, "format", {"rgba", "png"}, "rgba"); }), 400);
  EXPECT_TRUE(bool_param({{"x", "true"}}, "x", false));
  EXPECT_FALSE(bool_param({{"x", "0"}}, "x", true));
  EXPECT_EQ(status_of([] { bool_param({{"x", "yes"}}, "x", true); }), 400);
}

TEST(ServeValidate, JsonBodies) {
  const Params p = params_from_json_body(R"({"model": "lego", "w": 200, "az": -12.5, "allow_over_budget": true})");
  EXPECT_EQ(p.find("model")->second, "lego");
  EXPECT_EQ(int_param(p, "w", 8, 800), 200);
  EXPECT_DOUBLE_EQ(number_param(p, "az", -360, 360), -12.5);
  EXPECT_TRUE(bool_param(p, "allow_over_budget", false));
  for (const char* bad :
       {"", "{", "[1, 2]", "\"text\"", "null", R"({"a": {"b": 1}})", R"({"a": [1]})", R"({"a": null})"})
    EXPECT_EQ(status_of([&] { params_from_json_body(bad); }), 400) << bad;
  const std::string big = "{\"a\": \"" + std::string(kMaxBodyBytes, 'x') + "\"}";
  EXPECT_EQ(status_of([&] { params_from_json_body(big); }), 413);
}

TEST(ServeValidate, ClientAndJobIds) {
  EXPECT_TRUE(is_client_id("0123abcd"));
  EXPECT_FALSE(is_client_id("short"));
  EXPECT_FALSE(is_client_id(std::string(65, 'a')));
  EXPECT_FALSE(is_client_id("abcdefgh/"));
  EXPECT_EQ(parse_job_id("42"), 42u);
  for (const char* bad : {"", "-1", "4x", "abc", "123456789012345678901", " 1"})
    EXPECT_EQ(status_of([&] { parse_job_id(bad); }), 400) << bad;
}

TEST(ServeValidate, ErrorBodiesAreJsonNamingTheField) {
  const nlohmann::json j = nlohmann::json::parse(error_json(400, "w", "parameter 'w' = 5: must be between 8 and 1024"));
  EXPECT_EQ(j["status"], 400);
  EXPECT_EQ(j["field"], "w");
  EXPECT_NE(j["error"].get<std::string>().find("1024"), std::string::npos);
  // Bytes that are not UTF-8 are replaced, never an exception.
  EXPECT_NO_THROW(nlohmann::json::parse(error_json(400, "\xff\xfe", "bad \xc3")));
}

TEST(ServeView, OrbitDefaultsAndLimits) {
  WebFixture fx;
  Catalog catalog = fx.catalog();
  const ViewChoice v = parse_view({}, catalog, "procedural-sphere", kMaxRenderSide);
  EXPECT_EQ(v.view, -1);
  EXPECT_EQ(v.camera.width, 400);
  EXPECT_EQ(v.camera.height, 400);
  // The default orbit: azimuth 30, elevation 30, radius 4.
  const Vec3d o = v.camera.origin();
  EXPECT_NEAR(std::sqrt(o.x * o.x + o.y * o.y + o.z * o.z), 4.0, 1e-9);
  EXPECT_NEAR(o.z, 4.0 * std::sin(30.0 * M_PI / 180), 1e-9);
  EXPECT_EQ(parse_view({{"w", "64"}}, catalog, "procedural-sphere", kMaxRenderSide).camera.height, 64);
  EXPECT_EQ(status_of([&] { parse_view({{"w", "801"}}, catalog, "procedural-sphere", kMaxSimSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"el", "90"}}, catalog, "procedural-sphere", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"radius", "0.1"}}, catalog, "procedural-sphere", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"fov", "179"}}, catalog, "procedural-sphere", kMaxRenderSide); }), 400);
  // A procedural model has no dataset of its own.
  EXPECT_EQ(status_of([&] { parse_view({{"view", "0"}}, catalog, "procedural-sphere", kMaxRenderSide); }), 400);
}

TEST(ServeView, TestViewsScaleByWholeFactors) {
  WebFixture fx;
  Catalog catalog = fx.catalog();
  // "tiny" model and dataset share a name: the dataset is the model's own.
  const ViewChoice v = parse_view({{"view", "1"}}, catalog, "tiny", kMaxRenderSide);
  EXPECT_EQ(v.view, 1);
  EXPECT_EQ(v.dataset, "tiny");
  EXPECT_EQ(v.camera.width, WebFixture::kViewSide);
  const ViewChoice half = parse_view({{"view", "0"}, {"w", "16"}}, catalog, "tiny", kMaxRenderSide);
  EXPECT_EQ(half.factor, 2);
  EXPECT_DOUBLE_EQ(half.camera.fx, catalog.dataset("tiny").views[0].camera.fx / 2);
  EXPECT_EQ(status_of([&] { parse_view({{"view", "0"}, {"w", "15"}}, catalog, "tiny", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"view", "2"}}, catalog, "tiny", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"view", "-1"}}, catalog, "tiny", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"view", "0"}, {"az", "3"}}, catalog, "tiny", kMaxRenderSide); }), 400);
  EXPECT_EQ(status_of([&] { parse_view({{"view", "0"}, {"dataset", "nope"}}, catalog, "tiny", kMaxRenderSide); }), 404);
  EXPECT_EQ(status_of([&] { parse_view({{"dataset", "tiny"}}, catalog, "tiny", kMaxRenderSide); }), 400);
}

TEST(ServeCatalog, ListsOnlyPlainNamesOfTheServedFolders) {
  WebFixture fx;
  Catalog catalog = fx.catalog();
  const std::vector<std::string> models = catalog.model_names();
  EXPECT_NE(std::find(models.begin(), models.end(), "tiny"), models.end());
  EXPECT_NE(std::find(models.begin(), models.end(), "procedural-several"), models.end());
  // A file whose stem is not a plain name is left out and reported.
  for (const std::string& m : models) EXPECT_TRUE(is_safe_name(m)) << m;
  EXPECT_EQ(catalog.skipped().size(), 1u);
  EXPECT_EQ(catalog.model_entry("tiny").dataset, "tiny");
  EXPECT_EQ(catalog.dataset("tiny").views.size(), 2u);
  EXPECT_THROW(Catalog({fx.dir / "missing", {}}, {}), Error);
  // The orbit closest to a test view: the dataset camera sits at radius 4 on the +x axis, 30 degrees up.
  const TestView& tv = catalog.dataset("tiny").views[0];
  EXPECT_NEAR(tv.radius, 4.0, 1e-9);
  EXPECT_NEAR(tv.elevation_deg, 30.0, 1e-9);
  EXPECT_NEAR(tv.azimuth_deg, 0.0, 1e-9);
  EXPECT_NEAR(tv.fov_deg, 40.0, 1e-9);
}

}  // namespace
}  // namespace edrnr::serve
