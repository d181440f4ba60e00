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
    nb.reach = std::max(nb.reach, std::sqrt(double(d2)));
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
                                             double radius_m, int threads, std::vector<bool>* planar,
                                             std::vector<bool>* rim) {
  if (points.empty() || map.empty()) {
    if (planar) planar->assign(points.size(), false);
    if (rim) rim->assign(points.size(), false);
    return std::vector<Eigen::Vector3f>(points.size(), Eigen::Vector3f::UnitZ());
  }
  const geometry::KdTree tree(std::make_shared<const PointCloud>(map), threads);
  return EstimateNormals(points, tree, map, radius_m, threads, planar, rim);
}

std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const geometry::KdTree& tree,
                                             const PointCloud& map, double radius_m, int threads,
                                             std::vector<bool>* planar, std::vector<bool>* rim) {
  std::vector<Eigen::Vector3f> normals(points.size(), Eigen::Vector3f::UnitZ());
  std::vector<std::uint8_t> plane(points.size(), 0), edge(points.size(), 0);
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
        const Eigen::Vector3d along = nb.mean - nb.mean.dot(nrm) * nrm;
        edge[i] = along.norm() > kRimOffset * nb.reach;
      } else {
        const Eigen::Vector3d line = nb.eigenvectors.col(2);
        nrm = Eigen::Vector3d::UnitZ() - line.z() * line;
        if (nrm.norm() < 1e-6) nrm = nb.eigenvectors.col(0);
      }
      normals[i] = nrm.normalized().cast<float>();
    }
  });
  if (planar) planar->assign(plane.begin(), plane.end());
  if (rim) rim->assign(edge.begin(), edge.end());
  return normals;
}

HitSurfaces::HitSurfaces(const PointCloud& map, const PointCloud& points, const BeamTest& test, int threads)
    : tol_(float(test.tol_m)) {
  // One kd-tree for the lookups and the normals' neighbourhoods: a map point within tol of a
  // return the test reads lies within ReachM - tol of a point asked, its neighbours within ReachM.
  PointCloud near = map.select(geometry::WithinRadius(map, points, ReachM(test), threads));
  if (near.empty()) return;
  tree_ = std::make_unique<geometry::KdTree>(std::move(near), threads);
  std::vector<bool> planar;
  normals_ = EstimateNormals(tree_->cloud(), *tree_, tree_->cloud(), test.tol_m, threads, &planar);
  for (std::size_t i = 0; i < normals_.size(); ++i)
    if (!planar[i]) normals_[i] = Eigen::Vector3f::Zero();
}

HitSurfaces::~HitSurfaces() = default;

bool HitSurfaces::Cosine(const Eigen::Vector3f& at, const Eigen::Vector3f& dir, float* cosine) const {
  std::uint32_t i = 0;
  float d2 = 0.f;
  if (!tree_ || !tree_->Nearest(at, &i, &d2) || d2 > tol_ * tol_ || normals_[i].isZero()) return false;
  *cosine = std::fabs(normals_[i].dot(dir));
  return true;
}

