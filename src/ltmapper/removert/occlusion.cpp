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

Neighbourhood FitNeighbourhood(const geometry::KdTree& tree, const PointCloud& cloud, const Eigen::Vector3f& p,
                               float radius) {
  Neighbourhood nb;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
  const float r2 = radius * radius;
  for (const auto& [j, d2] : tree.Knn(p, kNeighbourhoodPoints)) {
    if (d2 > r2) continue;
    const Eigen::Vector3d q = (cloud.points[j].xyz() - p).cast<double>();
    sum += q;
    second += q * q.transpose();
    ++nb.n;
  }
  if (nb.n == 0) return nb;
  nb.mean = sum / nb.n;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(second / nb.n - nb.mean * nb.mean.transpose());
  nb.eigenvalues = es.eigenvalues();
  nb.eigenvectors = es.eigenvectors();
  return nb;
}

std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads, std::vector<bool>* planar) {
  std::vector<Eigen::Vector3f> normals(points.size(), Eigen::Vector3f::UnitZ());
  std::vector<std::uint8_t> plane(points.size(), 0);
  if (points.empty() || map.empty()) return normals;
  const geometry::KdTree tree(std::make_shared<const PointCloud>(map), threads);
  const std::size_t chunk = 2048;
  ParallelFor((points.size() + chunk - 1) / chunk, threads, [&](std::size_t ch) {
    const std::size_t b = ch * chunk, e = std::min(points.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      const Neighbourhood nb = FitNeighbourhood(tree, map, points.points[i].xyz(), float(radius_m));
      if (nb.n < 2) continue;
      const Eigen::Vector3d& ev = nb.eigenvalues;  // ascending
      Eigen::Vector3d nrm;
      // Planar when the two largest spreads are comparable; else a line: the direction
      // perpendicular to it closest to vertical.
      if (nb.n >= 3 && ev(1) > 0.05 * ev(2)) {
        nrm = nb.eigenvectors.col(0);
        plane[i] = 1;
      } else {
        const Eigen::Vector3d line = nb.eigenvectors.col(2);
        nrm = Eigen::Vector3d::UnitZ() - line.z() * line;
        if (nrm.norm() < 1e-6) nrm = nb.eigenvectors.col(0);
      }
      normals[i] = nrm.normalized().cast<float>();
    }
  });
  if (planar) planar->assign(plane.begin(), plane.end());
  return normals;
}

Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads, bool own_pixel, const std::vector<bool>* standing) {
  Visibility out;
  out.seen.assign(points.size(), false);
  out.observed.assign(points.size(), false);
  out.same.assign(points.size(), false);
  if (own_pixel) out.seen_own.assign(points.size(), false);
  if (points.empty() || keyframes.empty()) return out;
  RemovertConfig vcfg = cfg;
  vcfg.submap_radius_m = cfg.ld_submap_radius_m;
  vcfg.window_px = cfg.ld_window_px;
  vcfg.pose_sigma_deg = 0.0;  // LD's own windows (ld.window_px); HD's pose widening is not applied here
  VisibilityOptions opt;
  opt.count_occluded = true;
  opt.within_beams = false;
  opt.count_own_see = own_pixel;
  std::vector<Eigen::Vector3f> normals;
  std::vector<bool> planar;  // normals[i] is a plane's (else a scan line's: orientation unknown)
  const bool beams = cfg.ld_same_min_hits > 0 && cfg.ld_same_test == "beams";
  if (cfg.ld_same_min_hits > 0 && (beams || cfg.ld_surface_max_m > 0.0)) {
    normals = EstimateNormals(points, own_map, cfg.ld_normal_radius_m, threads, &planar);
    opt.normals = &normals;
    if (beams)
      opt.beams = &cfg.ld_beam;
    else
      opt.surface_max_m = cfg.ld_surface_max_m;
  }
  const VisibilityVotes v = CountVisibility(points, keyframes, cfg.ld_resolutions_deg, vcfg, threads, opt);
  for (std::size_t i = 0; i < points.size(); ++i) {
    bool seen = false, observed = false, seen_own = false;
    int see_max = 0;
    int hits = beams ? int(v.beam_hits[i]) : 0;  // same-surface evidence: beam test, else pixel hits
    for (int l = 0; l < v.levels; ++l) {
      const double s = v.See(l, i), h = v.Hit(l, i);
      seen = seen || (s >= cfg.ld_min_votes && s >= cfg.ld_min_ratio * (s + h));
      see_max = std::max(see_max, int(s));
      if (own_pixel) {
        const double o = v.SeeOwn(l, i);
        seen_own = seen_own || (o >= cfg.ld_min_votes && o >= cfg.ld_min_ratio * (o + h));
      }
      observed = observed || s + h + v.Occ(l, i) > 0;
      if (!beams) hits = std::max(hits, int(h));
    }
    out.seen[i] = seen;
    // A beam going on past a surface more horizontal than vertical (ground, a roof) passed it at
    // a grazing angle, no sign its place was free: the own pixel decides only on upright planes
    // and on scan lines (a sparse sensor's rows on an upright side, orientation unknown).
    // Nor is it where the beams around the point met its own surface farther away (BeamTest's
    // "around": a surface the other session sampled only sparsely, which its own-pixel beam
    // went on past).
    if (own_pixel) {
      const bool upright = planar.empty() || !planar[i] || std::abs(normals[i].z()) < kUprightNormalZ;
      const bool around = beams && v.beam_around[i] > 0;
      // A beam that passed it and met nothing (the sky beyond a tall thing) saw its place free;
      // not at the edge of a surface the beams around it met (a facade's top against the sky).
      const bool passed = beams && upright && !around && v.beam_passed[i] >= cfg.ld_min_votes;
      out.seen_own[i] = seen || (seen_own && upright && !around) || passed;
      observed = observed || passed;
    }
    out.observed[i] = observed;
    // A beam that ended on level ground (or a roof) near the point is its surface, even where the
    // pixels say seen through: their rays passed over it at a grazing angle and met the same
    // surface farther along. Not under a lower body standing on the other session's ground.
    const bool level = beams && planar[i] && std::abs(normals[i].z()) >= kUprightNormalZ &&
                       !(standing && (*standing)[i]);
    out.same[i] = (!seen || (level && hits >= see_max)) && cfg.ld_same_min_hits > 0 && hits >= cfg.ld_same_min_hits;
  }
  return out;
}

}  // namespace ltm::removert::detail
