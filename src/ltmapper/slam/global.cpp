// Global registration, the fallback for a session Scan Context could not align: FPFH features
// (Rusu et al. 2009) of an aligned session's whole map and of query submaps, matched by PCL's
// SampleConsensusPrerejective (RANSAC over feature correspondences, rejecting samples whose edge
// lengths disagree before scoring them). Its placements are only loop candidates: they go
// through the same GICP verification and anchor consensus as Scan Context's.
//
// Every scale follows from the coarse registration voxel v (registration.coarse_voxel_m): the
// clouds are voxelised at v, normals use neighbours within kNormalRadiusVoxels v and features
// within kFeatureRadiusVoxels v (a feature sees a few metres of structure: a facade corner, a
// pole with the ground), and a placement's inliers lie within kInlierVoxels v.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/internal.hpp"

#include <pcl/features/normal_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/sample_consensus_prerejective.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace ltm::slam {

namespace {
constexpr double kNormalRadiusVoxels = 2.0;
constexpr double kFeatureRadiusVoxels = 5.0;
constexpr double kInlierVoxels = 1.5;
// RANSAC: samples of three correspondences, each drawn among a point's few most similar features;
// a sample survives only when its edge lengths agree within the similarity ratio.
constexpr int kRansacIterations = 20000;
constexpr int kSampleSize = 3;
constexpr int kCorrespondenceRandomness = 5;
constexpr float kEdgeSimilarity = 0.9f;
// Fixed seed: PCL's RANSAC draws from std::rand, so placements repeat run to run.
constexpr unsigned kRansacSeed = 1;

using Cloud = pcl::PointCloud<pcl::PointXYZ>;
using Features = pcl::PointCloud<pcl::FPFHSignature33>;

Cloud::Ptr ToPcl(const PointCloud& c) {
  auto out = pcl::make_shared<Cloud>();
  out->reserve(c.size());
  for (const auto& p : c.points) out->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  out->width = std::uint32_t(out->size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

// The three angles of an oriented pair in its Darboux frame (f1 the normals' angle about w, in
// [-pi, pi]; f2 = v . n_t and f3 = u . d / |d|, in [-1, 1]). The source is the point whose normal
// makes the smaller angle with the line joining them, so the pair gives the same angles in either
// order. False for coincident points or a normal along the line.
bool PairAngles(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2,
                const Eigen::Vector3f& n2, Eigen::Vector3f* f) {
  Eigen::Vector3f d = p2 - p1;
  const float dist = d.norm();
  if (dist == 0.f) return false;
  const float c1 = n1.dot(d) / dist, c2 = n2.dot(d) / dist;
  const bool swap = std::acos(std::fabs(c1)) > std::acos(std::fabs(c2));
  const Eigen::Vector3f& u = swap ? n2 : n1;
  const Eigen::Vector3f& nt = swap ? n1 : n2;
  if (swap) d = -d;
  Eigen::Vector3f v = d.cross(u);
  const float vn = v.norm();
  if (vn == 0.f) return false;
  v /= vn;
  const Eigen::Vector3f w = u.cross(v);
  (*f)[0] = std::atan2(w.dot(nt), u.dot(nt));
  (*f)[1] = v.dot(nt);
  (*f)[2] = swap ? -c2 : c1;
  return true;
}

constexpr int kFpfhBins = 11;  // per angle, as in the FPFH paper

int Bin(float x, float lo, float hi) {
  return std::clamp(int(std::floor(kFpfhBins * (x - lo) / (hi - lo))), 0, kFpfhBins - 1);
}

// One point's SPFH: its pairs with its neighbours (itself among them), each 100 / (neighbours - 1).
// A pair with a missing normal (a point with too few neighbours for a plane) counts in the lowest
// bin of each angle it has no value for, as PCL's FPFHEstimation counts it (its NaN angles): the
// descriptors, and so the placements the RANSAC finds, stay those of PCL's.
Fpfh Spfh(const PointCloud& cloud, const std::vector<Eigen::Vector3f>& normals, std::size_t i,
          const std::vector<std::pair<std::uint32_t, float>>& nn) {
  Fpfh h{};
  if (nn.size() < 2) return h;
  const float step = 100.f / float(nn.size() - 1);
  constexpr float kPi = float(M_PI);
  for (const auto& [j, d2] : nn) {
    if (j == i) continue;
    const Eigen::Vector3f& pi = cloud.points[i].xyz();
    const Eigen::Vector3f& pj = cloud.points[j].xyz();
    Eigen::Vector3f f;
    if (!normals[i].allFinite() || !normals[j].allFinite()) {
      if (pi == pj) continue;  // coincident points make no pair
      const float c = normals[i].allFinite() ? normals[i].dot(pj - pi) / (pj - pi).norm() : -1.f;
      f = Eigen::Vector3f(-kPi, -1.f, c);  // only the angle of i's own normal is known
    } else if (!PairAngles(pi, normals[i], pj, normals[j], &f)) {
      continue;
    }
    h[std::size_t(Bin(f[0], -kPi, kPi))] += step;
    h[std::size_t(kFpfhBins + Bin(f[1], -1.f, 1.f))] += step;
    h[std::size_t(2 * kFpfhBins + Bin(f[2], -1.f, 1.f))] += step;
  }
  return h;
}
}  // namespace

std::vector<Fpfh> FpfhDescriptors(const PointCloud& cloud, const std::vector<Eigen::Vector3f>& normals,
                                  double radius_m) {
  const geometry::KdTree tree(cloud);
  std::vector<std::vector<std::pair<std::uint32_t, float>>> nn(cloud.size());
  std::vector<Fpfh> spfh(cloud.size()), out(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    nn[i] = tree.Radius(cloud.points[i].xyz(), float(radius_m));
    spfh[i] = Spfh(cloud, normals, i, nn[i]);
  }
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    Fpfh& h = out[i];
    for (const auto& [j, d2] : nn[i]) {
      if (d2 == 0.f) continue;
      for (std::size_t b = 0; b < h.size(); ++b) h[b] += spfh[j][b] / d2;
    }
    for (int part = 0; part < 3; ++part) {
      float sum = 0.f;
      for (int b = 0; b < kFpfhBins; ++b) sum += h[std::size_t(part * kFpfhBins + b)];
      if (sum != 0.f)
        for (int b = 0; b < kFpfhBins; ++b) h[std::size_t(part * kFpfhBins + b)] *= 100.f / sum;
    }
  }
  return out;
}

namespace {
// A voxelised cloud as PCL's RANSAC takes it, with its FPFH features (PCL's normals, ours FPFH).
struct Described {
  Cloud::Ptr cloud;
  Features::Ptr features;
};

Described Describe(const PointCloud& points, double voxel_m) {
  Described d{ToPcl(points), pcl::make_shared<Features>()};
  auto tree = pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>();
  pcl::PointCloud<pcl::Normal> normals;
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(d.cloud);
  ne.setSearchMethod(tree);
  ne.setRadiusSearch(kNormalRadiusVoxels * voxel_m);
  ne.setViewPoint(0.f, 0.f, 1e4f);  // normals point up (ground) or outwards consistently
  ne.compute(normals);
  std::vector<Eigen::Vector3f> n(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) n[i] = normals[i].getNormalVector3fMap();
  for (const Fpfh& h : FpfhDescriptors(points, n, kFeatureRadiusVoxels * voxel_m)) {
    pcl::FPFHSignature33 f;
    std::copy(h.begin(), h.end(), f.histogram);
    d.features->push_back(f);
  }
  return d;
}
}  // namespace

struct GlobalMap::Impl {
  double voxel_m = 1.0, min_inlier_fraction = 0.3;
  Cloud::Ptr cloud;
  Features::Ptr features;
};

GlobalMap::GlobalMap(const PointCloud& world_map, const SlamConfig& cfg) : impl_(std::make_unique<Impl>()) {
  impl_->voxel_m = cfg.reg_coarse_voxel_m;
  impl_->min_inlier_fraction = cfg.reg_min_overlap;
  Described d = Describe(geometry::VoxelDownsample(world_map, impl_->voxel_m, 1), impl_->voxel_m);
  impl_->cloud = std::move(d.cloud);
  impl_->features = std::move(d.features);
}
GlobalMap::~GlobalMap() = default;

std::size_t GlobalMap::size() const { return impl_->cloud->size(); }

std::optional<Pose> GlobalMap::Place(const PointCloud& submap) const {
  const Impl& m = *impl_;
  const PointCloud points = geometry::VoxelDownsample(submap, m.voxel_m, 1);
  if (points.size() < std::size_t(kSampleSize) || m.cloud->size() < std::size_t(kSampleSize)) return std::nullopt;
  const Described src = Describe(points, m.voxel_m);
  pcl::SampleConsensusPrerejective<pcl::PointXYZ, pcl::PointXYZ, pcl::FPFHSignature33> ransac;
  ransac.setInputSource(src.cloud);
  ransac.setSourceFeatures(src.features);
  ransac.setInputTarget(m.cloud);
  ransac.setTargetFeatures(m.features);
  ransac.setMaximumIterations(kRansacIterations);
  ransac.setNumberOfSamples(kSampleSize);
  ransac.setCorrespondenceRandomness(kCorrespondenceRandomness);
  ransac.setSimilarityThreshold(kEdgeSimilarity);
  ransac.setMaxCorrespondenceDistance(kInlierVoxels * m.voxel_m);
  ransac.setInlierFraction(float(m.min_inlier_fraction));
  std::srand(kRansacSeed);
  Cloud aligned;
  ransac.align(aligned);
  if (!ransac.hasConverged()) return std::nullopt;
  const Eigen::Matrix4d M = ransac.getFinalTransformation().cast<double>();
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(Eigen::Matrix3d(M.block<3, 3>(0, 0))).normalized().toRotationMatrix();
  T.translation() = M.block<3, 1>(0, 3);
  return T;
}

}  // namespace ltm::slam
