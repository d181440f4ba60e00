// Oracle tests for the geometry module: kd-tree vs brute force, voxel grid vs a std::map
// reference, range-image pixel math on hand-placed points, transforms round trip.
#include "ltmapper/geometry/geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>

namespace ltm::geometry {
namespace {

PointCloud RandomCloud(std::size_t n, float extent, unsigned seed, Eigen::Vector3f offset = {0, 0, 0}) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i)
    c.push_back(offset.x() + u(rng), offset.y() + u(rng), offset.z() + u(rng), float(i % 7));
  return c;
}

void AddArrays(PointCloud& c) {
  for (std::size_t i = 0; i < c.size(); ++i) {
    c.cls.push_back(PointClass(i % 7));
    c.session.push_back(std::uint16_t(i % 3));
    c.object.push_back(std::int32_t(i));
  }
}

// ------------------------------------------------------------------------------ transforms
TEST(Transform, RoundTripAndArraysKept) {
  PointCloud c = RandomCloud(500, 50.f, 1);
  AddArrays(c);
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(10, -20, 3);
  const PointCloud t = Transform(c, T);
  ASSERT_EQ(t.size(), c.size());
  EXPECT_EQ(t.cls, c.cls);
  EXPECT_EQ(t.session, c.session);
  EXPECT_EQ(t.object, c.object);
  for (std::size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3d expect = T * c.points[i].xyz().cast<double>();
    EXPECT_LT((t.points[i].xyz().cast<double>() - expect).norm(), 1e-4);
    EXPECT_EQ(t.points[i].intensity, c.points[i].intensity);
  }
  PointCloud back = t;
  TransformInPlace(back, T.inverse());
  for (std::size_t i = 0; i < c.size(); ++i)
    EXPECT_LT((back.points[i].xyz() - c.points[i].xyz()).norm(), 1e-4f);
}

TEST(Filters, RangeCropNonFiniteKeepArraysAligned) {
  PointCloud c;
  c.push_back(1, 0, 0);    // r = 1
  c.push_back(0, 5, 0);    // r = 5
  c.push_back(0, 0, 10);   // r = 10
  c.push_back(20, 0, 0);   // r = 20
  AddArrays(c);
  PointCloud r = RangeFilter(c, 5.0, 10.0);  // bounds inclusive
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r.object, (std::vector<std::int32_t>{1, 2}));
  EXPECT_EQ(r.cls.size(), 2u);

  PointCloud b = CropBox(c, Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 5, 5));
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b.object, (std::vector<std::int32_t>{0, 1}));
  EXPECT_EQ(b.session, (std::vector<std::uint16_t>{0, 1}));

  PointCloud n = c;
  n.points[1].y = std::numeric_limits<float>::quiet_NaN();
  n.points[3].z = std::numeric_limits<float>::infinity();
  EXPECT_EQ(RemoveNonFinite(n), 2u);
  ASSERT_EQ(n.size(), 2u);
  EXPECT_EQ(n.object, (std::vector<std::int32_t>{0, 2}));
  EXPECT_EQ(n.cls.size(), 2u);
  EXPECT_EQ(n.session.size(), 2u);
  EXPECT_EQ(RemoveNonFinite(n), 0u);
}

// -------------------------------------------------------------------------- voxel downsampling
struct RefVoxel {
  double sx = 0, sy = 0, sz = 0, si = 0;
  std::size_t n = 0;
  std::size_t first = 0;
};

// Slow reference: std::map keyed by the voxel index triple (lexicographic = documented order).
std::map<std::array<std::int64_t, 3>, RefVoxel> RefVoxels(const PointCloud& c, double v) {
  std::map<std::array<std::int64_t, 3>, RefVoxel> m;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const auto& p = c.points[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    std::array<std::int64_t, 3> k{std::int64_t(std::floor(p.x / v)), std::int64_t(std::floor(p.y / v)),
                                  std::int64_t(std::floor(p.z / v))};
    auto [it, inserted] = m.try_emplace(k);
    if (inserted) it->second.first = i;
    it->second.sx += p.x;
    it->second.sy += p.y;
    it->second.sz += p.z;
    it->second.si += p.intensity;
    ++it->second.n;
  }
  return m;
}

