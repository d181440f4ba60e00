// Loop verification by registration: PCL Generalized-ICP (Segal et al. 2009) between two
// downsampled clouds, scored by the inlier ratio (source points with a target neighbour within
// an inlier radius) and the RMS distance of those inliers, both gates derived from the voxel
// size and the sensor's range noise (InlierRadius, InlierRmsBound).
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/registration.hpp"

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>

#include <cmath>
#include <sstream>

namespace ltm::slam {

namespace {
using PclCloud = pcl::PointCloud<pcl::PointXYZ>;
// Half the diagonal of a voxel: a point of a surface lies at most this far (in units of the
// voxel) from the centroid of its voxel, so a correctly placed source centroid finds a target
// centroid of the same surface within it.
const double kHalfVoxelDiagonal = std::sqrt(3.0) / 2.0;
// Gaussian gate on the range noise: 3 sigma keeps 99.7 % of correctly placed points.
constexpr double kNoiseSigmas = 3.0;
// Uniform offset within a voxel along each axis: variance v^2 / 12 per axis, three axes.
constexpr double kUniformVariance = 1.0 / 12.0;
constexpr double kAxes = 3.0;
// The coarse stage's early rejection asks for this fraction of reg_min_overlap: at the coarse
// voxel, before the fine stage, a true match overlaps at least half as well as at the end.
constexpr double kCoarseOverlapFraction = 0.5;
// GICP stops when an update is smaller than this (transformation / rotation / fitness change).
constexpr double kGicpEpsilon = 1e-8;

pcl::PointCloud<pcl::PointXYZ>::Ptr ToPcl(const PointCloud& cloud) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  out->reserve(cloud.size());
  for (const auto& p : cloud.points) out->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  out->width = static_cast<std::uint32_t>(out->size());
  out->height = 1;
  out->is_dense = true;
  return out;
}
}  // namespace

double InlierRadius(double voxel_m, double range_noise_m) {
  // Both clouds carry range noise: the difference of two samples has std-dev sqrt(2) sigma.
  return kHalfVoxelDiagonal * voxel_m + kNoiseSigmas * std::sqrt(2.0) * range_noise_m;
}

double InlierRmsBound(double voxel_m, double range_noise_m) {
  // A correctly placed source centroid lies, at worst, anywhere in the voxel of the target
  // centroid it matches: a uniform offset on each of the three axes (variance v^2 / 12 each, an
  // RMS of v / 2); the range noise of both clouds adds 2 sigma^2. (On a plane the offset has two
  // axes only, v / sqrt(6): true loops measure between the two.)
  return std::sqrt(kAxes * kUniformVariance * voxel_m * voxel_m +
                   2.0 * range_noise_m * range_noise_m);
}

