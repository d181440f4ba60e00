// Our FPFH descriptors (slam/global.cpp, the global registration's features) against PCL's
// FPFHEstimation, with PCL's normals, on a real scan and on a simulated scene: the same histograms.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/internal.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>
#include <pcl/features/fpfh.h>
#include <pcl/features/normal_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <cmath>
#include <random>

namespace ltm {
namespace {

// Largest difference of one bin between our descriptors and PCL's, per point; and how many
// points have a non-zero descriptor (so that equal all-zero histograms cannot pass).
void CompareWithPcl(const PointCloud& cloud, double normal_radius, double feature_radius) {
  auto pc = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& p : cloud.points) pc->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  auto tree = pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>();
  auto normals = pcl::make_shared<pcl::PointCloud<pcl::Normal>>();
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(pc);
  ne.setSearchMethod(tree);
  ne.setRadiusSearch(normal_radius);
  ne.setViewPoint(0.f, 0.f, 1e4f);
  ne.compute(*normals);
  pcl::PointCloud<pcl::FPFHSignature33> theirs;
  pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fe;
  fe.setInputCloud(pc);
  fe.setInputNormals(normals);
  fe.setSearchMethod(tree);
  fe.setRadiusSearch(feature_radius);
  fe.compute(theirs);

  std::vector<Eigen::Vector3f> n(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) n[i] = (*normals)[i].getNormalVector3fMap();
  const std::vector<slam::Fpfh> ours = slam::FpfhDescriptors(cloud, n, feature_radius);
  ASSERT_EQ(ours.size(), theirs.size());
  std::size_t close = 0, described = 0;
  double worst = 0.0;
  for (std::size_t i = 0; i < ours.size(); ++i) {
    float sum = 0.f;
    double l1 = 0.0;  // of 300: each of the three parts sums to 100
    for (int b = 0; b < 33; ++b) {
      sum += ours[i][std::size_t(b)];
      l1 += std::fabs(double(ours[i][std::size_t(b)]) - double(theirs[i].histogram[b]));
    }
    described += sum > 0.f;
    close += l1 < 1.0;  // a pair near a bin edge rounding the other way moves a few hundredths
    worst = std::max(worst, l1);
  }
  std::printf("FPFH of %zu points: %zu described, %zu within 1 %% of PCL's (L1 < 1 of 300; worst %.3g)\n",
              ours.size(), described, close, worst);
  EXPECT_GT(described, ours.size() * 9 / 10);
  EXPECT_GE(close, ours.size() * 99 / 100);
}

TEST(Fpfh, EqualsPclOnARealScan) {
  LTM_REQUIRE_REAL_DATA(data);
  const PointCloud scan = io::ReadPcd(data + "/gicp_pair/251370668.pcd");
  const double voxel = 0.5;
  CompareWithPcl(geometry::VoxelDownsample(scan, voxel, 1), 2 * voxel, 5 * voxel);
}

TEST(Fpfh, EqualsPclOnASimulatedScene) {
  // Ground, a wall and a box with noise: planes, edges and corners.
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.f, 0.02f);
  PointCloud c;
  for (float x = -10; x <= 10; x += 0.4f)
    for (float y = -10; y <= 10; y += 0.4f) c.push_back(x, y, noise(rng));
  for (float x = -10; x <= 10; x += 0.4f)
    for (float z = 0.4f; z <= 4; z += 0.4f) c.push_back(x, 6.f + noise(rng), z);
  for (float x = -1; x <= 1; x += 0.25f)
    for (float y = -1; y <= 1; y += 0.25f) c.push_back(x, y, 1.5f + noise(rng));
  CompareWithPcl(c, 1.0, 2.0);
}

}  // namespace
}  // namespace ltm