void ExpectMatchesReference(const PointCloud& c, double v, int threads) {
  const PointCloud d = VoxelDownsample(c, v, threads);
  const auto ref = RefVoxels(c, v);
  ASSERT_EQ(d.size(), ref.size());
  std::size_t j = 0;
  for (const auto& [k, r] : ref) {
    const auto& p = d.points[j];
    const double tol = 1e-6 * (1.0 + std::abs(r.sx / r.n) + std::abs(r.sy / r.n) + std::abs(r.sz / r.n));
    EXPECT_NEAR(p.x, r.sx / r.n, tol) << "voxel " << j;
    EXPECT_NEAR(p.y, r.sy / r.n, tol) << "voxel " << j;
    EXPECT_NEAR(p.z, r.sz / r.n, tol) << "voxel " << j;
    EXPECT_NEAR(p.intensity, r.si / r.n, 1e-5);
    if (!c.object.empty()) {
      EXPECT_EQ(d.object[j], c.object[r.first]);
      EXPECT_EQ(d.cls[j], c.cls[r.first]);
      EXPECT_EQ(d.session[j], c.session[r.first]);
    }
    ++j;
  }
}

TEST(Voxel, MatchesReferenceRandomNegativeCoords) {
  PointCloud c = RandomCloud(20000, 10.f, 2);
  AddArrays(c);
  ExpectMatchesReference(c, 0.5, 1);
  ExpectMatchesReference(c, 0.5, 2);
  ExpectMatchesReference(c, 3.0, 0);
}

TEST(Voxel, BoundaryPointsGoToUpperVoxel) {
  PointCloud c;
  c.push_back(0.f, 0.f, 0.f);    // voxel (0,0,0)
  c.push_back(0.5f, 0.f, 0.f);   // exactly on the boundary: voxel (1,0,0)
  c.push_back(-0.5f, 0.f, 0.f);  // voxel (-1,0,0)
  c.push_back(-0.f, 0.f, 0.f);   // -0 joins voxel 0
  c.push_back(0.49f, 0.49f, 0.49f);
  c.push_back(-1e-7f, 0.f, 0.f);  // voxel (-1,0,0)
  const PointCloud d = VoxelDownsample(c, 0.5, 1);
  ASSERT_EQ(d.size(), 3u);
  EXPECT_NEAR(d.points[0].x, (-0.5 - 1e-7) / 2, 1e-7);
  EXPECT_NEAR(d.points[1].x, 0.49 / 3, 1e-6);
  EXPECT_NEAR(d.points[1].y, 0.49 / 3, 1e-6);
  EXPECT_FLOAT_EQ(d.points[2].x, 0.5f);
  ExpectMatchesReference(c, 0.5, 2);
}

TEST(Voxel, FarCoordinatesAndWideKeys) {
  // +-1e6 m: packed keys for 1 m voxels, the 3 x int64 fallback for 1 mm voxels.
  PointCloud c = RandomCloud(3000, 30.f, 3, {1e6f, -1e6f, 5e5f});
  PointCloud far2 = RandomCloud(3000, 30.f, 4, {-1e6f, 1e6f, -5e5f});
  c.append(far2);
  AddArrays(c);
  ExpectMatchesReference(c, 1.0, 2);
  ExpectMatchesReference(c, 0.001, 2);
  EXPECT_THROW(VoxelDownsample(c, 1e-20, 1), Error);
}

// Bit-identical points, in the same order.
void ExpectSamePoints(const PointCloud& a, const PointCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a.points[i].x, b.points[i].x);
    ASSERT_EQ(a.points[i].y, b.points[i].y);
    ASSERT_EQ(a.points[i].z, b.points[i].z);
    ASSERT_EQ(a.points[i].intensity, b.points[i].intensity);
  }
}

TEST(Voxel, RunsOfVoxelisedCloudsMergeToTheSameResult) {
  // Three voxelised clouds, overlapping, concatenated; then one run out of order.
  PointCloud cat;
  std::vector<std::size_t> starts;
  for (int k = 0; k < 3; ++k) {
    PointCloud c = RandomCloud(30000, 20.f, 11 + k);
    for (auto& p : c.points) p.x += 5.f * float(k);
    starts.push_back(cat.size());
    cat.append(VoxelDownsample(c, 0.25, 1));
  }
  const PointCloud want = VoxelDownsample(cat, 0.25, 2);
  ExpectSamePoints(VoxelDownsampleRuns(cat, starts, 0.25, 2), want);
  ExpectSamePoints(VoxelDownsampleRuns(cat, starts, 0.25, 1), want);
  std::swap(cat.points[starts[1] + 3], cat.points[starts[1] + 4000]);  // run 1 no longer sorted
  ExpectSamePoints(VoxelDownsampleRuns(cat, starts, 0.25, 2), VoxelDownsample(cat, 0.25, 2));
  EXPECT_THROW(VoxelDownsampleRuns(cat, {5, 10}, 0.25), Error);
  EXPECT_THROW(VoxelDownsampleRuns(cat, {0, 10, 3}, 0.25), Error);
}