namespace {

// The beam tests' keyframes vote, as each looks once: `votes` keyframes' evidence for a see-through
// wins where it reaches ld.min_votes and outnumbers the `against` keyframes' evidence of the
// surface (PD: beams that passed the point without a return against beams around it that met its
// surface; ND: beams that went through its place against beams that ended near it).
bool Outvotes(int votes, int against, const RemovertConfig& cfg) { return votes >= cfg.ld_min_votes && votes > against; }

// Per point where `want` holds: its own map drew its surface twice. The other session's map holds
// at least ld.min_neighbors points on the point's normal line (within ld.beam_tol_m of it) within
// ld.radius_max_m in front of or behind it (the most LD accepts between two samplings of one
// surface), on a surface parallel to the point's (their normal within 45 deg of its), and its own
// map holds them too (a point within ld.beam_tol_m of each): both sessions met that surface, and
// this point is its own map's displaced copy of it (a pass of its session misaligned). A thing
// that left in front of a wall is not: its own session did not see the wall behind it. Upright
// points only: under a level one (a car's hood or roof) the ground both maps hold is what the
// thing stood on (Missing's kRawAboveTheirGround), not a copy of it.
std::vector<bool> DrawnTwice(const PointCloud& points, const std::vector<Eigen::Vector3f>& normals,
                             const std::vector<bool>& want, const PointCloud& own, const PointCloud& other,
                             const RemovertConfig& cfg, int threads) {
  std::vector<bool> out(points.size(), false);
  if (other.empty() || std::find(want.begin(), want.end(), true) == want.end()) return out;
  const float reach = float(cfg.ld_radius_max_m), tol = float(cfg.ld_beam.tol_m);
  const float line = std::hypot(reach, tol), normal_r = float(cfg.ld_normal_radius_m);
  // Only the maps' points these tests can reach (the maps are far larger than the points asked).
  const PointCloud asked = points.select(want);
  const PointCloud other_near = other.select(geometry::WithinRadius(other, asked, line + normal_r, threads));
  const PointCloud own_near = own.select(geometry::WithinRadius(own, asked, line + tol, threads));
  if (other_near.empty()) return out;
  const geometry::KdTree other_tree(std::make_shared<const PointCloud>(other_near), threads);
  const geometry::KdTree own_tree(std::make_shared<const PointCloud>(own_near), threads);
  const std::size_t k = std::size_t(cfg.ld_min_neighbors);
  std::vector<std::uint8_t> twice(points.size(), 0);
  const std::size_t chunk = 2048;
  ParallelFor((points.size() + chunk - 1) / chunk, threads, [&](std::size_t ch) {
    const std::size_t b = ch * chunk, e = std::min(points.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      if (!want[i] || std::abs(normals[i].z()) >= kUprightNormalZ) continue;
      const Eigen::Vector3f p = points.points[i].xyz();
      std::size_t n = 0;
      for (const auto& [j, d2] : other_tree.RadiusUnsorted(p, line)) {
        const Eigen::Vector3f q = other_near.points[j].xyz(), d = q - p;
        const float along = d.dot(normals[i]);
        if (std::abs(along) > reach || d2 - along * along > tol * tol) continue;
        if (own_tree.CountWithin(q, tol, 1) == 0) continue;
        const Neighbourhood nb = FitNeighbourhood(other_tree, other_near, q, normal_r);
        const bool parallel = nb.n >= 3 && std::abs(nb.eigenvectors.col(0).cast<float>().dot(normals[i])) >= kParallelCos;
        if (parallel && ++n >= k) break;
      }
      twice[i] = n >= k;
    }
  });
  out.assign(twice.begin(), twice.end());
  return out;
}

// How far a point's surface goes on along one direction of its plane: the farthest of the
// offsets (along it, ascending) reached from the point without a gap wider than `gap`.
float Reach(std::vector<float>& along, float gap) {
  std::sort(along.begin(), along.end());
  float reached = 0.f;
  for (const float a : along) {
    if (a - reached > gap) break;
    reached = std::max(reached, a);
  }
  return reached;
}

// Per point where `want` holds and that lies on an upright plane (normal within 45 deg of level):
// how far its own map's surface goes on around it (SurfaceExtent), up to kSurfaceExtentTols x `tol`:
// own-map points within tol of the plane and within tol of the line through the point up (or
// across), with no gap wider than kSurfaceGapTols x tol (rows of a surface scanned from afar), on the
// map thinned to voxels of kSurfaceVoxelTols x tol. All
// zero elsewhere (not asked). A beam that passed within tol of the point and crossed the plane
// inside that extent went through the surface (the beam truth's "observed absent"); one that
// crossed it beyond (a canopy's top, a fence seen edge-on) passed beside it (ColumnImage::PassedInside).
std::vector<SurfaceExtent> SurfaceExtents(const PointCloud& points, const PointCloud& map,
                                          const std::vector<Eigen::Vector3f>& normals, const std::vector<bool>& want,
                                          double tol_m, int threads) {
  std::vector<SurfaceExtent> out(points.size());
  if (map.empty() || std::find(want.begin(), want.end(), true) == want.end()) return out;
  const float tol = float(tol_m), reach = float(kSurfaceExtentTols) * tol, gap = float(kSurfaceGapTols) * tol;
  // The map near the points asked, thinned (kSurfaceVoxelTols).
  const PointCloud near = geometry::VoxelDownsample(
      map.select(geometry::WithinRadius(map, points.select(want), reach, threads)), kSurfaceVoxelTols * tol_m, threads);
  const geometry::KdTree tree(near);
  const std::size_t chunk = 256;
  ParallelFor((points.size() + chunk - 1) / chunk, threads, [&](std::size_t ch) {
    const std::size_t b = ch * chunk, e = std::min(points.size(), b + chunk);
    std::vector<float> way[4];  // up, down, left, right
    for (std::size_t i = b; i < e; ++i) {
      const Eigen::Vector3f& n = normals[i];
      if (!want[i] || std::abs(n.z()) >= kUprightNormalZ) continue;
      const Eigen::Vector3f up = n.cross(Eigen::Vector3f::UnitZ().cross(n)).normalized(), side = up.cross(n);
      const Eigen::Vector3f p = points.points[i].xyz();
      for (auto& w : way) w.clear();
      for (const auto& [j, d2] : tree.RadiusUnsorted(p, reach)) {
        const Eigen::Vector3f d = near.points[j].xyz() - p;
        if (std::abs(d.dot(n)) > tol) continue;
        const float u = d.dot(up), v = d.dot(side);
        if (std::abs(v) <= tol) way[u >= 0.f ? 0 : 1].push_back(std::abs(u));
        if (std::abs(u) <= tol) way[v >= 0.f ? 2 : 3].push_back(std::abs(v));
      }
      SurfaceExtent& x = out[i];
      x.up = up;
      x.above = Reach(way[0], gap), x.below = Reach(way[1], gap), x.left = Reach(way[2], gap), x.right = Reach(way[3], gap);
    }
  });
  return out;
}

// Per point not in a plane (`planar` false: a scan line of its map), whether its own map holds a
// point lower than it by more than ld.beam_tol_m in its xy cell (ld.normal_radius_m wide): the line
// stands over a surface (a fence's row over the ground), not on it. A far ground row is the lowest
// its cell holds: a beam that passed it without a return grazed the ground, whose far returns the
// sensor drops, no sign its place was free.
std::vector<bool> OverOwnSurface(const PointCloud& points, const PointCloud& own_map, const std::vector<bool>& planar,
                                 const RemovertConfig& cfg) {
  std::vector<bool> out(points.size(), false);
  geometry::LowestGrid lowest(cfg.ld_normal_radius_m);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!planar[i]) lowest.Watch(points.points[i].xyz(), points.points[i].xyz());
  lowest.AddWatched(own_map);
  float z = 0.f;
  for (std::size_t i = 0; i < points.size(); ++i)
    out[i] = !planar[i] && lowest.At(points.points[i].xyz(), &z) && z < points.points[i].z - float(cfg.ld_beam.tol_m);
  return out;
}

