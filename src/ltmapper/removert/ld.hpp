// ltmapper removert: LD change detection between the HD-free central and query maps.
#pragma once

#include "ltmapper/removert/keyframes.hpp"

#include <vector>

namespace ltm::removert {

struct LdStats {
  std::size_t central_points = 0, query_points = 0;
  std::size_t nd_strong = 0, nd_weak = 0, pd_strong = 0, pd_weak = 0;
  std::size_t pd_unobserved = 0, nd_unobserved = 0;
  std::size_t pd_same = 0, nd_same = 0;  // raw changes the other session observed as the same surface
  std::size_t nd_residue = 0, pd_residue = 0;  // seen-through changes that are residues of movers (HD)
  double seconds = 0;
};
struct LdResult {
  PointCloud nd_strong, nd_weak;  // central map points, world frame
  PointCloud pd_strong, pd_weak;  // query map points, world frame
  PointCloud pd_unobserved;       // query points the central never had in view (new territory)
  PointCloud nd_unobserved;       // central points the query never had in view (kept, no change)
  // Multi-session cleanup (ld.residue_*): residues of moving objects that the other session saw
  // through, taken out of nd_strong (central points) and pd_weak (query points).
  PointCloud nd_residue, pd_residue;
  std::vector<bool> central_nd;   // per central map point: it is in nd_strong, nd_weak or nd_residue
  LdStats stats;
};
// LD changes between the HD-free central and query maps (world frame). The keyframes (scans +
// world poses) decide occlusion: ND seen through by a query scan is strong (else weak), PD seen
// through by a central scan is weak (else strong); small clusters of strong ND / weak PD are
// residues of moving objects (nd_residue, pd_residue).
LdResult DetectLd(const PointCloud& central_map, const PointCloud& query_map,
                  const std::vector<WorldKeyframe>& central_keyframes,
                  const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg,
                  int threads = 0);

}  // namespace ltm::removert