TEST(Voxel, ManyRunsMergeInKeyRangesToTheSameResult) {
  // Enough points for several parallel key ranges; runs overlap in space, carry per-point arrays
  // (taken from a voxel's first point, in run order), and share voxels with up to 12 others.
  PointCloud cat;
  std::vector<std::size_t> starts;
  for (int k = 0; k < 12; ++k) {
    PointCloud c = RandomCloud(60000, 15.f, 100 + k, {float(k), 0.f, 0.f});
    AddArrays(c);
    starts.push_back(cat.size());
    cat.append(VoxelDownsample(c, 0.3, 1));
  }
  ASSERT_GT(cat.size(), 4u * 65536u);
  const PointCloud want = VoxelDownsample(cat, 0.3, 2);
  for (int threads : {1, 2}) {
    const PointCloud got = VoxelDownsampleRuns(cat, starts, 0.3, threads);
    ExpectSamePoints(got, want);
    EXPECT_EQ(got.cls, want.cls);
    EXPECT_EQ(got.session, want.session);
    EXPECT_EQ(got.object, want.object);
  }
  // Empty runs are allowed.
  std::vector<std::size_t> with_empty = starts;
  with_empty.insert(with_empty.begin() + 3, starts[3]);
  with_empty.push_back(cat.size());
  ExpectSamePoints(VoxelDownsampleRuns(cat, with_empty, 0.3, 2), want);
}

TEST(Voxel, ThreadCountDoesNotChangeOutput) {
  PointCloud c = RandomCloud(200000, 40.f, 5);
  AddArrays(c);
  const PointCloud a = VoxelDownsample(c, 0.3, 1);
  const PointCloud b = VoxelDownsample(c, 0.3, 2);
  ExpectSamePoints(a, b);
  EXPECT_EQ(a.object, b.object);
}

TEST(Voxel, EmptyNonFiniteAndBadArgs) {
  EXPECT_TRUE(VoxelDownsample(PointCloud{}, 1.0).empty());
  PointCloud c;
  c.push_back(std::numeric_limits<float>::quiet_NaN(), 0, 0);
  EXPECT_TRUE(VoxelDownsample(c, 1.0).empty());
  c.push_back(1.2f, 0, 0);
  EXPECT_EQ(VoxelDownsample(c, 1.0).size(), 1u);
  EXPECT_THROW(VoxelDownsample(c, 0.0), Error);
  EXPECT_THROW(VoxelDownsample(c, -1.0), Error);
  EXPECT_THROW(VoxelDownsample(c, 1.0, -2), Error);
}

// ----------------------------------------------------------------------------------- kd-tree
// Same arithmetic as the tree: float differences, double squares and sum.
double Sq(const Eigen::Vector3f& q, const PointXYZI& p) {
  const double dx = q.x() - p.x, dy = q.y() - p.y, dz = q.z() - p.z;
  return dx * dx + dy * dy + dz * dz;
}

void CheckOneTree(const KdTree& tree, const PointCloud& c, const std::vector<Eigen::Vector3f>& queries, float radius);

// One tree and forests of blocks (2 threads; 3, 17 and 500 points a block) give the same exact
// answers.
void CheckTree(const PointCloud& c, const std::vector<Eigen::Vector3f>& queries, float radius) {
  CheckOneTree(KdTree(c), c, queries, radius);
  for (std::size_t block : {std::size_t(3), std::size_t(17), std::size_t(500)}) {
    SCOPED_TRACE("blocks of " + std::to_string(block));
    CheckOneTree(KdTree(c, 2, block), c, queries, radius);
  }
}