// The surfaces of the points asked and the vote options they enable: normals from the own map
// (planar, rim), the beam test or surface hits, and for ND the points whose place a beam may have
// gone through. `opt` points into this struct: it is filled in place and never copied or moved.
struct SurfaceSetup {
  SurfaceSetup() = default;
  SurfaceSetup(const SurfaceSetup&) = delete;
  SurfaceSetup& operator=(const SurfaceSetup&) = delete;
  bool beams = false;  // ld.same_test beams
  std::vector<Eigen::Vector3f> normals;
  std::vector<bool> planar;      // normals[i] is a plane's (else a scan line's: orientation unknown)
  std::vector<bool> rim;         // points[i] lies at the rim of its plane (EstimateNormals)
  std::vector<bool> through_at;  // ND: points inside a plane, whose place a beam may have gone through
  std::vector<bool> line_at;     // ND: points on a scan line (no plane), which a beam may have passed
  std::vector<SurfaceExtent> extents;  // ND: how far the upright surface around a point goes on, for
                                       // a beam that passed it without a return
  std::unique_ptr<HitSurfaces> hits;   // beams: the other session's surfaces where its beams ended
  VisibilityOptions opt;
};

void SetUpSurfaces(const PointCloud& points, const PointCloud& own_map, const PointCloud* other_map,
                   const RemovertConfig& cfg, int threads, bool own_pixel, SurfaceSetup* s) {
  s->opt.count_occluded = true;
  s->opt.within_beams = false;
  s->opt.count_own_see = own_pixel;
  s->beams = cfg.ld_same_min_hits > 0 && cfg.ld_same_test == "beams";
  if (cfg.ld_same_min_hits <= 0 || !(s->beams || cfg.ld_surface_max_m > 0.0)) return;
  s->normals = EstimateNormals(points, own_map, cfg.ld_normal_radius_m, threads, &s->planar, &s->rim);
  s->opt.normals = &s->normals;
  if (s->beams) s->opt.beams = &cfg.ld_beam;
  if (s->beams && other_map != nullptr) {
    s->hits = std::make_unique<HitSurfaces>(*other_map, points, cfg.ld_beam, threads);
    s->opt.hit_surfaces = s->hits.get();
  }
  // ND: a beam may have gone through the place of a point inside a plane (planar, not at its rim):
  // a ray that crossed the plane within a voxel of a line's or an edge's point may have passed
  // beside the surface.
  if (s->beams && !own_pixel) {
    s->through_at.resize(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) s->through_at[i] = s->planar[i] && !s->rim[i];
    s->opt.through_at = &s->through_at;
    s->extents = SurfaceExtents(points, own_map, s->normals, s->through_at, cfg.ld_beam.tol_m, threads);
    s->opt.passed_at = &s->extents;
    s->line_at = OverOwnSurface(points, own_map, s->planar, cfg);
    s->opt.line_at = &s->line_at;
  }
  if (!s->beams) s->opt.surface_max_m = cfg.ld_surface_max_m;
}

