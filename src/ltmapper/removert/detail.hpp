// Private helpers of the removert module (not installed, not included outside this folder).
#pragma once

#include "ltmapper/removert/removert.hpp"

#include "ltmapper/removert/images.hpp"
#include "ltmapper/removert/tile_index.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <unordered_map>
#include <vector>

namespace ltm::removert::detail {

// The keyframe's scan (memory or file).
std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf);
// The keyframes' sensor positions (world frame), one point per keyframe, in keyframe order.
PointCloud Positions(const std::vector<WorldKeyframe>& keyframes);

// parallel_for over [0, n) inside a task_arena of `threads` (0 = default), grain 1.
using ltm::ParallelFor;  // core.hpp

// Per point: keyframes see through it at any LD resolution (seen), and whether any keyframe had
// a return in the window at its pixel at all (observed) (occlusion.cpp).
// same: not seen through, and at least ld_same_min_hits keyframes hit it on its surface plane
// (the other session has this surface; its map is only sparser there). `own_map` (the map the
// points come from) gives their normals.
struct Visibility {
  std::vector<bool> seen, observed, same;
};
Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads);

// The at most kNeighbourhoodPoints nearest points of `cloud` within `radius` of p: how many, their
// mean offset from p, and the eigen decomposition (ascending) of their covariance.
constexpr std::size_t kNeighbourhoodPoints = 16;
struct Neighbourhood {
  int n = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();
  Eigen::Matrix3d eigenvectors = Eigen::Matrix3d::Identity();
};
Neighbourhood FitNeighbourhood(const geometry::KdTree& tree, const PointCloud& cloud, const Eigen::Vector3f& p,
                               float radius);

// Unit normals of `points` from their neighbourhood in `map` (at most 16 nearest within
// radius_m): the PCA normal of a planar neighbourhood; for a line-like one (a far ground ring,
// a pole) the direction perpendicular to the line closest to vertical; +z with < 2 neighbours.
std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads);

// Points of `cloud` (world frame) moved into a keyframe's frame: p_local = T^-1 p.
PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor);

}  // namespace ltm::removert::detail