void CheckOneTree(const KdTree& tree, const PointCloud& c, const std::vector<Eigen::Vector3f>& queries, float radius) {
  ASSERT_EQ(tree.size(), c.size());
  const double r2 = double(radius) * double(radius);
  for (const auto& q : queries) {
    std::vector<std::pair<double, std::uint32_t>> all;
    for (std::size_t i = 0; i < c.size(); ++i) all.emplace_back(Sq(q, c.points[i]), std::uint32_t(i));
    std::sort(all.begin(), all.end());

    // Radius: exact index set, sorted by (distance, index).
    std::vector<std::uint32_t> expect_r;
    for (const auto& [d, i] : all)
      if (d < r2) expect_r.push_back(i);
    const auto got_r = tree.Radius(q, radius);
    ASSERT_EQ(got_r.size(), expect_r.size());
    std::vector<std::uint32_t> got_idx;
    for (std::size_t j = 0; j < got_r.size(); ++j) {
      got_idx.push_back(got_r[j].first);
      EXPECT_EQ(got_r[j].second, float(Sq(q, c.points[got_r[j].first])));
      if (j > 0) {
        EXPECT_LE(got_r[j - 1].second, got_r[j].second);
      }
    }
    std::vector<std::uint32_t> a = got_idx, b = expect_r;
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    EXPECT_EQ(a, b);
    // RadiusUnsorted: the same pairs in another order.
    auto unsorted = tree.RadiusUnsorted(q, radius);
    std::sort(unsorted.begin(), unsorted.end());
    auto sorted = got_r;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(unsorted, sorted);

    // CountWithin with early stop.
    for (std::size_t max_count : {std::size_t(1), std::size_t(3), std::size_t(1000000)})
      EXPECT_EQ(tree.CountWithin(q, radius, max_count), std::min(max_count, expect_r.size()));

    // Knn: the k smallest distances (ties may pick different indices of equal distance).
    for (std::size_t k : {std::size_t(1), std::size_t(4), std::size_t(10)}) {
      const auto got = tree.Knn(q, k);
      ASSERT_EQ(got.size(), std::min(k, c.size()));
      for (std::size_t j = 0; j < got.size(); ++j) {
        EXPECT_EQ(got[j].second, float(all[j].first)) << "k=" << k << " j=" << j;
        EXPECT_EQ(got[j].second, float(Sq(q, c.points[got[j].first])));
      }
    }
    std::uint32_t ni = 99;
    float nd = -1.f;
    if (c.empty()) {
      EXPECT_FALSE(tree.Nearest(q, &ni, &nd));
    } else {
      ASSERT_TRUE(tree.Nearest(q, &ni, &nd));
      EXPECT_EQ(nd, float(all[0].first));
      EXPECT_EQ(float(Sq(q, c.points[ni])), nd);
    }
  }
}

std::vector<Eigen::Vector3f> Queries(const PointCloud& c, std::size_t n, float extent, unsigned seed,
                                     Eigen::Vector3f offset = {0, 0, 0}) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  std::vector<Eigen::Vector3f> q;
  for (std::size_t i = 0; i < n; ++i) q.emplace_back(offset.x() + u(rng), offset.y() + u(rng), offset.z() + u(rng));
  for (std::size_t i = 0; i < std::min<std::size_t>(c.size(), 5); ++i) q.push_back(c.points[i].xyz());
  return q;
}

TEST(KdTree, EmptyCloud) {
  PointCloud c;
  CheckTree(c, Queries(c, 3, 1.f, 1), 1.f);
  KdTree t(c);
  EXPECT_TRUE(t.Knn({0, 0, 0}, 3).empty());
  EXPECT_EQ(t.CountWithin({0, 0, 0}, 10.f, 10), 0u);
}

TEST(KdTree, OneToFivePoints) {
  for (std::size_t n = 1; n <= 5; ++n) {
    const PointCloud c = RandomCloud(n, 2.f, unsigned(10 + n));
    CheckTree(c, Queries(c, 20, 3.f, unsigned(n)), 1.5f);
  }
}

TEST(KdTree, DuplicatesAndTies) {
  PointCloud c;
  for (int i = 0; i < 40; ++i) c.push_back(1.f, 2.f, 3.f);  // all identical
  for (int x = -3; x <= 3; ++x)
    for (int y = -3; y <= 3; ++y) c.push_back(float(x), float(y), 0.f);  // grid: many equal distances
  std::vector<Eigen::Vector3f> q = Queries(c, 30, 4.f, 7);
  q.push_back({0.5f, 0.5f, 0.f});
  q.push_back({1.f, 2.f, 3.f});
  q.push_back({0.f, 0.f, 0.f});
  CheckTree(c, q, 1.0f);   // grid neighbours at exactly 1.0 are excluded (strict)
  CheckTree(c, q, 2.5f);
}

TEST(KdTree, RandomAndFarFromOrigin) {
  const PointCloud c = RandomCloud(3000, 20.f, 21);
  CheckTree(c, Queries(c, 200, 22.f, 22), 2.0f);
  const Eigen::Vector3f off(1e6f, -1e6f, 1e6f);
  const PointCloud f = RandomCloud(2000, 50.f, 23, off);
  CheckTree(f, Queries(f, 100, 55.f, 24, off), 6.0f);
}

TEST(KdTree, SharedCloudAndMove) {
  auto c = std::make_shared<const PointCloud>(RandomCloud(100, 5.f, 30));
  KdTree a(c);
  EXPECT_EQ(&a.cloud(), c.get());
  KdTree b(std::move(a));
  EXPECT_EQ(b.size(), 100u);
  std::uint32_t i;
  float d;
  ASSERT_TRUE(b.Nearest(c->points[17].xyz(), &i, &d));
  EXPECT_EQ(i, 17u);
  EXPECT_EQ(d, 0.f);
  PointCloud bad;
  bad.push_back(std::numeric_limits<float>::quiet_NaN(), 0, 0);
  EXPECT_THROW(KdTree{bad}, Error);
}