// Point i's labels from its votes: seen (through), seen_own (PD: the own pixel's votes were
// counted, VisibilityOptions::count_own_see), observed, same.
void JudgePoint(std::size_t i, const VisibilityVotes& v, bool seen, const SurfaceSetup& s, const RemovertConfig& cfg,
                const std::vector<bool>* standing, Visibility* out) {
  const bool own_pixel = s.opt.count_own_see;
  bool observed = false, seen_own = false;
  int see_max = 0;
  int hits = s.beams ? int(v.beam_hits[i]) : 0;  // same-surface evidence: beam test, else pixel hits
  for (int l = 0; l < v.levels; ++l) {
    const double see = v.See(l, i), h = v.Hit(l, i);
    see_max = std::max(see_max, int(see));
    if (own_pixel) {
      const double o = v.SeeOwn(l, i);
      seen_own = seen_own || (o >= cfg.ld_min_votes && o >= cfg.ld_min_ratio * (o + h));
    }
    observed = observed || see + h + v.Occ(l, i) > 0;
    if (!s.beams) hits = std::max(hits, int(h));
  }
  out->seen[i] = seen;
  // A beam going on past a surface more horizontal than vertical (ground, a roof) passed it at
  // a grazing angle, no sign its place was free: the own pixel decides only on upright planes
  // and on scan lines (a sparse sensor's rows on an upright side, orientation unknown).
  // Nor is it where the beams around the point met its own surface farther away (BeamTest's
  // "around": a surface the other session sampled only sparsely, which its own-pixel beam
  // went on past).
  if (own_pixel) {
    const bool upright = s.planar.empty() || !s.planar[i] || std::abs(s.normals[i].z()) < kUprightNormalZ;
    const bool around = s.beams && v.beam_around[i] > 0;
    // A beam that passed it and met nothing (the sky beyond a tall thing, ground beyond the
    // sensor's range) saw its place free; not at the edge of a surface the beams around it met (a
    // facade's top against the sky), by the keyframes' vote (Outvotes). Far out, a beam below a
    // point may land on ground that happens to lie on the point's plane: Pandar64 (seed 7, true
    // poses) passed a structure 71 m out with 22 keyframes and met "around" it with 1 to 3, which
    // made its lower half strong PD while one "around" vetoed all passes (weak PD recall 0.88).
    const bool passed = s.beams && upright && Outvotes(v.beam_passed[i], v.beam_around[i], cfg);
    out->seen_own[i] = seen || (seen_own && upright && !around) || passed;
    observed = observed || passed;
  }
  out->observed[i] = observed;
  // A beam that ended on level ground (or a roof) near the point is its surface, even where the
  // pixels say seen through: their rays passed over it at a grazing angle and met the same
  // surface farther along. Not for a lower body standing on the other session's ground: the
  // other session's surface near it is that ground, below it by more than the two samplings of
  // one surface can be apart (AboveTheirGround), so its beams that ended within ld.beam_tol_m
  // of it met the ground, not its surface.
  const bool on_their_ground = standing && (*standing)[i];
  const bool level = s.beams && s.planar[i] && std::abs(s.normals[i].z()) >= kUprightNormalZ;
  out->same[i] = !on_their_ground && (!seen || (level && hits >= see_max)) && cfg.ld_same_min_hits > 0 &&
                 hits >= cfg.ld_same_min_hits;
}

}  // namespace

