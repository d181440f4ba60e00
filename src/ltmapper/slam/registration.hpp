// ltmapper slam: Scan Context descriptors and GICP registration between keyframe submaps.
#pragma once

#include "ltmapper/slam/config.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace ltm::slam {

struct ScanContext {
  Eigen::MatrixXf desc;        // rings x sectors; 0 = empty bin
  Eigen::VectorXf ring_key;    // row means (rotation invariant), retrieval key
  Eigen::VectorXf sector_key;  // column means, for the coarse shift
};
// Descriptor of a scan in its sensor frame. Sector s covers azimuth [s, s+1) * 2pi/sectors
// counter-clockwise from +x; ring r covers xy range [r, r+1) * max_range/rings.
ScanContext MakeScanContext(const PointCloud& scan, const SlamConfig& cfg);
// From a rings x sectors matrix (e.g. an SCDs/*.scd file).
ScanContext ScanContextFromMatrix(const Eigen::MatrixXd& desc);
struct ScMatch {
  double distance = 1.0;  // 1 - mean cosine of the columns non-empty in both, at the best shift
  int shift = 0;          // columns: b's column c matches a's column c + shift
  double yaw_rad = 0.0;   // rotation of the yaw part of T_a_b (p_a = Rz(yaw) p_b)
};
ScMatch CompareScanContexts(const ScanContext& a, const ScanContext& b, const SlamConfig& cfg);

// ------------------------------------------------------------------------------ registration
struct RegistrationResult {
  Pose T_target_source = Pose::Identity();
  double fitness = 1e9;   // mean squared NN distance [m^2] of the inliers (= inlier_rms^2)
  double overlap = 0.0;   // inlier ratio: source points with a target NN within the inlier radius
  double inlier_rms_m = 1e9;  // RMS NN distance of the inliers
  double inlier_radius_m = 0;   // the derived inlier gate (InlierRadius)
  double plane_z = 1e9;         // inliers' mean squared residual along the target normals / explained variance
  double plane_tail = 1.0;      // share of those residuals beyond 3 sigma ...
  double plane_tail_bound = 0;  // ... and what a Gaussian allows for that many inliers
  // Fisher information of the pose from the inliers' residuals along the target normals (each over
  // its explained variance): sum J^T J / var over k (the plane neighbours: neighbouring residuals
  // share their normals), in the pose graph's order (x y z rx ry rz, source frame). Small along
  // directions the surfaces do not constrain (a straight street's axis).
  Eigen::Matrix<double, 6, 6> fisher = Eigen::Matrix<double, 6, 6>::Zero();
  bool converged = false;
  bool accepted = false;  // converged, inlier ratio / plane residuals / correction within the gates
  std::string reason;     // why not accepted
};
// GICP of `source` onto `target` (both already downsampled to reg_voxel_m), from
// `T_target_source_init`: a coarse stage on reg_coarse_voxel_m clouds with a wide correspondence
// distance (the initial translation may be metres off), then the fine stage. Accepted when the
// inlier ratio (radius InlierRadius) >= reg_min_overlap, the inliers' residuals along the target's
// surface normals average no more than the surfaces' spread and the range noise explain, and no
// more of them lie beyond 3 sigma than a Gaussian allows (registration.cpp).
// The inlier radius: half a voxel diagonal plus 3 sigma of both clouds' range noise.
double InlierRadius(double voxel_m, double range_noise_m);
RegistrationResult RegisterGicp(const PointCloud& target, const PointCloud& source,
                                const Pose& T_target_source_init, const SlamConfig& cfg);

}  // namespace ltm::slam