// ------------------------------------------------------------------------------ range images
Eigen::Vector3f Dir(double az_deg, double el_deg, double r) {
  const double az = az_deg * M_PI / 180, el = el_deg * M_PI / 180;
  return (r * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)))
      .cast<float>();
}

TEST(RangeImage, PixelOfHandPlacedPoints) {
  const RangeImage img(RangeImageConfig{});  // 64 x 900, +2 .. -24.8 deg
  int row, col;
  float r;
  // Straight ahead: pitch 0 -> row floor(2 / 26.8 * 64) = 4; azimuth 0 -> column 450.
  ASSERT_TRUE(img.Project({10.f, 0.f, 0.f}, &row, &col, &r));
  EXPECT_EQ(row, 4);
  EXPECT_EQ(col, 450);
  EXPECT_FLOAT_EQ(r, 10.f);
  // Behind: azimuth +-180 deg -> column 0 (both signs of zero y).
  ASSERT_TRUE(img.Project({-10.f, 0.f, 0.f}, &row, &col, &r));
  EXPECT_EQ(col, 0);
  ASSERT_TRUE(img.Project({-10.f, -0.f, 0.f}, &row, &col, &r));
  EXPECT_EQ(col, 0);
  ASSERT_TRUE(img.Project(Dir(-179.9, 0, 5), &row, &col, &r));
  EXPECT_EQ(col, 899);
  ASSERT_TRUE(img.Project(Dir(179.9, 0, 5), &row, &col, &r));
  EXPECT_EQ(col, 0);
  // Left (+y, azimuth +90) -> column 225 (clockwise from +180); right -> 675.
  ASSERT_TRUE(img.Project({0.f, 10.f, 0.f}, &row, &col, &r));
  EXPECT_EQ(col, 225);
  ASSERT_TRUE(img.Project({0.f, -10.f, 0.f}, &row, &col, &r));
  EXPECT_EQ(col, 675);
  // Vertical FOV edges.
  ASSERT_TRUE(img.Project(Dir(30, 1.99, 20), &row, &col, &r));
  EXPECT_EQ(row, 0);
  ASSERT_TRUE(img.Project(Dir(30, -24.79, 20), &row, &col, &r));
  EXPECT_EQ(row, 63);
  EXPECT_FALSE(img.Project(Dir(30, 2.1, 20), &row, &col, &r));
  EXPECT_FALSE(img.Project(Dir(30, -25.0, 20), &row, &col, &r));
  EXPECT_FALSE(img.Project({0.f, 0.f, 0.f}, &row, &col, &r));
  // A row boundary: pitch 2 - 26.8 * 10.5 / 64 deg is in the middle of row 10.
  ASSERT_TRUE(img.Project(Dir(0, 2.0 - 26.8 * 10.5 / 64, 7), &row, &col, &r));
  EXPECT_EQ(row, 10);
}

TEST(RangeImage, BuildKeepsMinimumRangeAndIndex) {
  RangeImage img(RangeImageConfig{});
  PointCloud c;
  c.push_back(20.f, 0.f, 0.f);   // 0: far
  c.push_back(5.f, 0.f, 0.f);    // 1: near, same pixel -> wins
  c.push_back(10.f, 0.f, 0.f);   // 2
  c.push_back(0.f, 0.f, 50.f);   // 3: outside FOV
  c.push_back(0.f, -3.f, 0.f);   // 4: right
  img.Build(c);
  EXPECT_FLOAT_EQ(img.At(4, 450), 5.f);
  EXPECT_EQ(img.IndexAt(4, 450), 1);
  EXPECT_FLOAT_EQ(img.At(4, 675), 3.f);
  EXPECT_EQ(img.IndexAt(4, 675), 4);
  int filled = 0;
  for (int r = 0; r < img.rows(); ++r)
    for (int k = 0; k < img.cols(); ++k) {
      if (img.IndexAt(r, k) >= 0) {
        ++filled;
      } else {
        EXPECT_TRUE(std::isinf(img.At(r, k)));
      }
    }
  EXPECT_EQ(filled, 2);
  img.Build(PointCloud{});  // resets
  EXPECT_EQ(img.IndexAt(4, 450), -1);
  EXPECT_TRUE(std::isinf(img.At(4, 450)));
}