namespace {
struct Inliers {
  double ratio = 0.0, rms = 1e9;
};

// Inlier ratio and RMS of `source` under T against a kd-tree of the target.
Inliers CountInliers(const pcl::KdTreeFLANN<pcl::PointXYZ>& tree, const PointCloud& source,
                     const Eigen::Matrix4d& T, double radius) {
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  double sum = 0.0;
  std::size_t inside = 0;
  for (const auto& p : source.points) {
    const Eigen::Vector4d q = T * Eigen::Vector4d(p.x, p.y, p.z, 1.0);
    if (tree.nearestKSearch(pcl::PointXYZ(float(q.x()), float(q.y()), float(q.z())), 1, idx, d2) <
            1 ||
        d2[0] > radius * radius) {
      continue;
    }
    sum += d2[0];
    ++inside;
  }
  Inliers in;
  if (source.empty()) return in;
  in.ratio = double(inside) / double(source.size());
  if (inside > 0) in.rms = std::sqrt(sum / double(inside));
  return in;
}

// One GICP run from `guess` (updated in place); returns whether it converged.
bool RunGicp(const PclCloud::Ptr& t, const PclCloud::Ptr& s, double max_corr,
             const SlamConfig& cfg, Eigen::Matrix4f& guess) {
  pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
  gicp.setInputTarget(t);
  gicp.setInputSource(s);
  gicp.setMaxCorrespondenceDistance(max_corr);
  gicp.setMaximumIterations(cfg.reg_max_iterations);
  gicp.setCorrespondenceRandomness(cfg.reg_covariance_neighbours);
  gicp.setTransformationEpsilon(kGicpEpsilon);
  gicp.setRotationEpsilon(kGicpEpsilon);
  gicp.setEuclideanFitnessEpsilon(kGicpEpsilon);
  gicp.setRANSACIterations(0);
  gicp.setMaximumOptimizerIterations(cfg.reg_max_iterations);
  pcl::PointCloud<pcl::PointXYZ> aligned;
  gicp.align(aligned, guess);
  guess = gicp.getFinalTransformation();
  return gicp.hasConverged();
}

// Coarse stage (the initial translation may be metres off); returns an empty string or why the
// candidate is rejected early (saves the fine stage for wrong places).
std::string CoarseStage(const PointCloud& target, const PointCloud& source, const SlamConfig& cfg,
                        Eigen::Matrix4f& guess, double* coarse_overlap) {
  const std::size_t min_points = static_cast<std::size_t>(cfg.reg_covariance_neighbours) + 1;
  const PointCloud tc = geometry::VoxelDownsample(target, cfg.reg_coarse_voxel_m, 1);
  const PointCloud sc = geometry::VoxelDownsample(source, cfg.reg_coarse_voxel_m, 1);
  if (tc.size() < min_points || sc.size() < min_points) return {};
  auto tcp = ToPcl(tc);
  RunGicp(tcp, ToPcl(sc), cfg.reg_coarse_correspondence_m, cfg, guess);
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(tcp);
  const double radius = InlierRadius(cfg.reg_coarse_voxel_m, cfg.reg_range_noise_m);
  *coarse_overlap = CountInliers(tree, sc, guess.cast<double>(), radius).ratio;
  const double need = kCoarseOverlapFraction * cfg.reg_min_overlap;
  if (*coarse_overlap >= need) return {};
  std::ostringstream why;
  why.precision(3);
  why << "coarse stage overlap " << *coarse_overlap << " < " << need;
  return why.str();
}

// Why a registered candidate is not accepted (empty when it is).
std::string Verdict(const RegistrationResult& r, const Pose& T_init, const SlamConfig& cfg) {
  const Pose delta = T_init.inverse() * r.T_target_source;
  const double corr_deg = Eigen::AngleAxisd(delta.linear()).angle() * 180.0 / M_PI;
  const double corr_m = delta.translation().norm();
  std::ostringstream why;
  why.precision(3);
  if (!r.converged) {
    why << "GICP did not converge";
  } else if (r.overlap < cfg.reg_min_overlap) {
    why << "inlier ratio " << r.overlap << " < " << cfg.reg_min_overlap << " (radius "
        << r.inlier_radius_m << " m)";
  } else if (r.inlier_rms_m > r.rms_bound_m) {
    why << "inlier RMS " << r.inlier_rms_m << " m > " << r.rms_bound_m << " m";
  } else if (corr_deg > cfg.reg_max_correction_deg) {
    why << "rotation correction " << corr_deg << " deg > " << cfg.reg_max_correction_deg;
  } else if (corr_m > cfg.reg_max_translation_m) {
    why << "translation correction " << corr_m << " m > " << cfg.reg_max_translation_m;
  }
  return why.str();
}
}  // namespace

RegistrationResult RegisterGicp(const PointCloud& target, const PointCloud& source,
                                const Pose& T_target_source_init, const SlamConfig& cfg) {
  RegistrationResult r;
  const std::size_t min_points = static_cast<std::size_t>(cfg.reg_covariance_neighbours) + 1;
  if (target.size() < min_points || source.size() < min_points) {
    r.reason = "too few points for registration (" + std::to_string(target.size()) + " / " +
               std::to_string(source.size()) + ")";
    return r;
  }
  Eigen::Matrix4f guess = T_target_source_init.matrix().cast<float>();
  if (cfg.reg_coarse_correspondence_m > 0.0) {
    r.reason = CoarseStage(target, source, cfg, guess, &r.overlap);
    if (!r.reason.empty()) return r;
  }
  auto tgt = ToPcl(target);
  r.converged = RunGicp(tgt, ToPcl(source), cfg.reg_max_correspondence_m, cfg, guess);

  const Eigen::Matrix4d M = guess.cast<double>();
  r.T_target_source = Pose::Identity();
  r.T_target_source.linear() =
      Eigen::Quaterniond(Eigen::Matrix3d(M.block<3, 3>(0, 0))).normalized().toRotationMatrix();
  r.T_target_source.translation() = M.block<3, 1>(0, 3);

  // Inlier ratio and RMS, in double precision with the final pose.
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(tgt);
  r.inlier_radius_m = InlierRadius(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  r.rms_bound_m = InlierRmsBound(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  const Inliers in = CountInliers(tree, source, r.T_target_source.matrix(), r.inlier_radius_m);
  r.overlap = in.ratio;
  r.inlier_rms_m = in.rms;
  r.fitness = in.ratio > 0.0 ? in.rms * in.rms : 1e9;
  r.reason = Verdict(r, T_target_source_init, cfg);
  r.accepted = r.reason.empty();
  return r;
}

}  // namespace ltm::slam
