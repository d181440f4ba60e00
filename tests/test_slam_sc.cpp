// Scan Context: descriptor layout, rotation -> column shift and yaw, distance properties, SCD
// input, and place recognition on real KITTI scans.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/slam.hpp"
#include "test_slam_synth.hpp"
#include "test_util.hpp"

#include <cmath>

using namespace ltm;
using namespace ltm::slam;

namespace {
// Loop threshold of the original Scan Context code (1 - mean cosine), a reference for these
// pairs of scans; LT-SLAM itself gates on each session pair's distance statistics.
constexpr double kScOriginalThreshold = 0.4;
PointCloud Rotated(const PointCloud& c, double yaw) {
  return geometry::Transform(c, test::MakePose(0, 0, 0, yaw));
}
}  // namespace

TEST(ScanContext, BinsAndKeys) {
  SlamConfig cfg;
  PointCloud c;
  c.push_back(1.0f, 0.1f, -1.0f);   // ring 0, sector 0, height 1.0
  c.push_back(1.5f, 0.1f, 0.5f);    // same bin, higher: 2.5
  c.push_back(0.0f, 30.0f, 1.0f);   // azimuth 90 deg -> sector 15, ring 7 (30 / 4 m)
  c.push_back(100.0f, 0.0f, 5.0f);  // beyond 80 m: ignored
  const ScanContext sc = MakeScanContext(c, cfg);
  ASSERT_EQ(sc.desc.rows(), 20);
  ASSERT_EQ(sc.desc.cols(), 60);
  EXPECT_FLOAT_EQ(sc.desc(0, 0), 2.5f);
  EXPECT_FLOAT_EQ(sc.desc(7, 15), 3.0f);
  EXPECT_FLOAT_EQ(sc.desc.sum(), 5.5f);
  EXPECT_NEAR(sc.ring_key[0], 2.5 / 60, 1e-6);
  EXPECT_NEAR(sc.sector_key[15], 3.0 / 20, 1e-6);
}

TEST(ScanContext, RotatedScanGivesZeroDistanceAndTheYaw) {
  SlamConfig cfg;
  const PointCloud world = test::SynthWorld(3);
  const auto scan = test::SynthScan(world, test::MakePose(5, 0, 1.8, 0), 60.0, 1, 0.0);
  const ScanContext a = MakeScanContext(*scan, cfg);
  for (int k : {0, 7, 15, 29, 30, 44, 59}) {
    // Rotating the sensor by +yaw rotates the points by -yaw: p_b = Rz(-yaw) p_a. Then
    // p_a = Rz(yaw) p_b, and the match must report that yaw. Exact sector multiples, so the
    // bins map onto each other.
    const double yaw = k * 2 * M_PI / 60.0;
    const ScanContext b = MakeScanContext(Rotated(*scan, -yaw), cfg);
    const ScMatch m = CompareScanContexts(a, b, cfg);
    EXPECT_LT(m.distance, 0.02) << "k=" << k;
    EXPECT_EQ(m.shift, k);
    const double err = std::remainder(m.yaw_rad - yaw, 2 * M_PI);
    EXPECT_LT(std::abs(err), 1e-6) << "k=" << k;
    // Ring keys are rotation invariant.
    // (up to points that fall on the other side of a bin edge after rounding).
    EXPECT_LT((a.ring_key - b.ring_key).norm(), 1e-2 * (1 + a.ring_key.norm()));
  }
  // A rotation between sector boundaries still finds the right yaw within a sector.
  const double yaw = 1.234;
  const ScMatch m = CompareScanContexts(a, MakeScanContext(Rotated(*scan, -yaw), cfg), cfg);
  EXPECT_LT(std::abs(std::remainder(m.yaw_rad - yaw, 2 * M_PI)), 2 * M_PI / 60.0);
  EXPECT_LT(m.distance, 0.2);
}

TEST(ScanContext, DifferentPlacesAreFar) {
  SlamConfig cfg;
  const PointCloud w1 = test::SynthWorld(11), w2 = test::SynthWorld(12);
  const auto s1 = test::SynthScan(w1, test::MakePose(0, 0, 1.8, 0), 60.0, 1);
  const auto s2 = test::SynthScan(w2, test::MakePose(0, 0, 1.8, 0), 60.0, 2);
  const ScMatch m = CompareScanContexts(MakeScanContext(*s1, cfg), MakeScanContext(*s2, cfg), cfg);
  EXPECT_GT(m.distance, kScOriginalThreshold);
  // Empty descriptors: distance 1 (no column to compare), no crash.
  const ScanContext empty = MakeScanContext(PointCloud{}, cfg);
  EXPECT_DOUBLE_EQ(CompareScanContexts(empty, empty, cfg).distance, 1.0);
}

TEST(ScanContext, ScdFileRoundTrip) {
  test::TempDir tmp;
  SlamConfig cfg;
  const PointCloud world = test::SynthWorld(5);
  const auto scan = test::SynthScan(world, test::MakePose(0, 0, 1.8, 0), 60.0, 1);
  const ScanContext a = MakeScanContext(*scan, cfg);
  io::WriteScd(tmp / "000000.scd", a.desc.cast<double>());
  const ScanContext b = ScanContextFromMatrix(io::ReadScd(tmp / "000000.scd"));
  EXPECT_LT((a.desc - b.desc).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LT(CompareScanContexts(a, b, cfg).distance, 1e-6);
}

TEST(ScanContext, SizeMismatchIsAnError) {
  SlamConfig cfg;
  const ScanContext a = ScanContextFromMatrix(Eigen::MatrixXd::Ones(20, 60));
  const ScanContext b = ScanContextFromMatrix(Eigen::MatrixXd::Ones(20, 30));
  EXPECT_THROW(CompareScanContexts(a, b, cfg), Error);
}

TEST(ScanContextReal, KittiScans0And5AreTheSamePlace) {
  LTM_REQUIRE_REAL_DATA(data);
  const std::string dir = data + "/kitti00_head";
  SlamConfig cfg;
  const PointCloud s0 = io::ReadKittiBin(dir + "/velodyne/000000.bin");
  const PointCloud s5 = io::ReadKittiBin(dir + "/velodyne/000005.bin");
  const ScMatch m = CompareScanContexts(MakeScanContext(s0, cfg), MakeScanContext(s5, cfg), cfg);
  std::printf("KITTI 0 vs 5: SC distance %.3f, yaw %.2f deg\n", m.distance, m.yaw_rad * 180 / M_PI);
  EXPECT_LT(m.distance, kScOriginalThreshold);
  EXPECT_LT(std::abs(m.yaw_rad), 2 * 2 * M_PI / 60.0);  // within two sectors of 0
}