TEST(RangeImage, RandomPointsLandWithinOnePixelOfTheirDirection) {
  RangeImageConfig cfg;
  cfg.rows = 32;
  cfg.cols = 360;
  cfg.fov_up_deg = 15;
  cfg.fov_down_deg = -15;
  const RangeImage img(cfg);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> az(-180, 180), el(-14.9, 14.9), rr(0.5, 80);
  for (int i = 0; i < 2000; ++i) {
    const double a = az(rng), e = el(rng);
    int row, col;
    float r;
    ASSERT_TRUE(img.Project(Dir(a, e, rr(rng)), &row, &col, &r));
    const double row_exact = (15.0 - e) / 30.0 * 32;
    const double col_exact = (180.0 - a) / 360.0 * 360;
    EXPECT_LE(std::abs(row + 0.5 - row_exact), 0.5 + 1e-3);
    const double dc = std::abs(col + 0.5 - col_exact);
    EXPECT_LE(std::min(dc, 360 - dc), 0.5 + 1e-3);
  }
  EXPECT_THROW(RangeImage(RangeImageConfig{1.0, 2.0, 64, 900}), Error);
  EXPECT_THROW(RangeImage(RangeImageConfig{2.0, -2.0, 0, 900}), Error);
}

// Euclidean clusters: transitive links closer than the gap, numbered by lowest point index; the
// longest horizontal edge of the xy-oriented box.
TEST(Geometry, EuclideanClustersAndHorizontalEdge) {
  PointCloud c;
  for (int i = 0; i < 10; ++i) c.push_back(0.3f * float(i), 0.f, 0.f);  // a 2.7 m chain, links of 0.3 m
  c.push_back(10.f, 10.f, 0.f);                                          // alone
  for (int i = 0; i < 5; ++i) {                                          // a diagonal chain, 0.4 m links
    const float t = 0.4f * float(i) / std::sqrt(2.f);
    c.push_back(20.f + t, 20.f + t, 1.f);
  }
  const auto label = geometry::EuclideanClusters(c, 0.5);
  ASSERT_EQ(label.size(), c.size());
  for (int i = 0; i < 10; ++i) EXPECT_EQ(label[std::size_t(i)], 0u);
  EXPECT_EQ(label[10], 1u);
  for (int i = 11; i < 16; ++i) EXPECT_EQ(label[std::size_t(i)], 2u);
  const auto fine = geometry::EuclideanClusters(c, 0.35);  // the 0.4 m links break, the 0.3 m ones hold
  EXPECT_EQ(fine[9], 0u);
  EXPECT_EQ(fine[11], 2u);
  EXPECT_EQ(fine[15], 6u);
  std::vector<std::uint32_t> chain(10), diag{11, 12, 13, 14, 15};
  for (std::uint32_t i = 0; i < 10; ++i) chain[i] = i;
  EXPECT_NEAR(geometry::LongestHorizontalEdge(c, chain), 2.7, 1e-5);
  EXPECT_NEAR(geometry::LongestHorizontalEdge(c, diag), 1.6, 1e-5);  // along the diagonal, not the axes' 1.13
  EXPECT_EQ(geometry::LongestHorizontalEdge(c, {10}), 0.0);
  EXPECT_TRUE(geometry::EuclideanClusters(PointCloud(), 0.5).empty());
}

// A 6.06 x 2.44 m container turned by 30 deg and scanned on two faces (an L of points along one
// long and one short side): the box whose sides the points hug is the container's; the principal
// axes' box is longer (the L's spread tilts its axis), and the smallest-area box of the L's
// triangular hull may lie along its hypotenuse (a right triangle's two boxes have equal areas).
TEST(Geometry, SidesBoxOfAnLShapedScan) {
  const double yaw = 30.0 * M_PI / 180.0, L = 6.06, W = 2.44;
  const Eigen::Vector2d u(std::cos(yaw), std::sin(yaw)), v(-u.y(), u.x()), c(10.0, -4.0);
  PointCloud scan;
  auto add = [&](const Eigen::Vector2d& p) { scan.push_back(float(p.x()), float(p.y()), 1.f); };
  for (int i = 0; i <= 60; ++i) add(c + u * (L * (i / 60.0 - 0.5)) - v * (W / 2));   // long face
  for (int i = 1; i <= 12; ++i) add(c + u * (L / 2) + v * (W * (i / 12.0 - 0.5)));   // short face
  const geometry::HorizontalBox b = geometry::SidesBoxOf(scan);
  EXPECT_NEAR(b.length, L, 1e-4);
  EXPECT_NEAR(b.width, W, 1e-4);
  EXPECT_NEAR(std::abs(std::sin(b.yaw_rad - yaw)), 0.0, 1e-4);  // along the long side, either way
  EXPECT_NEAR((b.center - c).norm(), 0.0, 1e-4);
  EXPECT_GT(geometry::HorizontalBoxOf(scan).length, L + 0.25);  // its axis tilted towards the short face
  // Fewer than three points, or all on one spot: the principal axes' box.
  EXPECT_NEAR(geometry::SidesBoxOf(scan, {0, 60}).length, L, 1e-4);
  PointCloud spot;
  for (int i = 0; i < 4; ++i) spot.push_back(1.f, 2.f, 0.f);
  EXPECT_NEAR(geometry::SidesBoxOf(spot).length, 0.0, 1e-9);
}

