#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "render/cameras.h"
#include "render/options.h"

namespace edrnr {
namespace {

void expect_vec(const Vec3d& a, const Vec3d& b, double tol = 1e-12) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

TEST(Cameras, OrbitLooksAtTheOriginWithZUp) {
  // Azimuth 0, elevation 0, radius 4, 90 degree field of view, 3x3 pixels:
  // fx = 1.5 / tan(45 deg) = 1.5.
  const Camera c = orbit_camera(3, 3, 0, 0, 4, 90);
  EXPECT_NEAR(c.fx, 1.5, 1e-12);
  EXPECT_EQ(c.cx, 1.5);
  expect_vec(c.origin(), {4, 0, 0});
  expect_vec(c.pixel_ray(1, 1).dir, {-1, 0, 0});
  // One pixel right: camera direction (1/1.5, 0, -1); camera +x is world +y.
  expect_vec(c.pixel_ray(2, 1).dir, normalize(Vec3d{-1, 2.0 / 3, 0}));
  // One pixel up: world +z.
  expect_vec(c.pixel_ray(1, 0).dir, normalize(Vec3d{-1, 0, 2.0 / 3}));

  // Azimuth 90, elevation 30, radius 2: at (0, 2 cos 30, 2 sin 30).
  const Camera d = orbit_camera(5, 5, 90, 30, 2, 40);
  expect_vec(d.origin(), {0, std::sqrt(3.0), 1});
  expect_vec(d.pixel_ray(2, 2).dir, {0, -std::sqrt(3.0) / 2, -0.5});
}

TEST(Cameras, OrbitRejectsBadParameters) {
  EXPECT_THROW(orbit_camera(0, 10, 0, 0, 4, 40), Error);
  EXPECT_THROW(orbit_camera(10, 10, 0, 90, 4, 40), Error);
  EXPECT_THROW(orbit_camera(10, 10, 0, 0, 0, 40), Error);
  EXPECT_THROW(orbit_camera(10, 10, 0, 0, 4, 180), Error);
}

TEST(Cameras, JsonWithFieldOfView) {
  const Camera c = parse_camera_json(
      R"({"w": 100, "h": 50, "camera_angle_x": 1.5707963267948966,
          "transform_matrix": [[1,0,0,0.5],[0,1,0,0],[0,0,1,4],[0,0,0,1]]})",
      "cam.json");
  EXPECT_EQ(c.width, 100);
  EXPECT_EQ(c.height, 50);
  EXPECT_NEAR(c.fx, 50.0, 1e-9);  // 50 / tan(45 deg)
  EXPECT_NEAR(c.fy, 50.0, 1e-9);
  EXPECT_EQ(c.cx, 50.0);
  EXPECT_EQ(c.cy, 25.0);
  expect_vec(c.origin(), {0.5, 0, 4});
}

TEST(Cameras, JsonWithFocalLengths) {
  const Camera c = parse_camera_json(
      R"({"w": 80, "h": 60, "fl_x": 70, "fl_y": 72, "cx": 41, "cy": 29,
          "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]})",
      "cam.json");
  EXPECT_EQ(c.fx, 70.0);
  EXPECT_EQ(c.fy, 72.0);
  EXPECT_EQ(c.cx, 41.0);
  EXPECT_EQ(c.cy, 29.0);
}

TEST(Cameras, JsonErrorsNameTheField) {
  auto message = [](const std::string& text) {
    try {
      parse_camera_json(text, "cam.json");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string m = R"("transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]])";
  EXPECT_NE(message(R"({"w": 10, "h": 10, "fl_x": 5})").find("transform_matrix"), std::string::npos);
  EXPECT_NE(message(R"({"h": 10, "fl_x": 5, )" + m + "}").find("\"w\""), std::string::npos);
  EXPECT_NE(message(R"({"w": 10, "h": 10, )" + m + "}").find("camera_angle_x"), std::string::npos);
  EXPECT_NE(message(R"({"w": 0, "h": 10, "fl_x": 5, )" + m + "}").find("image size"), std::string::npos);
  EXPECT_NE(message(R"({"w": 10, "h": 10, "fl_x": 5, "transform_matrix": [[1,0,0,0]]})").find("4 rows"),
            std::string::npos);
  EXPECT_NE(message(R"({"w": 10, "h": 10, "fl_x": "5", )" + m + "}").find("fl_x"), std::string::npos);
  EXPECT_NE(message("{nope").find("not valid JSON"), std::string::npos);
  EXPECT_NE(message("{nope").find("cam.json"), std::string::npos);
}

TEST(Cameras, ResizeScalesIntrinsics) {
  Camera c;
  c.width = 100;
  c.height = 50;
  c.fx = 60;
  c.fy = 62;
  c.cx = 50;
  c.cy = 24;
  const Camera r = resize_camera(c, 200, 25);
  EXPECT_EQ(r.width, 200);
  EXPECT_EQ(r.height, 25);
  EXPECT_EQ(r.fx, 120.0);
  EXPECT_EQ(r.cx, 100.0);
  EXPECT_EQ(r.fy, 31.0);
  EXPECT_EQ(r.cy, 12.0);
  EXPECT_THROW(resize_camera(c, 0, 10), Error);
}

TEST(Options, Background) {
  float rgb[3];
  parse_background("white", "--background", rgb);
  EXPECT_EQ(rgb[2], 1.f);
  parse_background("black", "--background", rgb);
  EXPECT_EQ(rgb[0], 0.f);
  parse_background("0.25,0.5,1", "--background", rgb);
  EXPECT_EQ(rgb[0], 0.25f);
  EXPECT_EQ(rgb[1], 0.5f);
  EXPECT_EQ(rgb[2], 1.f);
  for (const char* bad : {"red", "1,0", "1,0,0,0", "1.5,0,0", "0,,0", "0,0,x", ""}) {
    try {
      parse_background(bad, "--background", rgb);
      ADD_FAILURE() << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("--background"), std::string::npos);
    }
  }
}

TEST(Options, FormAndVectors) {
  EXPECT_EQ(parse_model_form("auto", "--form"), ModelForm::Auto);
  EXPECT_EQ(parse_model_form("float", "--form"), ModelForm::Float);
  EXPECT_EQ(parse_model_form("quantized", "--form"), ModelForm::Quantized);
  EXPECT_THROW(parse_model_form("int8", "--form"), Error);
  EXPECT_STREQ(model_form_name(ModelForm::Quantized), "quantized");
  EXPECT_EQ(parse_vec3("1,-2.5,3e-1", "--center"), (Vec3f{1, -2.5f, 0.3f}));
  EXPECT_THROW(parse_vec3("1,2", "--center"), Error);
  EXPECT_THROW(parse_vec3("1,2,inf", "--center"), Error);
}

}  // namespace
}  // namespace edrnr
