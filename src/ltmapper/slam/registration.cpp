// Loop verification by registration: PCL Generalized-ICP (Segal et al. 2009) between two
// downsampled clouds, scored by a fitness (mean squared nearest-neighbour distance of the
// overlapping source points) and an overlap ratio.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/slam.hpp"

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>

#include <cmath>
#include <sstream>

namespace ltm::slam {

namespace {
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

RegistrationResult RegisterGicp(const PointCloud& target, const PointCloud& source,
                                const Pose& T_target_source_init, const SlamConfig& cfg) {
  RegistrationResult r;
  const std::size_t min_points = static_cast<std::size_t>(cfg.reg_covariance_neighbours) + 1;
  if (target.size() < min_points || source.size() < min_points) {
    r.reason = "too few points for registration (" + std::to_string(target.size()) + " / " +
               std::to_string(source.size()) + ")";
    return r;
  }
  auto tgt = ToPcl(target);
  auto src = ToPcl(source);
  Eigen::Matrix4f guess = T_target_source_init.matrix().cast<float>();
  const auto run = [&](const pcl::PointCloud<pcl::PointXYZ>::Ptr& t,
                       const pcl::PointCloud<pcl::PointXYZ>::Ptr& s, double max_corr) {
    pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
    gicp.setInputTarget(t);
    gicp.setInputSource(s);
    gicp.setMaxCorrespondenceDistance(max_corr);
    gicp.setMaximumIterations(cfg.reg_max_iterations);
    gicp.setCorrespondenceRandomness(cfg.reg_covariance_neighbours);
    gicp.setTransformationEpsilon(1e-8);
    gicp.setRotationEpsilon(1e-8);
    gicp.setEuclideanFitnessEpsilon(1e-8);
    gicp.setRANSACIterations(0);
    gicp.setMaximumOptimizerIterations(cfg.reg_max_iterations);
    pcl::PointCloud<pcl::PointXYZ> aligned;
    gicp.align(aligned, guess);
    guess = gicp.getFinalTransformation();
    return gicp.hasConverged();
  };
  if (cfg.reg_coarse_correspondence_m > 0.0) {
    const PointCloud tc = geometry::VoxelDownsample(target, cfg.reg_coarse_voxel_m, 1);
    const PointCloud sc = geometry::VoxelDownsample(source, cfg.reg_coarse_voxel_m, 1);
    if (tc.size() >= min_points && sc.size() >= min_points) {
      auto tcp = ToPcl(tc);
      run(tcp, ToPcl(sc), cfg.reg_coarse_correspondence_m);
      // Early rejection (saves the fine stage for wrong places): after the coarse stage a true
      // match overlaps well at the coarse resolution; require half the final overlap ratio.
      pcl::KdTreeFLANN<pcl::PointXYZ> coarse_tree;
      coarse_tree.setInputCloud(tcp);
      const double r2 = std::pow(std::max(cfg.reg_fitness_range_m, cfg.reg_coarse_voxel_m), 2);
      const Eigen::Matrix4f G = guess;
      std::vector<int> ci(1);
      std::vector<float> cd(1);
      std::size_t near = 0;
      for (const auto& p : sc.points) {
        const Eigen::Vector4f q = G * Eigen::Vector4f(p.x, p.y, p.z, 1.f);
        if (coarse_tree.nearestKSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), 1, ci, cd) > 0 &&
            cd[0] <= r2) {
          ++near;
        }
      }
      const double coarse_overlap = double(near) / double(sc.size());
      if (coarse_overlap < 0.5 * cfg.reg_min_overlap) {
        std::ostringstream why;
        why.precision(3);
        why << "coarse stage overlap " << coarse_overlap << " < " << 0.5 * cfg.reg_min_overlap;
        r.reason = why.str();
        r.overlap = coarse_overlap;
        return r;
      }
    }
  }
  r.converged = run(tgt, src, cfg.reg_max_correspondence_m);

  const Eigen::Matrix4d M = guess.cast<double>();
  r.T_target_source = Pose::Identity();
  r.T_target_source.linear() =
      Eigen::Quaterniond(Eigen::Matrix3d(M.block<3, 3>(0, 0))).normalized().toRotationMatrix();
  r.T_target_source.translation() = M.block<3, 1>(0, 3);

  // Fitness and overlap, in double precision with the final pose.
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(tgt);
  const double range_sq = cfg.reg_fitness_range_m * cfg.reg_fitness_range_m;
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  double sum = 0.0;
  std::size_t inside = 0;
  for (const auto& p : source.points) {
    const Eigen::Vector3d q = r.T_target_source * Eigen::Vector3d(p.x, p.y, p.z);
    if (tree.nearestKSearch(pcl::PointXYZ(float(q.x()), float(q.y()), float(q.z())), 1, idx, d2) <
        1) {
      continue;
    }
    if (d2[0] <= range_sq) {
      sum += d2[0];
      ++inside;
    }
  }
  r.overlap = double(inside) / double(source.size());
  r.fitness = inside > 0 ? sum / double(inside) : 1e9;

  const Pose delta = T_target_source_init.inverse() * r.T_target_source;
  const double corr_deg = Eigen::AngleAxisd(delta.linear()).angle() * 180.0 / M_PI;
  const double corr_m = delta.translation().norm();
  std::ostringstream why;
  why.precision(3);
  if (!r.converged) {
    why << "GICP did not converge";
  } else if (r.overlap < cfg.reg_min_overlap) {
    why << "overlap " << r.overlap << " < " << cfg.reg_min_overlap;
  } else if (r.fitness >= cfg.reg_fitness_threshold) {
    why << "fitness " << r.fitness << " >= " << cfg.reg_fitness_threshold;
  } else if (corr_deg > cfg.reg_max_correction_deg) {
    why << "rotation correction " << corr_deg << " deg > " << cfg.reg_max_correction_deg;
  } else if (corr_m > cfg.reg_max_translation_m) {
    why << "translation correction " << corr_m << " m > " << cfg.reg_max_translation_m;
  }
  r.reason = why.str();
  r.accepted = r.reason.empty();
  return r;
}

}  // namespace ltm::slam