// Per point: seen through by the pixels (at some resolution, ld.min_votes keyframes and
// ld.min_ratio of those with evidence), or by beams of the other session that went through the
// point's place and ended beyond it, at more keyframes than had a beam end near the point
// (Outvotes): the beam truth's "observed absent" (a see-through the pixels miss where the other
// sensor looks down at a grazing angle: the ground in front of a thing that left counts as a hit in
// its pixel window; asked only where SeenThroughBy's `through_at` holds).
std::vector<bool> SeenThroughVotes(const VisibilityVotes& v, const RemovertConfig& cfg) {
  std::vector<bool> seen(v.points, false);
  for (std::size_t i = 0; i < v.points; ++i) {
    for (int l = 0; l < v.levels && !seen[i]; ++l) {
      const double s = v.See(l, i), h = v.Hit(l, i);
      seen[i] = s >= cfg.ld_min_votes && s >= cfg.ld_min_ratio * (s + h);
    }
    seen[i] = seen[i] || (!v.beam_through.empty() && Outvotes(v.beam_through[i], v.beam_hits[i], cfg));
  }
  return seen;
}

Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads, bool own_pixel, const std::vector<bool>* standing, const PointCloud* other_map) {
  Visibility out;
  out.seen.assign(points.size(), false);
  out.observed.assign(points.size(), false);
  out.same.assign(points.size(), false);
  if (own_pixel) out.seen_own.assign(points.size(), false);
  if (points.empty() || keyframes.empty()) return out;
  RemovertConfig vcfg = cfg;
  vcfg.submap_radius_m = cfg.max_range_m;
  vcfg.window_px = cfg.ld_window_px;
  vcfg.pose_sigma_deg = 0.0;  // LD's own windows (ld.window_px); HD's pose widening is not applied here
  SurfaceSetup surfaces;
  SetUpSurfaces(points, own_map, other_map, cfg, threads, own_pixel, &surfaces);
  const VisibilityVotes v = CountVisibility(points, keyframes, cfg.ld_resolutions_deg, vcfg, threads, surfaces.opt);
  std::vector<bool> seen_through = SeenThroughVotes(v, cfg);
  // Not where its own map drew the surface twice (DrawnTwice): those rays went past a displaced
  // copy to the surface both sessions met.
  if (other_map != nullptr && !own_pixel && !surfaces.normals.empty()) {
    const std::vector<bool> displaced =
        DrawnTwice(points, surfaces.normals, seen_through, own_map, *other_map, cfg, threads);
    for (std::size_t i = 0; i < points.size(); ++i) seen_through[i] = seen_through[i] && !displaced[i];
  }
  for (std::size_t i = 0; i < points.size(); ++i)
    JudgePoint(i, v, seen_through[i], surfaces, cfg, standing, &out);
  return out;
}

}  // namespace ltm::removert::detail