// More points than one batch of the parallel neighbour search (64 x 1024), more than one kd-tree
// block: the labels of every thread count equal those of a brute-force join of all close pairs.
TEST(Geometry, EuclideanClustersOnManyCoresEqualOneCore) {
  const PointCloud c = RandomCloud(140000, 20.f, 41);  // about 2 neighbours a point
  const double gap = 0.6;
  const auto one = geometry::EuclideanClusters(c, gap, 1);
  EXPECT_EQ(geometry::EuclideanClusters(c, gap, 3), one);
  // Brute force on a grid of gap-sized cells: join every pair closer than the gap.
  std::vector<std::uint32_t> parent(c.size());
  std::iota(parent.begin(), parent.end(), 0u);
  auto root = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i];
    return i;
  };
  std::map<std::array<int, 3>, std::vector<std::uint32_t>> cells;
  auto cell = [&](const PointXYZI& p) {
    return std::array<int, 3>{int(std::floor(p.x / gap)), int(std::floor(p.y / gap)), int(std::floor(p.z / gap))};
  };
  for (std::uint32_t i = 0; i < c.size(); ++i) cells[cell(c.points[i])].push_back(i);
  for (std::uint32_t i = 0; i < c.size(); ++i) {
    const auto k = cell(c.points[i]);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells.find({k[0] + dx, k[1] + dy, k[2] + dz});
          if (it == cells.end()) continue;
          for (const std::uint32_t j : it->second)
            if (j > i && Sq(c.points[i].xyz(), c.points[j]) < gap * gap) {
              const std::uint32_t a = root(i), b = root(j);
              if (a != b) parent[std::max(a, b)] = std::min(a, b);
            }
        }
  }
  std::map<std::uint32_t, std::uint32_t> number;
  std::size_t differ = 0;
  for (std::uint32_t i = 0; i < c.size(); ++i) {
    const std::uint32_t r = root(i);
    const auto it = number.emplace(r, std::uint32_t(number.size())).first;
    differ += it->second != one[i];
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(number.size(), 100u);   // many clusters,
  EXPECT_LT(number.size(), 50000u);  // and many links
  // Members: cluster k's points in ascending order, the same clusters.
  const auto members = geometry::EuclideanClusterMembers(c, gap, 2);
  ASSERT_EQ(members.size(), number.size());
  std::size_t listed = 0;
  for (std::size_t k = 0; k < members.size(); ++k) {
    EXPECT_TRUE(std::is_sorted(members[k].begin(), members[k].end()));
    for (const std::uint32_t i : members[k]) EXPECT_EQ(one[i], k);
    listed += members[k].size();
  }
  EXPECT_EQ(listed, c.size());
  EXPECT_TRUE(geometry::EuclideanClusterMembers(PointCloud{}, gap).empty());
}

// Per-point gaps: equal gaps give the plain clusters; rows 0.6 m apart join with a 1 m vertical
// gap while columns 0.6 m apart stay apart with a 0.5 m horizontal one; the smaller of two
// points' gaps decides; a wrong count or a gap <= 0 is an error.
TEST(Geometry, EuclideanClustersWithPerPointGaps) {
  PointCloud c;
  for (const float z : {0.f, 0.6f, 1.2f})
    for (const float y : {0.f, 0.3f, 1.5f, 1.8f}) c.push_back(0.f, y, z, 0.f);  // two 0.3 m columns, 1.2 m apart
  const std::vector<Eigen::Vector2f> same(c.size(), Eigen::Vector2f(0.7f, 0.7f));
  EXPECT_EQ(geometry::EuclideanClusterMembers(c, same), geometry::EuclideanClusterMembers(c, 0.7));
  const std::vector<Eigen::Vector2f> rows(c.size(), Eigen::Vector2f(0.5f, 1.0f));
  const auto joined = geometry::EuclideanClusterMembers(c, rows);
  ASSERT_EQ(joined.size(), 2u);  // each column's three rows, the columns apart
  EXPECT_EQ(joined[0], (std::vector<std::uint32_t>{0, 1, 4, 5, 8, 9}));
  EXPECT_EQ(geometry::EuclideanClusterMembers(c, 0.5).size(), 6u);  // the rows apart
  std::vector<Eigen::Vector2f> one_small = rows;
  one_small[4] = one_small[5] = Eigen::Vector2f(0.5f, 0.5f);  // the first column's middle row: 0.5 m gaps
  const auto split = geometry::EuclideanClusterMembers(c, one_small);
  EXPECT_EQ(split.size(), 4u);  // that column's rows apart, the other column whole
  EXPECT_THROW(geometry::EuclideanClusterMembers(c, std::vector<Eigen::Vector2f>(3, Eigen::Vector2f(1, 1))), Error);
  std::vector<Eigen::Vector2f> zero = rows;
  zero[0].y() = 0.f;
  EXPECT_THROW(geometry::EuclideanClusterMembers(c, zero), Error);
}

