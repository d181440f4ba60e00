// Sensor model: preset tables, explicit-table errors, estimation from ring scans (beam
// elevations within 0.05 deg of the table) and detection of a non-repetitive scanner.
#include "ltmapper/geometry/geometry.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace ltm::geometry {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

// A spinning scan of `table` (elevations [deg]) with `columns` azimuths, ranges 4-60 m, 2 %
// dropout: what a ring LiDAR returns.
PointCloud RingScan(const std::vector<double>& table, int columns, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> range(4.0, 60.0), u(0.0, 1.0);
  PointCloud c;
  for (double el : table)
    for (int k = 0; k < columns; ++k) {
      if (u(rng) < 0.02) continue;
      const double az = 2.0 * 3.14159265358979323846 * k / columns, r = range(rng);
      c.push_back(float(r * std::cos(el * kDeg) * std::cos(az)), float(r * std::cos(el * kDeg) * std::sin(az)),
                  float(r * std::sin(el * kDeg)));
    }
  return c;
}

TEST(SensorPreset, RealTablesHaveTheirBeams) {
  EXPECT_EQ(SensorPreset("vlp16").beams(), 16);
  EXPECT_EQ(SensorPreset("hdl32e").beams(), 32);
  EXPECT_EQ(SensorPreset("vlp32c").beams(), 32);
  EXPECT_EQ(SensorPreset("hdl64e").beams(), 64);
  EXPECT_EQ(SensorPreset("os1-64").beams(), 64);
  EXPECT_EQ(SensorPreset("os1-128").beams(), 128);
  EXPECT_EQ(SensorPreset("pandar64").beams(), 64);
  const SensorModel v = SensorPreset("vlp32c");  // non-uniform: dense at the horizon
  EXPECT_NEAR(v.fov_up_deg, 15.0, 1e-9);
  EXPECT_NEAR(v.fov_down_deg, -25.0, 1e-9);
  EXPECT_NEAR(v.SpacingAt(0.1), 0.333, 1e-6);
  EXPECT_NEAR(v.MaxSpacing(), 25.0 - 15.639, 1e-6);
  const SensorModel h = SensorPreset("hdl64e");  // two blocks
  EXPECT_NEAR(h.SpacingAt(0.0), 10.333 / 31, 1e-3);
  EXPECT_NEAR(h.SpacingAt(-20.0), 16.0 / 31, 1e-3);
  EXPECT_THROW(SensorPreset("hdl65e"), Error);
}

TEST(SensorTable, BadTablesAreErrorsNamingTheKey) {
  try {
    ResolveSensor("table", {1.0, 1.0, -2.0}, {}, "sensor");
    FAIL() << "duplicate accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("sensor.elevations_deg"), std::string::npos);
  }
  EXPECT_THROW(SensorFromTable({3.0}, 0.2, "k"), Error);
  EXPECT_THROW(SensorFromTable({3.0, 95.0}, 0.2, "k"), Error);
  EXPECT_THROW(ResolveSensor("auto", {1.0, 2.0}, {}, "sensor"), Error);  // table without `table`
  EXPECT_THROW(ResolveSensor("auto", {}, {}, "sensor"), Error);          // nothing to estimate from
  const SensorModel t = ResolveSensor("table", {-1.0, 2.0, 0.5}, {}, "sensor");
  EXPECT_EQ(t.elevations_deg, (std::vector<double>{2.0, 0.5, -1.0}));
}

TEST(SensorEstimate, RingTablesWithin005Deg) {
  for (const std::string name : {"vlp16", "hdl32e", "vlp32c", "hdl64e", "os1-128", "pandar64", "sim64"}) {
    const SensorModel truth = SensorPreset(name);
    const int columns = int(std::lround(360.0 / truth.azimuth_step_deg));
    const std::vector<PointCloud> scans = {RingScan(truth.elevations_deg, columns, 1),
                                           RingScan(truth.elevations_deg, columns, 2)};
    const SensorModel est = EstimateSensor(scans);
    ASSERT_TRUE(est.ring_based) << name;
    ASSERT_EQ(est.beams(), truth.beams()) << name;
    for (int b = 0; b < truth.beams(); ++b)
      EXPECT_NEAR(est.elevations_deg[std::size_t(b)], truth.elevations_deg[std::size_t(b)], 0.05) << name << " beam " << b;
    EXPECT_NEAR(est.azimuth_step_deg, truth.azimuth_step_deg, 0.05 * truth.azimuth_step_deg) << name;
    EXPECT_LT(est.spread_deg, 0.01) << name;
    EXPECT_EQ(est.azimuth_half_fov_deg, 180.0) << name << ": a ring sensor looks all around";
    EXPECT_TRUE(est.InAzimuthView(179.9) && est.InAzimuthView(-90.0)) << name;
  }
}

TEST(SensorEstimate, NonRepetitivePatternHasNoRings) {
  // Livox-like: directions spread over a 70 x 70 deg cone, no two at the same elevation.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> el(-35.0, 35.0), az(-35.0, 35.0), range(4.0, 60.0);
  PointCloud c;
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    const double e = el(rng) * kDeg, a = az(rng) * kDeg, r = range(rng);
    c.push_back(float(r * std::cos(e) * std::cos(a)), float(r * std::cos(e) * std::sin(a)), float(r * std::sin(e)));
  }
  const SensorModel est = EstimateSensor({c});
  EXPECT_FALSE(est.ring_based);
  EXPECT_NEAR(est.fov_up_deg, 35.0, 0.1);
  EXPECT_NEAR(est.fov_down_deg, -35.0, 0.1);
  // 70 x 70 deg holding 1e5 points: one point per (0.22 deg)^2.
  EXPECT_NEAR(est.grid_deg, 70.0 / std::sqrt(double(n)), 0.02);
  EXPECT_NEAR(est.SpacingAt(0.0), est.grid_deg, 1e-12);
  // Its horizontal field of view: the cone, +-35 deg about +x (to the 1 deg cells it is told in).
  EXPECT_NEAR(est.azimuth_center_deg, 0.0, 1.0);
  EXPECT_NEAR(est.azimuth_half_fov_deg, 35.0, 1.0);
  EXPECT_TRUE(est.InAzimuthView(30.0));
  EXPECT_FALSE(est.InAzimuthView(40.0));
  EXPECT_FALSE(est.InAzimuthView(180.0));
  // The same cone looking back (about 180 deg, across the wrap of the azimuth).
  PointCloud back;
  for (const auto& p : c.points) back.push_back(-p.x, -p.y, p.z);
  const SensorModel rear = EstimateSensor({back});
  EXPECT_NEAR(std::abs(rear.azimuth_center_deg), 180.0, 1.0);
  EXPECT_NEAR(rear.azimuth_half_fov_deg, 35.0, 1.0);
  EXPECT_TRUE(rear.InAzimuthView(-170.0) && rear.InAzimuthView(170.0));
  EXPECT_FALSE(rear.InAzimuthView(0.0));
}

TEST(SensorEstimate, TooFewPointsIsAnError) {
  PointCloud c;
  c.push_back(10.f, 0.f, 0.f);
  EXPECT_THROW(EstimateSensor({c}), Error);
}

}  // namespace
}  // namespace ltm::geometry
