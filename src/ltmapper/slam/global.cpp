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

#include <pcl/features/fpfh.h>
#include <pcl/features/normal_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/sample_consensus_prerejective.h>
#include <pcl/search/kdtree.h>

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

Features::Ptr Describe(const Cloud::Ptr& cloud, double voxel_m) {
  auto tree = pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>();
  auto normals = pcl::make_shared<pcl::PointCloud<pcl::Normal>>();
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(cloud);
  ne.setSearchMethod(tree);
  ne.setRadiusSearch(kNormalRadiusVoxels * voxel_m);
  ne.setViewPoint(0.f, 0.f, 1e4f);  // normals point up (ground) or outwards consistently
  ne.compute(*normals);
  auto features = pcl::make_shared<Features>();
  pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fe;
  fe.setInputCloud(cloud);
  fe.setInputNormals(normals);
  fe.setSearchMethod(tree);
  fe.setRadiusSearch(kFeatureRadiusVoxels * voxel_m);
  fe.compute(*features);
  return features;
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
  impl_->cloud = ToPcl(geometry::VoxelDownsample(world_map, impl_->voxel_m, 1));
  impl_->features = Describe(impl_->cloud, impl_->voxel_m);
}
GlobalMap::~GlobalMap() = default;

std::size_t GlobalMap::size() const { return impl_->cloud->size(); }

std::optional<Pose> GlobalMap::Place(const PointCloud& submap) const {
  const Impl& m = *impl_;
  const Cloud::Ptr src = ToPcl(geometry::VoxelDownsample(submap, m.voxel_m, 1));
  if (src->size() < std::size_t(kSampleSize) || m.cloud->size() < std::size_t(kSampleSize)) return std::nullopt;
  pcl::SampleConsensusPrerejective<pcl::PointXYZ, pcl::PointXYZ, pcl::FPFHSignature33> ransac;
  ransac.setInputSource(src);
  ransac.setSourceFeatures(Describe(src, m.voxel_m));
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