// The lowest point per xy cell: a cell's own lowest z, a box's lowest over the cells it overlaps.
TEST(Geometry, LowestGridIsTheGroundUnderABox) {
  PointCloud c;
  c.push_back(0.5f, 0.5f, 2.f);
  c.push_back(0.6f, 0.4f, -1.f);  // same cell (0, 0)
  c.push_back(1.5f, 0.5f, 0.5f);  // cell (1, 0)
  c.push_back(-0.5f, -0.5f, -3.f);  // cell (-1, -1)
  geometry::LowestGrid g(1.0);
  EXPECT_TRUE(g.empty());
  g.Add(c);
  float z = 0.f;
  ASSERT_TRUE(g.At({0.1f, 0.9f, 5.f}, &z));
  EXPECT_EQ(z, -1.f);
  EXPECT_FALSE(g.At({5.f, 5.f, 0.f}, &z));
  EXPECT_EQ(g.Under({1.2f, 0.2f, 0.f}, {1.8f, 0.8f, 0.f}), 0.5f);
  EXPECT_EQ(g.Under({0.2f, 0.2f, 0.f}, {1.8f, 0.8f, 0.f}), -1.f);
  EXPECT_EQ(g.Under({0.2f, 0.2f, 0.f}, {0.8f, 0.8f, 0.f}, 1), -3.f);  // grown by one cell
  EXPECT_TRUE(std::isinf(g.Under({10.f, 10.f, 0.f}, {11.f, 11.f, 0.f})));
  // Watching one box: only its cells are lowered, with the same answer there.
  geometry::LowestGrid watched(1.0);
  watched.Watch({0.2f, 0.2f, 0.f}, {1.8f, 0.8f, 0.f});
  watched.AddWatched(c);
  EXPECT_EQ(watched.Under({0.2f, 0.2f, 0.f}, {1.8f, 0.8f, 0.f}), -1.f);
  EXPECT_FALSE(watched.At({-0.5f, -0.5f, 0.f}, &z));  // cell (-1, -1): not watched
  watched.Watch({5.f, 5.f, 0.f}, {5.f, 5.f, 0.f});
  EXPECT_FALSE(watched.At({5.f, 5.f, 0.f}, &z));      // watched, no point in it
  geometry::LowestGrid off(0.0);
  off.Add(c);
  EXPECT_TRUE(off.empty());
}

// WithinRadius against brute force: a few query points among many cloud points (the cells near
// the query are marked first) and as many query points as cloud points (no marking), on one and
// on three threads.
TEST(RadiusIndex, WithinRadiusEqualsBruteForceOnAnyThreads) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-5.f, 5.f);
  auto random_cloud = [&](std::size_t n) {
    PointCloud c;
    for (std::size_t i = 0; i < n; ++i) c.push_back(u(rng), u(rng), u(rng) * 0.2f);
    return c;
  };
  const PointCloud cloud = random_cloud(20000);
  for (std::size_t nq : {std::size_t(12), std::size_t(20000)}) {
    const PointCloud query = random_cloud(nq);
    const double r = 0.15;
    const std::vector<bool> got = WithinRadius(cloud, query, r);
    ASSERT_EQ(WithinRadius(cloud, query, r, 3), got);
    std::size_t hits = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      bool near = false;
      for (const auto& q : query.points) near |= (q.xyz() - cloud.points[i].xyz()).squaredNorm() <= float(r * r);
      ASSERT_EQ(got[i], near) << "point " << i << " with " << nq << " query points";
      hits += near;
    }
    EXPECT_GT(hits, 0u);
  }
}

}  // namespace
}  // namespace ltm::geometry
