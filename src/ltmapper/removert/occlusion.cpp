// Occlusion-aware split of LD changes (paper: "Weak ND Preservation", "Strong PD").
//
// The paper's modified Removert: instead of removing map points that a scan sees through, it
// keeps (reverts to the static map) the raw ND points that the other session could not see
// through. Here one rule serves both directions: a point is "seen through" by a set of keyframes
// when, at any of the LD resolutions, at least ld_min_votes keyframes see through it and those
// are at least ld_min_ratio of the keyframes with evidence about it. Out of range, out of the
// FOV, occluded (scan range shorter) and no-return pixels give no see-through vote.
//   ND seen through by the query  -> strong ND (removed);  else weak ND (kept).
//   PD seen through by the central -> weak PD (was free);  else strong PD.
// With ld.covisible_only, a raw change the other session never had in view at all (no return
// in the window at its pixel from any keyframe in range: out of range, out of FOV) is
// "unobserved": a coverage difference, not a change. Unobserved ND stays static; unobserved PD
// is new territory (written apart, and added to the keyframe clouds as strong PD).
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <memory>

namespace ltm::removert::detail {

std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads) {
  std::vector<Eigen::Vector3f> normals(points.size(), Eigen::Vector3f::UnitZ());
  if (points.empty() || map.empty()) return normals;
  const geometry::KdTree tree(std::make_shared<const PointCloud>(map));
  const float r2 = float(radius_m * radius_m);
  constexpr std::size_t kMaxNeighbours = 16;
  const std::size_t chunk = 2048;
  ParallelFor((points.size() + chunk - 1) / chunk, threads, [&](std::size_t ch) {
    const std::size_t b = ch * chunk, e = std::min(points.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      const auto nn = tree.Knn(points.points[i].xyz(), kMaxNeighbours);
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      int n = 0;
      for (const auto& [j, d2] : nn)
        if (d2 <= r2) mean += map.points[j].xyz().cast<double>(), ++n;
      if (n < 2) continue;
      mean /= n;
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (const auto& [j, d2] : nn)
        if (d2 <= r2) {
          const Eigen::Vector3d q = map.points[j].xyz().cast<double>() - mean;
          cov += q * q.transpose();
        }
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
      const Eigen::Vector3d ev = es.eigenvalues();  // ascending
      Eigen::Vector3d nrm;
      // Planar when the two largest spreads are comparable; else a line: the direction
      // perpendicular to it closest to vertical.
      if (n >= 3 && ev(1) > 0.05 * ev(2)) {
        nrm = es.eigenvectors().col(0);
      } else {
        const Eigen::Vector3d line = es.eigenvectors().col(2);
        nrm = Eigen::Vector3d::UnitZ() - line.z() * line;
        if (nrm.norm() < 1e-6) nrm = es.eigenvectors().col(0);
      }
      normals[i] = nrm.normalized().cast<float>();
    }
  });
  return normals;
}

Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads) {
  Visibility out;
  out.seen.assign(points.size(), false);
  out.observed.assign(points.size(), false);
  out.same.assign(points.size(), false);
  if (points.empty() || keyframes.empty()) return out;
  RemovertConfig vcfg = cfg;
  vcfg.submap_radius_m = cfg.ld_submap_radius_m;
  vcfg.window_px = cfg.ld_window_px;
  VisibilityOptions opt;
  opt.count_occluded = true;
  std::vector<Eigen::Vector3f> normals;
  const bool beams = cfg.ld_same_min_hits > 0 && cfg.ld_same_test == "beams";
  if (cfg.ld_same_min_hits > 0 && (beams || cfg.ld_surface_max_m > 0.0)) {
    normals = EstimateNormals(points, own_map, cfg.ld_normal_radius_m, threads);
    opt.normals = &normals;
    if (beams)
      opt.beams = &cfg.ld_beam;
    else
      opt.surface_max_m = cfg.ld_surface_max_m;
  }
  const VisibilityVotes v = CountVisibility(points, keyframes, cfg.ld_resolutions_deg, vcfg, threads, opt);
  for (std::size_t i = 0; i < points.size(); ++i) {
    bool seen = false, observed = false;
    int hits = beams ? int(v.beam_hits[i]) : 0;  // same-surface evidence: beam test, else pixel hits
    for (int l = 0; l < v.levels; ++l) {
      const double s = v.See(l, i), h = v.Hit(l, i);
      seen = seen || (s >= cfg.ld_min_votes && s >= cfg.ld_min_ratio * (s + h));
      observed = observed || s + h + v.occ[std::size_t(l) * v.points + i] > 0;
      if (!beams) hits = std::max(hits, int(h));
    }
    out.seen[i] = seen;
    out.observed[i] = observed;
    out.same[i] = !seen && cfg.ld_same_min_hits > 0 && hits >= cfg.ld_same_min_hits;
  }
  return out;
}

}  // namespace ltm::removert::detail
