// viz: render hand-built clouds, decode the PNG and check colours at known pixels.
#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include "test_util.hpp"

#include <gtest/gtest.h>

namespace ltm::viz {
namespace {

constexpr Rgb kWhite{255, 255, 255};

Layer L(const PointCloud* c, std::string name = "", PointClass cls = PointClass::kUnknown) {
  Layer l;
  l.cloud = c;
  l.name = std::move(name);
  l.default_class = cls;
  return l;
}

std::size_t CountNonWhite(const Image& img, const Rect& r) {
  std::size_t n = 0;
  for (int y = r.y0; y < r.y0 + r.h; ++y)
    for (int x = r.x0; x < r.x0 + r.w; ++x) n += img.At(x, y) != kWhite;
  return n;
}

bool RectHasColor(const Image& img, const Rect& r, Rgb c) {
  for (int y = r.y0; y < r.y0 + r.h; ++y)
    for (int x = r.x0; x < r.x0 + r.w; ++x)
      if (img.At(x, y) == c) return true;
  return false;
}

struct Scene {
  PointCloud cloud;
  std::vector<std::pair<Eigen::Vector2d, PointClass>> known;  // isolated points
};

// A static strip along y = 2 (x in 0..20), one isolated point of each class, and a PD strong
// point hidden under a static point (same pixel, earlier in the array).
Scene MakeScene() {
  Scene s;
  auto add = [&](double x, double y, PointClass c) {
    s.cloud.push_back(float(x), float(y), 0.f);
    s.cloud.cls.push_back(c);
  };
  add(10.0, 2.0, PointClass::kPDStrong);  // drawn before the static point at the same place
  for (int i = 0; i <= 200; ++i) add(0.1 * i + 0.05, 2.05, PointClass::kStatic);
  const PointClass classes[] = {PointClass::kStatic,   PointClass::kHD,     PointClass::kPDStrong,
                                PointClass::kPDWeak,   PointClass::kNDStrong, PointClass::kNDWeak,
                                PointClass::kUnknown};
  for (int k = 0; k < 7; ++k) {
    const Eigen::Vector2d p(2.05 + 2.5 * k, 8.05);
    add(p.x(), p.y(), classes[k]);
    s.known.push_back({p, classes[k]});
  }
  add(20.0, 20.0, PointClass::kStatic);  // corner, fixes the extent to 0..20
  add(0.0, 0.0, PointClass::kStatic);
  return s;
}

RenderConfig SmallConfig() {
  RenderConfig cfg;
  cfg.meters_per_pixel = 0.1;
  cfg.margin_px = 10;
  return cfg;
}

TEST(Viz, ClassColorsAtKnownPixelsThroughPng) {
  const Scene s = MakeScene();
  Trajectory traj;
  traj.name = "drive";
  for (int k = 0; k <= 4; ++k) traj.positions.emplace_back(2.0 + 4.0 * k, 14.0, 0.0);
  test::TempDir tmp;
  const std::string png = tmp / "map.png";
  const RenderResult r = RenderTopDown({L(&s.cloud, "map")}, {traj}, SmallConfig(), png);
  EXPECT_NEAR(r.meters_per_pixel, 0.1, 1e-12);
  EXPECT_EQ(r.map.w, 201);
  EXPECT_EQ(r.map.h, 201);
  EXPECT_EQ(r.points_drawn, s.cloud.size());

  const Image img = ReadPng(png);
  ASSERT_EQ(img.width, r.image.width);
  ASSERT_EQ(img.height, r.image.height);
  EXPECT_EQ(img.rgb, r.image.rgb);

  int px, py;
  for (const auto& [p, c] : s.known) {
    ASSERT_TRUE(r.WorldToPixel(p.x(), p.y(), &px, &py));
    EXPECT_EQ(img.At(px, py), ClassColor(c)) << ToString(c);
    // Neighbouring pixels are background.
    EXPECT_EQ(img.At(px + 3, py), kWhite);
    EXPECT_EQ(img.At(px, py + 3), kWhite);
  }
  // Map north-up: larger y is higher in the image.
  int px2, py2;
  ASSERT_TRUE(r.WorldToPixel(5.0, 2.05, &px, &py));
  ASSERT_TRUE(r.WorldToPixel(5.0, 8.05, &px2, &py2));
  EXPECT_LT(py2, py);
  // Static strip, and the PD point on top of the static point at the same pixel.
  EXPECT_EQ(img.At(px, py), ClassColor(PointClass::kStatic));
  ASSERT_TRUE(r.WorldToPixel(10.0, 2.0, &px, &py));
  EXPECT_EQ(img.At(px, py), ClassColor(PointClass::kPDStrong));
  // Empty space.
  ASSERT_TRUE(r.WorldToPixel(15.0, 5.0, &px, &py));
  EXPECT_EQ(img.At(px, py), kWhite);
  // Trajectory colour along the line between keyframes.
  for (double x : {3.0, 7.0, 11.5, 17.0}) {
    ASSERT_TRUE(r.WorldToPixel(x, 14.0, &px, &py));
    EXPECT_EQ(img.At(px, py), TrajectoryColor(0)) << x;
  }
  // Keyframe tick: perpendicular to the path, above and below it.
  ASSERT_TRUE(r.WorldToPixel(6.0, 14.0, &px, &py));
  EXPECT_EQ(img.At(px, py - 3), TrajectoryColor(0));
  EXPECT_EQ(img.At(px, py + 3), TrajectoryColor(0));
  ASSERT_TRUE(r.WorldToPixel(8.0, 14.0, &px, &py));
  EXPECT_EQ(img.At(px, py - 3), kWhite);  // no tick between keyframes

  // Legend: beside the map, with text and a swatch of every class present.
  ASSERT_GT(r.legend.w, 0);
  EXPECT_GE(r.legend.x0, r.map.x0 + r.map.w);
  EXPECT_GT(CountNonWhite(img, r.legend), 200u);
  for (const auto& [p, c] : s.known) EXPECT_TRUE(RectHasColor(img, r.legend, ClassColor(c))) << ToString(c);
  EXPECT_TRUE(RectHasColor(img, r.legend, TrajectoryColor(0)));
  // Scale bar below the map: black pixels.
  ASSERT_GT(r.scale_bar.h, 0);
  EXPECT_GE(r.scale_bar.y0, r.map.y0 + r.map.h);
  EXPECT_TRUE(RectHasColor(img, r.scale_bar, Rgb{0, 0, 0}));
}

TEST(Viz, SessionAndHeightModes) {
  PointCloud a, b;
  a.push_back(0.f, 0.f, 0.f);
  a.push_back(10.f, 10.f, 5.f);
  b.push_back(5.f, 5.f, 10.f);
  b.push_back(0.f, 0.f, 1.f);  // same pixel as a's first point: the later session wins
  RenderConfig cfg = SmallConfig();
  cfg.color_by = "session";
  RenderResult r = Render({L(&a, "central"), L(&b, "query")}, {}, cfg);
  int px, py;
  ASSERT_TRUE(r.WorldToPixel(10.0, 10.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), SessionColor(0));
  ASSERT_TRUE(r.WorldToPixel(5.0, 5.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), SessionColor(1));
  ASSERT_TRUE(r.WorldToPixel(0.0, 0.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), SessionColor(1));
  EXPECT_TRUE(RectHasColor(r.image, r.legend, SessionColor(0)));
  EXPECT_TRUE(RectHasColor(r.image, r.legend, SessionColor(1)));

  cfg.color_by = "height";
  cfg.height_min_m = 0.0;
  cfg.height_max_m = 10.0;
  r = Render({L(&a, "central"), L(&b, "query")}, {}, cfg);
  ASSERT_TRUE(r.WorldToPixel(5.0, 5.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), HeightColor(1.0));
  ASSERT_TRUE(r.WorldToPixel(10.0, 10.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), HeightColor(0.5));
  ASSERT_TRUE(r.WorldToPixel(0.0, 0.0, &px, &py));
  EXPECT_EQ(r.image.At(px, py), HeightColor(0.1));  // highest point of the pixel (z = 1)
  EXPECT_TRUE(RectHasColor(r.image, r.legend, HeightColor(0.0)));
  EXPECT_TRUE(RectHasColor(r.image, r.legend, HeightColor(1.0)));
}

TEST(Viz, PerPointSessionsAndSizeLimit) {
  PointCloud c;
  for (int i = 0; i < 1000; ++i) {
    c.push_back(float(i), float(i % 37), 0.f);
    c.session.push_back(std::uint16_t(i % 3));
  }
  RenderConfig cfg;
  cfg.meters_per_pixel = 0.01;  // would be 100k px wide
  cfg.max_size_px = 500;
  cfg.color_by = "session";
  const RenderResult r = Render({L(&c)}, {}, cfg);
  EXPECT_LE(r.map.w, 500);
  EXPECT_LE(r.map.h, 500);
  EXPECT_GT(r.meters_per_pixel, 1.9);
  for (int s = 0; s < 3; ++s) EXPECT_TRUE(RectHasColor(r.image, r.legend, SessionColor(s)));
}

TEST(Viz, EmptyInputsAndErrors) {
  const RenderResult r = Render({}, {}, RenderConfig{});
  EXPECT_GT(r.image.width, 0);
  EXPECT_EQ(r.points_drawn, 0u);
  RenderConfig bad;
  bad.color_by = "rainbow";
  PointCloud c;
  c.push_back(0, 0, 0);
  EXPECT_THROW(Render({L(&c)}, {}, bad), Error);
  EXPECT_THROW(Render({L(nullptr)}, {}, RenderConfig{}), Error);
  EXPECT_THROW(ReadPng("/nonexistent/x.png"), Error);
  EXPECT_EQ(ClassFromFileName("changes/pair_00_01/pd_strong.pcd"), PointClass::kPDStrong);
  EXPECT_EQ(ClassFromFileName("changes/session_00/hd_map.pcd"), PointClass::kHD);
  EXPECT_EQ(ClassFromFileName("a/static_map.pcd"), PointClass::kStatic);
  EXPECT_EQ(ClassFromFileName("a/b.pcd"), PointClass::kUnknown);
}

TEST(Viz, CliRendersPlyAndPoses) {
  test::TempDir tmp;
  const Scene s = MakeScene();
  io::WritePly(tmp / "map.ply", s.cloud);
  PointCloud nd;
  nd.push_back(5.f, 5.f, 0.f);
  io::WritePcd(tmp / "nd_strong.pcd", nd);
  std::vector<Pose> poses(3, Pose::Identity());
  for (int k = 0; k < 3; ++k) poses[std::size_t(k)].translation() = Eigen::Vector3d(2.0 + 5 * k, 14.0, 0.0);
  io::WriteKittiPoses(tmp / "poses.txt", poses);
  std::string out;
  const std::string png = tmp / "out.png";
  ASSERT_EQ(test::RunCli("render --cloud " + (tmp / "map.ply") + " --cloud " + (tmp / "nd_strong.pcd") +
                             " --poses " + (tmp / "poses.txt") + " --color-by class --resolution 0.1 --out " + png,
                         &out),
            0)
      << out;
  const Image img = ReadPng(png);
  EXPECT_GT(img.width, 201);
  // Same layout as the library call (the extent is set by the PLY's corner points).
  const RenderResult r = Render({L(&s.cloud), L(&nd, "", PointClass::kNDStrong)}, {},
                                SmallConfig());
  int px, py;
  ASSERT_TRUE(r.WorldToPixel(5.0, 5.0, &px, &py));
  // The CLI uses the default 16 px margin, SmallConfig 10 px.
  EXPECT_EQ(img.At(px + 6, py + 6), ClassColor(PointClass::kNDStrong));
  EXPECT_NE(test::RunCli("render --cloud " + (tmp / "map.ply") + " --color-by rainbow --out " + png, &out), 0);
  EXPECT_NE(test::RunCli("render --cloud " + (tmp / "missing.pcd") + " --out " + png, &out), 0);
}

}  // namespace
}  // namespace ltm::viz
