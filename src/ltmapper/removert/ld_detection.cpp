// LD change detection between two HD-free maps (paper: "Low Dynamic (LD) Change Detection"):
// a point with fewer than k neighbours within r in the other session's map is a change; ND from
// the central map, PD from the query map. Occlusion then splits each into strong and weak
// (occlusion.cpp).
#include "ltmapper/removert/detail.hpp"
#include "ltmapper/removert/tiles.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <thread>
#include <tuple>
#include <utility>

namespace ltm::removert {

namespace {

// A neighbourhood is one plane when its thickness (std along its normal) is below this many map
// voxels: a surface sampled at the map voxel, with the sessions' range noise.
constexpr double kPlaneMaxThickness = 0.5;

// What Missing says of a point.
enum Raw : std::uint8_t { kRawNone = 0, kRawMissing = 1, kRawAboveTheirGround = 2 };

// How far the mean of a neighbourhood (offset from the point) lies from the point along the plane
// whose normal is `normal`.
double LateralOffset(const detail::Neighbourhood& nb, const Eigen::Vector3d& normal) {
  return (nb.mean - nb.mean.dot(normal) * normal).norm();
}

// The other session's neighbours of a point lie only beyond ld_radius_m, within r, all to one side
// of it along their surface (their mean off it by more than ld_rim_frac * r in their plane): the
// point lies past the rim of what that session sampled, not on a surface the poses shifted.
bool PastTheirRim(const detail::Neighbourhood& nb, float r, const RemovertConfig& cfg) {
  return nb.n < 3 || LateralOffset(nb, nb.eigenvectors.col(0)) > cfg.ld_rim_frac * r;
}

// The other session's neighbours of a point (none within a map voxel) are one plane of ground
// (thinner than kPlaneMaxThickness map voxels, normal more vertical than horizontal), around the
// point (not to one side as at a curb's edge, PastTheirRim's rule) and below it by more than a map
// voxel plus `shift` (what the sessions' rotation error can put between two samplings of one
// surface at the point's distance): two samplings of one surface lie within that of each other's
// plane, so the point is another surface standing on that ground (the lower body of a car that
// left or came).
bool AboveTheirGround(const detail::Neighbourhood& nb, float r, float shift, const RemovertConfig& cfg) {
  if (nb.n < 3) return false;
  const double voxel = cfg.map_voxel_m;
  const double thick = std::sqrt(std::max(nb.eigenvalues.x(), 0.0));
  const double spread = std::sqrt(std::max(nb.eigenvalues.y(), 0.0));
  if (thick > kPlaneMaxThickness * voxel || spread < voxel) return false;  // not one plane (a corner, a line)
  Eigen::Vector3d up = nb.eigenvectors.col(0);
  if (up.z() < 0.0) up = -up;
  if (up.z() < detail::kUprightNormalZ) return false;  // not ground
  if (LateralOffset(nb, up) > cfg.ld_rim_frac * r) return false;  // beside it, not under it
  return -up.dot(nb.mean) > voxel + double(shift);
}

// The plane AboveTheirGround found under p is the other session's ground there, not a ledge, a
// wall's top or a car's roof: the other map's lowest point around p (`lowest`: cells
// ld.radius_max_m wide, p's and the eight around it) lies within p's kd radius r plus a map voxel
// below p. A lower body stands on the ground; a point standing on a raised surface is as often a
// displaced copy of something on it (where the poses err more than LT-SLAM measured), and the kd
// radius decides it.
bool OnTheirGround(const geometry::LowestGrid& lowest, const Eigen::Vector3f& p, float r, float voxel) {
  constexpr int kAround = 1;
  return p.z() - lowest.Under(p, p, kAround) <= r + voxel;
}

// Per point: kRawMissing when points[i] has fewer than k neighbours within r_i in `other`, where
// r_i = ld_radius_m + LdRadiusRel() * (the larger distance from the point to the nearest keyframe
// of either session): a surface seen from afar carries the sessions' rotation error times that
// distance; or when it lies past the rim of the other's coverage (PastTheirRim, with ld.rim_frac);
// kRawAboveTheirGround when its neighbours there are the other session's ground under it
// (AboveTheirGround, OnTheirGround); with `beams_beyond_r0` (PD: points of the query), kRawMissing
// too when its neighbours lie only beyond ld_radius_m and what the rotation error adds to it
// (r_i - ld_radius_m) is within ld.beam_tol_m: there the beam test tells a copy of their surface the
// error moved (their beams ended on its plane within the tolerance) from a thing their beams went
// past; past that, the radius decides (a thing 0.3-0.5 m in front of a far surface the central
// sampled was no change: seed 53's tilted VLP-16 lost PD recall 40-60 m out). Not for ND: there it
// cost seed 31's tilted VLP-16 ND precision 0.925 -> 0.903, a crown the query saw only from 63-75 m
// with a rotation error LT-SLAM could not measure (docs/RESULTS.md). Else kRawNone. Either raw
// change goes on to the beam test, which decides.
std::vector<std::uint8_t> Missing(const PointCloud& points, const PointCloud& other, const PointCloud& own_kf,
                                  const PointCloud& other_kf, bool beams_beyond_r0, const RemovertConfig& cfg,
                                  int threads) {
  if (other.empty() || points.empty()) return std::vector<std::uint8_t>(points.size(), kRawMissing);
  const geometry::KdTree tree(other, threads);
  const bool rel = cfg.LdRadiusRel() > 0.0 && !own_kf.empty() && !other_kf.empty();
  std::unique_ptr<geometry::KdTree> own_tree, other_tree;
  if (rel) {
    own_tree = std::make_unique<geometry::KdTree>(own_kf);
    other_tree = std::make_unique<geometry::KdTree>(other_kf);
  }
  const std::size_t k = std::size_t(cfg.ld_min_neighbors);
  const float r0 = float(cfg.ld_radius_m), rr = float(cfg.LdRadiusRel());
  const float r_max = float(cfg.ld_radius_max_m), voxel = float(cfg.map_voxel_m), tol = float(cfg.ld_beam.tol_m);
  const bool rim = cfg.ld_rim_frac > 0.0;
  geometry::LowestGrid lowest(cfg.ld_radius_max_m);
  lowest.Add(other);
  std::vector<std::uint8_t> m(points.size(), kRawMissing);
  const std::size_t chunk = 4096;
  detail::ParallelFor((points.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
    const std::size_t b = c * chunk, e = std::min(points.size(), b + chunk);
    for (std::size_t i = b; i < e; ++i) {
      const Eigen::Vector3f p = points.points[i].xyz();
      float r = r0;
      if (rel) {
        std::uint32_t j;
        float d_own = 0.f, d_other = 0.f;
        own_tree->Nearest(p, &j, &d_own);
        other_tree->Nearest(p, &j, &d_other);
        r = std::min(r_max, r0 + rr * std::sqrt(std::max(d_own, d_other)));
      }
      m[i] = tree.CountWithin(p, r, k) < k ? kRawMissing : kRawNone;
      if (m[i]) continue;
      // Neighbours only beyond r0, or none within a map voxel: one fit of them for the rules.
      const bool beyond_r0 = (rim || beams_beyond_r0) && r > r0 && tree.CountWithin(p, r0, 1) == 0;
      const bool beyond_voxel = tree.CountWithin(p, voxel, 1) == 0;
      if (!beyond_r0 && !beyond_voxel) continue;
      const detail::Neighbourhood nb = detail::FitNeighbourhood(tree, other, p, r);
      if (beyond_r0 && rim && PastTheirRim(nb, r, cfg))
        m[i] = kRawMissing;
      else if (beyond_voxel && AboveTheirGround(nb, r, r - r0, cfg) && OnTheirGround(lowest, p, r, voxel))
        m[i] = kRawAboveTheirGround;
      else if (beams_beyond_r0 && beyond_r0 && r - r0 <= tol)
        m[i] = kRawMissing;
    }
  });
  return m;
}

// Raw changes split by what the other session saw (SeenThroughBy): the same surface (no change,
// counted in `same`), not covered (unobserved), else strong or weak. ND (nd = true) is strong
// when the query saw through it (or weak ND is off); PD is strong when the central did not.
struct Strength {
  std::vector<bool> strong, weak, unobserved;
  std::size_t same = 0;
};
Strength Split(const detail::Visibility& vis, bool nd, const RemovertConfig& cfg) {
  const std::size_t n = vis.seen.size();
  Strength s{std::vector<bool>(n), std::vector<bool>(n), std::vector<bool>(n), 0};
  for (std::size_t i = 0; i < n; ++i) {
    if (vis.same[i]) {
      ++s.same;
      continue;
    }
    const bool covered = !cfg.covisible_only || vis.observed[i];
    s.strong[i] = covered && (nd ? vis.seen[i] || !cfg.weak_nd : !vis.seen_own[i]);
    s.weak[i] = covered && !s.strong[i];
    s.unobserved[i] = !covered;
  }
  return s;
}

// The xy box of cluster m of `c`.
std::pair<Eigen::Vector3f, Eigen::Vector3f> BoxOf(const PointCloud& c, const std::vector<std::uint32_t>& m) {
  Eigen::Vector3f lo = c.points[m.front()].xyz(), hi = lo;
  for (auto i : m) lo = lo.cwiseMin(c.points[i].xyz()), hi = hi.cwiseMax(c.points[i].xyz());
  return {lo, hi};
}

// The ground of the residue rule: the lowest point of the session's own map in a cell of half a
// mover's length, read over the cell around a place (kGroundGrowCells on each side): what a thing's
// top is measured from (FitAMover) and what does not join things (OffTheGround).
constexpr int kGroundGrowCells = 1;
geometry::LowestGrid ResidueGround(const RemovertConfig& cfg) { return geometry::LowestGrid(0.5 * cfg.ld_residue_length_m); }

// The clusters of `c` that fit in a mover's size (Residues), marked point by point: first
// across (longest horizontal edge), then in height above the ground of `own` under them (the
// ground hashed only under the clusters that fit across).
std::vector<bool> FitAMover(const PointCloud& c, const std::vector<std::vector<std::uint32_t>>& members,
                            const PointCloud& own, const RemovertConfig& cfg) {
  struct Candidate {
    const std::vector<std::uint32_t>* members;
    Eigen::Vector3f lo, hi;
  };
  std::vector<Candidate> across;
  geometry::LowestGrid ground = ResidueGround(cfg);
  for (const auto& m : members)
    if (geometry::LongestHorizontalEdge(c, m) < cfg.ld_residue_length_m) {
      const auto [lo, hi] = BoxOf(c, m);
      across.push_back({&m, lo, hi});
      ground.Watch(lo, hi, kGroundGrowCells);
    }
  ground.AddWatched(own);
  std::vector<bool> fit(c.size(), false);
  for (const Candidate& k : across) {
    const double top = double(k.hi.z() - std::min(k.lo.z(), ground.Under(k.lo, k.hi, kGroundGrowCells)));
    if (top >= cfg.ld_radius_m && top < cfg.ld_residue_length_m)
      for (auto i : *k.members) fit[i] = true;
  }
  return fit;
}

// Unmarks the marked clusters with a point within `near_m` of an unmarked one (a piece of it).
void UnmarkPiecesOfLargerOnes(const PointCloud& c, const std::vector<std::vector<std::uint32_t>>& members,
                              double near_m, std::vector<bool>* marked) {
  std::vector<bool> large = *marked;
  large.flip();
  if (std::find(large.begin(), large.end(), true) == large.end()) return;
  const geometry::KdTree larger(c.select(large));
  for (const auto& m : members) {
    if (!(*marked)[m.front()]) continue;
    const bool beside = std::any_of(m.begin(), m.end(), [&](std::uint32_t i) {
      return larger.CountWithin(c.points[i].xyz(), float(near_m), 1) > 0;
    });
    if (beside)
      for (auto i : m) (*marked)[i] = false;
  }
}

// How near a return lies to a map point it is one of: a map voxel's diagonal (the map is the union
// of the returns, one point per voxel, so a voxel's point lies that close to every return it was
// made of).
float HitReach(const RemovertConfig& cfg) { return float(cfg.map_voxel_m * std::sqrt(3.0)); }

// How far `at` lies from the box [lo, hi] (0 inside it): a voter farther than its range from the
// box of the points asked has none of them within its reach.
float DistanceToBox(const Eigen::Vector3f& at, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  return (at.cwiseMax(lo).cwiseMin(hi) - at).norm();
}

// The voters LD picked for a session's own votes, with their settings (MarkSeenBriefly, BlockedByTheMap):
// as HD removal counts them (hd.window_px, pose_sigma_deg) at LD's resolutions, anywhere in the
// images' FOV (a keyframe that met a thing above its top beam met it too), nearer returns counted.
RemovertConfig OwnVoteConfig(const RemovertConfig& cfg) {
  RemovertConfig vcfg = cfg;
  vcfg.submap_radius_m = cfg.max_range_m;  // the voters LD picked (tiles: within this of the tile)
  return vcfg;
}
VisibilityOptions OwnVoteOptions() {
  VisibilityOptions opt;
  opt.within_beams = false;
  opt.count_occluded = true;
  return opt;
}

// Per level and point of `seen` among `asked` (VisibilityVotes::occ's layout, in `asked`'s order):
// how many of `own_voters` the session's map hid it from: the voter's image of its own returns
// that are points of `own` (within HitReach of one), less the things the points are parts of
// (`things`: a thing does not hide itself) has a nearer return in the point's window. Only the
// returns inside the box spanning the voter's place and the points (what lies between them) are
// asked; voters are taken a batch at a time (memory: one scan each).
std::vector<std::uint16_t> BlockedByTheMap(const PointCloud& seen, const std::vector<std::uint32_t>& asked,
                                           const PointCloud& things, const PointCloud& own,
                                           const std::vector<WorldKeyframe>& own_voters, const RemovertConfig& cfg,
                                           int threads) {
  const PointCloud pts = seen.select(asked);
  const int levels = int(cfg.ld_resolutions_deg.size());
  std::vector<std::uint16_t> blocked(std::size_t(levels) * pts.size(), 0);
  const float reach = HitReach(cfg), range = float(cfg.max_range_m);
  std::vector<bool> keep = geometry::WithinRadius(own, things, reach, threads);
  keep.flip();
  const geometry::KdTree map(own.select(keep));
  Eigen::Vector3f lo, hi;  // named (not a structured binding): the lambda below captures them
  std::tie(lo, hi) = BoxOf(seen, asked);
  const unsigned workers = threads > 0 ? unsigned(threads) : std::max(1u, std::thread::hardware_concurrency());
  const std::size_t batch = 2 * std::size_t(workers);
  for (std::size_t first = 0; first < own_voters.size(); first += batch) {
    const std::size_t n = std::min(own_voters.size() - first, batch);
    std::vector<WorldKeyframe> images(n);
    std::vector<bool> asked(n, false);
    detail::ParallelFor(n, threads, [&](std::size_t k) {
      const WorldKeyframe& voter = own_voters[first + k];
      const Eigen::Vector3f at = voter.T_world_sensor.translation().cast<float>();
      if (DistanceToBox(at, lo, hi) > range) return;
      const Eigen::Vector3f box_lo = lo.cwiseMin(at), box_hi = hi.cwiseMax(at);
      const std::shared_ptr<const PointCloud> scan = detail::LoadScan(voter);
      const Eigen::Affine3f to_world = voter.T_world_sensor.cast<float>();
      std::vector<bool> on_map(scan->size(), false);
      for (std::size_t i = 0; i < scan->size(); ++i) {
        const Eigen::Vector3f q = to_world * scan->points[i].xyz();
        on_map[i] = (q.array() >= box_lo.array()).all() && (q.array() <= box_hi.array()).all() &&
                    map.CountWithin(q, reach, 1) > 0;
      }
      images[k] = voter;
      images[k].cloud = std::make_shared<const PointCloud>(scan->select(on_map));
      images[k].sweep = SweepMotion();
      asked[k] = true;
    });
    std::vector<WorldKeyframe> in_reach;
    for (std::size_t k = 0; k < n; ++k)
      if (asked[k]) in_reach.push_back(std::move(images[k]));
    if (in_reach.empty()) continue;
    const VisibilityVotes v = CountVisibility(pts, in_reach, cfg.ld_resolutions_deg, OwnVoteConfig(cfg), threads, OwnVoteOptions());
    for (std::size_t j = 0; j < blocked.size(); ++j) blocked[j] = std::uint16_t(blocked[j] + v.occ[j]);
  }
  return blocked;
}

// The seen-through part of each thing of `whole` that has one (points below `n_seen`: the cluster
// cloud, Residues' `both`, holds the seen-through changes first), with the thing it is part of.
struct SeenParts {
  std::vector<std::vector<std::uint32_t>> parts;
  std::vector<const std::vector<std::uint32_t>*> whole;
};
SeenParts SeenPartsOf(const std::vector<std::vector<std::uint32_t>>& whole, std::size_t n_seen) {
  SeenParts out;
  for (const auto& m : whole) {
    std::vector<std::uint32_t> part;
    for (std::uint32_t i : m)
      if (i < n_seen) part.push_back(i);
    if (part.empty()) continue;
    out.parts.push_back(std::move(part));
    out.whole.push_back(&m);
  }
  return out;
}

// Whether most points of `m` at most `max_hits` voters hit (ld.residue_max_hits: one pass of a
// mover) while at least two, and more than hit them, had them in view (`views`): a keyframe that
// had a point in view and did not meet it there is what tells a mover from a thing every view met
// (a far car that a session of two keyframes saw twice stays a change).
bool MostlyHitBriefly(const std::vector<std::uint32_t>& m, const std::vector<int>& hits, const std::vector<int>& views,
                      int max_hits) {
  const auto n = std::count_if(m.begin(), m.end(), [&](std::uint32_t i) {
    return hits[i] <= max_hits && views[i] >= 2 && hits[i] < views[i];
  });
  return 2 * std::size_t(n) > m.size();
}

// A thing one pass of a mover could have left: standing still is more keyframes of its own session
// that met it at the same place (a hit: the pixel's return at the point's range) than a mover gives
// (ld.residue_max_hits). A cluster of `seen` most of whose points no more than that many of `own_voters`
// hit, while at least two and more than hit them had them in view (hit, seen through or met
// something nearer), is a residue of a mover whatever its size: a car driving ahead of the sensor
// when the session ended, or waiting beside it when the session began, is seen at its last (first)
// place by one keyframe only; the keyframes before (after) met it nearer, at its earlier (later)
// places, which they removed as HD; a car passing 37 m out is met at one place by two keyframes
// (seed 61's HDL-32E: a false disappeared object 17.5 m long). No keyframe of the session came back
// to see through its place, so its own HD removal could not (marked in *residue). A
// nearer return that is the session's map, `own` (a building, a fence in front), is no such place:
// a standing thing the map hides from all keyframes but one was seen once because it was hidden,
// not because it moved (BlockedByTheMap, asked for the clusters the plain count takes; seed 31's
// fence 9, 67 m out behind buildings from 59 of the 60 keyframes that had it in view, was
// residues on every sensor). A session of one scan has no second view and judges nothing. Only
// for ring sensors: a scanner without rings samples other places in each scan, so one hit there
// says nothing about motion. The votes are the session's own, counted as HD removal counts them
// (OwnVoteConfig), at LD's resolutions over LD's voters.
void MarkSeenBriefly(const PointCloud& seen, const PointCloud& both, const std::vector<std::vector<std::uint32_t>>& whole,
                  const PointCloud& own, const std::vector<WorldKeyframe>& own_voters, const RemovertConfig& cfg,
                  int threads, std::vector<bool>* residue) {
  if (own_voters.empty() || !cfg.SensorResolved() || !cfg.sensor_model.ring_based) return;
  const SeenParts things = SeenPartsOf(whole, seen.size());
  const VisibilityVotes v = CountVisibility(seen, own_voters, cfg.ld_resolutions_deg, OwnVoteConfig(cfg), threads, OwnVoteOptions());
  // A point's views: the most, over the levels, of the voters that hit it, saw through it or met
  // something nearer, less those whose nearer return was the map (`blocked` at the level, or 0).
  const auto views_of = [&](std::size_t i, const auto& blocked) {
    int most = 0;
    for (int l = 0; l < v.levels; ++l)
      most = std::max(most, int(v.See(l, i)) + int(v.Hit(l, i)) + std::max(0, int(v.Occ(l, i)) - blocked(l)));
    return most;
  };
  std::vector<int> hits(seen.size(), 0), views(seen.size(), 0);
  for (std::size_t i = 0; i < seen.size(); ++i) {
    for (int l = 0; l < v.levels; ++l) hits[i] = std::max(hits[i], int(v.Hit(l, i)));
    views[i] = views_of(i, [](int) { return 0; });
  }
  std::vector<std::size_t> candidates;
  for (std::size_t t = 0; t < things.parts.size(); ++t)
    if (MostlyHitBriefly(things.parts[t], hits, views, cfg.ld_residue_max_hits)) candidates.push_back(t);
  if (candidates.empty()) return;
  std::vector<std::uint32_t> asked, of_things;
  for (std::size_t t : candidates) {
    asked.insert(asked.end(), things.parts[t].begin(), things.parts[t].end());
    of_things.insert(of_things.end(), things.whole[t]->begin(), things.whole[t]->end());
  }
  const std::vector<std::uint16_t> blocked =
      BlockedByTheMap(seen, asked, both.select(of_things), own, own_voters, cfg, threads);
  for (std::size_t j = 0; j < asked.size(); ++j)
    views[asked[j]] = views_of(asked[j], [&](int l) { return int(blocked[std::size_t(l) * asked.size() + j]); });
  for (std::size_t t : candidates)
    if (MostlyHitBriefly(things.parts[t], hits, views, cfg.ld_residue_max_hits))
      for (auto i : things.parts[t]) (*residue)[i] = true;
}

// A trail needs two instants: a cluster that fewer keyframes of its session hit is not judged.
constexpr int kTrailMinKeyframes = 2;

// Per own keyframe, the points of `c` among `asked` that it returned on, in `asked`'s order: a return
// of its scan within HitReach of the point, counting, as the votes do, keyframes within
// sensor.max_range_m of the point.
std::vector<std::vector<std::uint32_t>> HitsPerKeyframe(const PointCloud& c, const std::vector<std::uint32_t>& asked,
                                                        const std::vector<WorldKeyframe>& own_voters,
                                                        const RemovertConfig& cfg, int threads) {
  std::vector<std::vector<std::uint32_t>> hits(own_voters.size());
  if (asked.empty()) return hits;
  const float reach = HitReach(cfg), submap = float(cfg.max_range_m);
  Eigen::Vector3f lo, hi;
  std::tie(lo, hi) = BoxOf(c, asked);
  lo.array() -= reach, hi.array() += reach;
  const geometry::KdTree tree(c.select(asked));
  detail::ParallelFor(own_voters.size(), threads, [&](std::size_t k) {
    const Eigen::Vector3f at = own_voters[k].T_world_sensor.translation().cast<float>();
    if (DistanceToBox(at, lo, hi) > submap) return;
    const PointCloud scan = geometry::Transform(*detail::LoadScan(own_voters[k]), own_voters[k].T_world_sensor);
    std::vector<bool> hit(asked.size(), false);
    for (const auto& q : scan.points) {
      const Eigen::Vector3f x = q.xyz();
      if ((x.array() < lo.array()).any() || (x.array() > hi.array()).any()) continue;
      for (const auto& [j, sq] : tree.RadiusUnsorted(x, reach)) hit[j] = true;
    }
    for (std::size_t j = 0; j < asked.size(); ++j)
      if (hit[j] && (tree.cloud().points[j].xyz() - at).norm() <= submap) hits[k].push_back(asked[j]);
  });
  return hits;
}

// The longest piece one keyframe saw of a cluster: its hits (`hit`, points of `c`) joined where
// closer than a mover's length, ld_residue_length_m (the returns on one mover lie that close to each
// other; a keyframe's hits farther apart are different things), the longest horizontal edge among
// the pieces. Not the gaps of the keyframe's samples: a far thing's changed part is a sparse subset
// of what the keyframe sampled on it (seed 7's car 4 and container 11, 70-100 m out, fell apart
// into pieces under 2 m and went as trails).
double LongestPieceSeen(const PointCloud& c, const std::vector<std::uint32_t>& hit, const RemovertConfig& cfg) {
  const PointCloud sub = c.select(hit);
  double longest = 0.0;
  for (const auto& m : geometry::EuclideanClusterMembers(sub, cfg.ld_residue_length_m))
    longest = std::max(longest, geometry::LongestHorizontalEdge(sub, m));
  return longest;
}

// Per point of `c` among `asked`: whether it is the bottom of its thing, within HitReach above the
// lowest of `asked` around it (cells of ResidueGround's size, kGroundGrowCells on each side). The
// returns from the ground a thing stands on lie that near its lowest points in every keyframe that
// sees the ground there, so they say nothing of where the thing was (LongestPieceSeen leaves them
// out): a walker's trail along a sidewalk was touched along its whole length by a few sidewalk
// returns of each keyframe (seed 83's Pandar64: 1-6 returns 0.17-0.21 m above the street level,
// against 63-215 on the walker, which each keyframe met within 0.08-0.64 m). Only for ring sensors,
// as MarkSeenBriefly: a scanner without rings samples a thing's upper parts in a pattern of its own
// per scan, in patches the bottom's samples joined (seed 7's rosette: ND recall over the objects'
// points 0.920 -> 0.903 with it).
std::vector<bool> BottomOf(const PointCloud& c, const std::vector<std::uint32_t>& asked, const RemovertConfig& cfg) {
  std::vector<bool> bottom(c.size(), false);
  if (!cfg.SensorResolved() || !cfg.sensor_model.ring_based) return bottom;
  geometry::LowestGrid lowest = ResidueGround(cfg);
  lowest.Add(c.select(asked));
  const float reach = HitReach(cfg);
  for (auto i : asked) {
    const Eigen::Vector3f p = c.points[i].xyz();
    bottom[i] = p.z() - lowest.Under(p, p, kGroundGrowCells) <= reach;
  }
  return bottom;
}

// How many keyframes before its last view a thing that drove with the sensor is tested over
// (DroveWithTheSensor): two instants, as a trail needs.
constexpr int kDroveKeyframesBefore = kTrailMinKeyframes;

// What one scan returned on a thing at one place (DroveWithTheSensor), counted two ways: the
// thing's points that a return lies within `reach` of, and the returns within reach of one of its
// points, each return once.
struct ReturnedOn {
  std::size_t points = 0, returns = 0;
  ReturnedOn& operator+=(const ReturnedOn& o) {
    points += o.points, returns += o.returns;
    return *this;
  }
};

// What a scan (world frame, its tree) returned on the points `pts` (world frame).
ReturnedOn ReturnsOn(const std::vector<Eigen::Vector3f>& pts, const geometry::KdTree& scan, float reach) {
  ReturnedOn n;
  std::vector<std::uint32_t> returns;
  for (const auto& p : pts) {
    const auto near = scan.RadiusUnsorted(p, reach);
    n.points += near.empty() ? 0 : 1;
    for (const auto& [i, sq] : near) returns.push_back(i);
  }
  std::sort(returns.begin(), returns.end());
  n.returns = std::size_t(std::unique(returns.begin(), returns.end()) - returns.begin());
  return n;
}

// Standard deviations by which one count of returns must exceed another to tell which place a
// thing was at (SignificantlyMore): the bound registration's gates use too (registration.cpp).
constexpr double kCountSigmas = 3.0;

// Whether `a` returns exceed `b` by more than chance: were each return as likely at either place,
// a - b would have mean 0 and standard deviation sqrt(a + b) (a sign test).
bool SignificantlyMore(std::size_t a, std::size_t b) {
  return double(a) - double(b) > kCountSigmas * std::sqrt(double(a + b));
}

// The clusters of `judged` that drove with the sensor (DroveWithTheSensor), each tested at the last
// of `own_voters` that hit it (`last`, -1: none) against the kDroveKeyframesBefore keyframes of the
// session just before it (by index), when LD picked them as voters too.
void MarkDroveWithTheSensor(const PointCloud& c, const std::vector<const std::vector<std::uint32_t>*>& judged,
                            const std::vector<int>& last, const std::vector<WorldKeyframe>& own_voters,
                            std::vector<bool>* residue, const RemovertConfig& cfg) {
  std::map<int, std::size_t> by_index;
  for (std::size_t v = 0; v < own_voters.size(); ++v) by_index[own_voters[v].index] = v;
  std::map<std::size_t, std::shared_ptr<const geometry::KdTree>> scans;  // voter -> its scan's tree
  const auto scan_of = [&](std::size_t v) {
    auto& t = scans[v];
    if (!t) t = std::make_shared<const geometry::KdTree>(geometry::Transform(*detail::LoadScan(own_voters[v]), own_voters[v].T_world_sensor));
    return t;
  };
  for (std::size_t t = 0; t < judged.size(); ++t) {
    if (last[t] < 0 || (*residue)[judged[t]->front()]) continue;
    const WorldKeyframe& k = own_voters[std::size_t(last[t])];
    std::vector<const WorldKeyframe*> before;
    std::vector<std::shared_ptr<const geometry::KdTree>> trees;
    for (int d = 1; d <= kDroveKeyframesBefore; ++d) {
      const auto it = by_index.find(k.index - d);
      if (it == by_index.end()) break;
      before.push_back(&own_voters[it->second]);
      trees.push_back(scan_of(it->second));
    }
    if (detail::DroveWithTheSensor(c, *judged[t], k, before, trees, cfg))
      for (auto i : *judged[t]) (*residue)[i] = true;
  }
}

}  // namespace

// A mover walking along its own session's line of sight leaves a trail in that session's map that
// its HD removal cannot take (the keyframes that met it later met it nearer, in front of its earlier
// places, so none saw through them) and that is longer than a mover (FitAMover does not take it).
// At one instant a mover is in one place: each keyframe that hit the trail hit a piece of it that
// fits in a mover's length, ld_residue_length_m, at another place along it. A thing standing there
// is seen along its visible length by the keyframes that see it whole. So a cluster of `c` (not yet
// marked) longer than a mover that at least kTrailMinKeyframes of `own_voters` hit, each in pieces
// shorter than a mover (LongestPieceSeen), is a mover's trail (marked in *residue, per point of
// `c`). A keyframe's returns from the ground a cluster stands on are no piece of it (BottomOf).
// The whole cluster decides, so a tile must hold it: clusters up to LdWholeClusterM long are
// judged (7.4 m with the Pandar64's gaps, printed on seed 61). The same clusters, with the
// keyframes' hits, are judged for having driven with the sensor (MarkDroveWithTheSensor).
void detail::MarkTrails(const PointCloud& c, const std::vector<std::vector<std::uint32_t>>& members,
                        const std::vector<WorldKeyframe>& own_voters, const RemovertConfig& cfg, int threads,
                        std::vector<bool>* residue) {
  const double longest = LdWholeClusterM(cfg);
  std::vector<const std::vector<std::uint32_t>*> judged;
  std::vector<std::uint32_t> asked;
  std::vector<std::uint32_t> cluster_of(c.size());  // index into `judged`, for the asked points
  for (const auto& m : members) {
    if ((*residue)[m.front()]) continue;
    const double length = geometry::LongestHorizontalEdge(c, m);
    if (length < cfg.ld_residue_length_m || length >= longest) continue;
    for (auto i : m) cluster_of[i] = std::uint32_t(judged.size());
    judged.push_back(&m);
    asked.insert(asked.end(), m.begin(), m.end());
  }
  if (judged.empty()) return;
  std::sort(asked.begin(), asked.end());  // each keyframe's hits, and so its pieces, in map order
  std::vector<int> seen_by(judged.size(), 0), last(judged.size(), -1);  // last: the latest voter that hit it
  std::vector<bool> whole(judged.size(), false);
  const auto hits = HitsPerKeyframe(c, asked, own_voters, cfg, threads);
  // A cluster most of whose points lie above its bottom is judged by the hits on those (a keyframe
  // that only touched its bottom met nothing of it); one that is mostly bottom, a low strip or one
  // scan line of a far fence (seed 23's VLP-16: 46 of 48 points, the line running up and down
  // across cells), by all its hits.
  const std::vector<bool> bottom = BottomOf(c, asked, cfg);
  std::vector<bool> mostly_above(judged.size(), false);
  for (std::size_t t = 0; t < judged.size(); ++t) {
    const auto above = std::count_if(judged[t]->begin(), judged[t]->end(), [&](std::uint32_t i) { return !bottom[i]; });
    mostly_above[t] = 2 * std::size_t(above) > judged[t]->size();
  }
  for (std::size_t v = 0; v < hits.size(); ++v) {
    std::vector<bool> hit(judged.size(), false);
    std::vector<std::vector<std::uint32_t>> met(judged.size());  // this keyframe's hits per cluster, as judged
    for (auto i : hits[v]) {
      hit[cluster_of[i]] = true;
      if (!mostly_above[cluster_of[i]] || !bottom[i]) met[cluster_of[i]].push_back(i);
    }
    for (std::size_t t = 0; t < judged.size(); ++t) {
      if (!hit[t]) continue;
      if (last[t] < 0 || own_voters[v].index > own_voters[std::size_t(last[t])].index) last[t] = int(v);
      if (met[t].empty()) continue;
      ++seen_by[t];
      whole[t] = whole[t] || LongestPieceSeen(c, met[t], cfg) >= cfg.ld_residue_length_m;
    }
  }
  for (std::size_t t = 0; t < judged.size(); ++t)
    if (!whole[t] && seen_by[t] >= kTrailMinKeyframes)
      for (auto i : *judged[t]) (*residue)[i] = true;
  MarkDroveWithTheSensor(c, judged, last, own_voters, residue, cfg);
}

namespace {

// The points of `c` higher than ld_radius_m above the ground of `own` under them (ResidueGround,
// as FitAMover measures a thing's top). A thing stands on the ground but is not joined to others
// through it: a strip of new road surface the other session did not see, between a parked car and
// the last place of a car that drove ahead of the sensor when the session ended, made one thing of
// the two, seen by many keyframes (the default scenario's HDL-64E: the driving car stayed in the
// map as a new object).
PointCloud OffTheGround(const PointCloud& c, const PointCloud& own, const RemovertConfig& cfg) {
  geometry::LowestGrid ground = ResidueGround(cfg);
  for (const auto& p : c.points) ground.Watch(p.xyz(), p.xyz(), kGroundGrowCells);
  ground.AddWatched(own);
  std::vector<bool> keep(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3f p = c.points[i].xyz();
    keep[i] = double(p.z() - ground.Under(p, p, kGroundGrowCells)) >= cfg.ld_radius_m;
  }
  return c.select(keep);
}

// Per point of `c`: the gaps {horizontal, vertical} that join it to its neighbours at its range
// from the nearest of `own_voters` (detail::ResidueGapsAt; a lower bound of the range it was
// scanned from), as LT-map clusters objects. A parked car 70-100 m out is sampled sparsely (rows
// 0.5 m apart on 64 beams): at a fixed gap its samples were pieces that each fit in a mover's size
// (seed 7's car 4 left the map as residues on three sensors).
std::vector<Eigen::Vector2f> ResidueGaps(const PointCloud& c, const std::vector<WorldKeyframe>& own_voters,
                                         const RemovertConfig& cfg) {
  std::vector<Eigen::Vector2f> gaps(c.size(), Eigen::Vector2f::Constant(float(cfg.ld_residue_gap_m)));
  if (own_voters.empty()) return gaps;
  const geometry::KdTree tree(detail::Positions(own_voters));
  for (std::size_t i = 0; i < c.size(); ++i) {
    std::uint32_t k = 0;
    float sq = 0.f;
    if (tree.Nearest(c.points[i].xyz(), &k, &sq)) gaps[i] = detail::ResidueGapsAt(cfg, std::sqrt(double(sq)));
  }
  return gaps;
}

// Multi-session cleanup (paper Fig. 3(f)): `seen` (changes the other session saw through, points
// of `own` map) split into clusters at ld_residue_gap_m (farther out at the sensor's sample gaps:
// ResidueGaps), sized together with `unseen` (the same map's changes on the same side that the
// other session did not see through, and the lower parts of both: LabelChanges): a thing whose
// end the other session saw through and whose body it never observed is one thing, not a
// pedestrian. A cluster that fits in a mover's size,
// ld_residue_length_m, along its longest horizontal edge and from the ground under it (the lowest
// point of `own` within half that around it) to its top, and that no larger cluster comes that
// close to, is a residue of a mover (marked in the result, per point of `seen`). A pole, a
// facade's edge or a lamp head that poses let the other session see past reaches higher; a short
// piece beside a large one is part of that object (a trunk's foot under its canopy, a sparse
// object's fragment). A flat patch within ld_radius_m of the ground is no mover's: a mover's part
// that low is within the radius of the other session's ground, so no change at all; such a patch
// is ground the other session did not cover (on real scans, around the other vehicle's place).
// So is a cluster longer than a mover that each keyframe of its own session saw only a mover-sized
// piece of (MarkTrails: a walker's trail), one of those lengths that drove with the sensor
// (MarkDroveWithTheSensor: a car ahead of it to the session's end), and a thing its own session saw
// at its place from no more keyframes than a mover (MarkSeenBriefly, over the seen-through part of
// each cluster).
std::vector<bool> Residues(const PointCloud& seen, const PointCloud& unseen, const PointCloud& own,
                           const std::vector<WorldKeyframe>& own_voters, const RemovertConfig& cfg, int threads) {
  if (cfg.ld_residue_length_m <= 0.0 || seen.empty()) return std::vector<bool>(seen.size(), false);
  PointCloud both = seen;
  both.append(OffTheGround(unseen, own, cfg));
  const auto whole = geometry::EuclideanClusterMembers(both, ResidueGaps(both, own_voters, cfg), threads);
  std::vector<bool> fit = FitAMover(both, whole, own, cfg);
  UnmarkPiecesOfLargerOnes(both, whole, cfg.ld_residue_length_m, &fit);
  detail::MarkTrails(both, whole, own_voters, cfg, threads, &fit);
  std::vector<bool> residue(fit.begin(), fit.begin() + std::ptrdiff_t(seen.size()));
  MarkSeenBriefly(seen, both, whole, own, own_voters, cfg, threads, &residue);
  return residue;
}

// Marks the points of `lower` within ld_residue_gap_m of a marked point of `body` (a residue's
// lower part, which only the other session's ground was near).
std::vector<bool> LowerPartsOf(const PointCloud& body, const std::vector<bool>& residue, const PointCloud& lower,
                               const RemovertConfig& cfg) {
  return geometry::WithinRadius(lower, body.select(residue), cfg.ld_residue_gap_m);
}

// The labels of one map's points (`own`) given its raw changes (`missing`, Raw) and the other
// session's keyframes: same / strong / weak / unobserved (Split), then the residues among the
// changes the other session saw through (strong ND, weak PD), sized with those it did not (weak
// ND, strong PD) and with the lower parts (kRawAboveTheirGround) of both: a lower part is marked
// only where it touches a residue (LowerPartsOf), but it is part of the thing's size. Where LD's
// radius has grown to ld.radius_max_m, a car's lower metre stands within it on the other
// session's ground: sized without it, seed 7's rosette car 1 (true poses) was two pieces of its
// roof 1.5 m and 1.2 m long, each a mover's residue, and the car that left was no change.
void LabelChanges(const PointCloud& own, const std::vector<std::uint8_t>& missing, const PointCloud& other,
                  const std::vector<WorldKeyframe>& own_voters, const std::vector<WorldKeyframe>& others, bool nd,
                  const RemovertConfig& cfg, int threads, std::vector<std::uint8_t>* label) {
  using namespace detail;
  std::vector<std::uint32_t> raw;
  for (std::size_t i = 0; i < missing.size(); ++i)
    if (missing[i] != kRawNone) raw.push_back(std::uint32_t(i));
  std::vector<bool> standing(raw.size());
  for (std::size_t j = 0; j < raw.size(); ++j) standing[j] = missing[raw[j]] == kRawAboveTheirGround;
  const Strength s = Split(SeenThroughBy(own.select(raw), own, others, cfg, threads, !nd, &standing, &other), nd, cfg);
  for (std::size_t j = 0; j < raw.size(); ++j)
    (*label)[raw[j]] = s.strong[j] ? kLdStrong : s.weak[j] ? kLdWeak : s.unobserved[j] ? kLdUnobserved : kLdSame;
  const std::uint8_t seen_label = nd ? kLdStrong : kLdWeak, unseen_label = nd ? kLdWeak : kLdStrong;
  std::vector<std::uint32_t> body, lower, sized_with;  // sized_with: the unseen changes and every lower part
  for (std::uint32_t i : raw) {
    const bool is_lower = missing[i] == kRawAboveTheirGround;
    if ((*label)[i] == seen_label) (is_lower ? lower : body).push_back(i);
    if ((*label)[i] == unseen_label || ((*label)[i] == seen_label && is_lower)) sized_with.push_back(i);
  }
  const PointCloud body_pts = own.select(body);
  const std::vector<bool> residue = Residues(body_pts, own.select(sized_with), own, own_voters, cfg, threads);
  const std::vector<bool> residue_lower = LowerPartsOf(body_pts, residue, own.select(lower), cfg);
  for (std::size_t j = 0; j < body.size(); ++j)
    if (residue[j]) (*label)[body[j]] = kLdResidue;
  for (std::size_t j = 0; j < lower.size(); ++j)
    if (residue_lower[j]) (*label)[lower[j]] = kLdResidue;
}

// The points of `map` with label `l`, in map order.
PointCloud WithLabel(const PointCloud& map, const std::vector<std::uint8_t>& label, std::uint8_t l) {
  std::vector<bool> mask(label.size());
  for (std::size_t i = 0; i < label.size(); ++i) mask[i] = label[i] == l;
  return map.select(mask);
}

}  // namespace

namespace detail {

// A car that drove ahead of the sensor at about its speed until the session ended stays at one
// place relative to the sensor, not in the world. The keyframes saw through its earlier places
// (HD removal took them), but none came after its last one, which its own session's map keeps: on
// OS1-64 and the rosette, two lead cars 19.5 m and 30 m ahead were false disappeared objects. A
// thing that each of the keyframes before its last view `last` (`before`) had more returns on at
// its place relative to the sensor (T_before T_last^-1 p) than at its place in the world, and all
// of them together by more than chance (SignificantlyMore), drove with the sensor. Whatever stands
// still is returned on at its world place at least as much: a wall along the road stays at one
// place relative to the sensor too, and in the world as well. Chance matters where neither keyframe
// saw the thing: a container under 3x drift that each keyframe returned on once near a corner's
// place relative to the sensor and never in the world. A return within HitReach of a point of the
// thing is on it, and the evidence is counted both ways, by the thing's points a return lies near
// and by the returns that lie near one of its points; both must say so. Each alone leans one way
// for some standing things: the points count a dense face once per point (a parked car whose map
// points are dense where its session passed close by: one return of the last, far keyframes that
// fell there once moved was tens of points, 76 against 27 on seed 31's OS1-64, and the car left
// the changes), the returns count a place at the density of the keyframe that sampled it (a thing
// ahead of the sensor is sampled more densely at its relative place, nearer the sensor, than at
// its world place: seed 31's Pandar64, a wall's piece 19 m ahead, 630 against 463 returns).
bool DroveWithTheSensor(const PointCloud& c, const std::vector<std::uint32_t>& m, const WorldKeyframe& last,
                        const std::vector<const WorldKeyframe*>& before, const std::vector<std::shared_ptr<const geometry::KdTree>>& scans,
                        const RemovertConfig& cfg) {
  if (before.size() < std::size_t(kDroveKeyframesBefore)) return false;
  const float reach = HitReach(cfg);
  std::vector<Eigen::Vector3f> world;
  for (auto i : m) world.push_back(c.points[i].xyz());
  ReturnedOn with_sensor, in_world;  // summed over `before`
  for (std::size_t j = 0; j < before.size(); ++j) {
    const Eigen::Affine3f to = (before[j]->T_world_sensor * last.T_world_sensor.inverse()).cast<float>();
    std::vector<Eigen::Vector3f> relative;
    for (const auto& p : world) relative.push_back(to * p);
    const ReturnedOn s = ReturnsOn(relative, *scans[j], reach), w = ReturnsOn(world, *scans[j], reach);
    if (s.points <= w.points || s.returns <= w.returns) return false;
    with_sensor += s;
    in_world += w;
  }
  return SignificantlyMore(with_sensor.points, in_world.points) &&
         SignificantlyMore(with_sensor.returns, in_world.returns);
}

Eigen::Vector2f ResidueGapsAt(const RemovertConfig& cfg, double range_m) {
  const Eigen::Vector2f gap = Eigen::Vector2f::Constant(float(cfg.ld_residue_gap_m));
  if (!cfg.SensorResolved()) return gap;
  const geometry::SensorModel& m = cfg.sensor_model;
  return gap.cwiseMax(geometry::SampleJoinGaps(m.azimuth_step_deg, m.CoarserStepDeg(), std::min(range_m, cfg.max_range_m)));
}

LdLabels LabelLd(const PointCloud& central_map, const PointCloud& query_map, const PointCloud& central_positions,
                 const PointCloud& query_positions, const std::vector<WorldKeyframe>& central_voters,
                 const std::vector<WorldKeyframe>& query_voters, const RemovertConfig& cfg, int threads) {
  LdLabels out{std::vector<std::uint8_t>(central_map.size(), kLdUnchanged),
               std::vector<std::uint8_t>(query_map.size(), kLdUnchanged)};
  const std::vector<std::uint8_t> nd = Missing(central_map, query_map, central_positions, query_positions, false, cfg, threads);
  const std::vector<std::uint8_t> pd = Missing(query_map, central_map, query_positions, central_positions, true, cfg, threads);
  // Weak ND preservation: ND the query never saw through stays in the map.
  LabelChanges(central_map, nd, query_map, central_voters, query_voters, true, cfg, threads, &out.central);
  // PD in space the central session observed as free is weak; behind / beyond it, strong.
  LabelChanges(query_map, pd, central_map, query_voters, central_voters, false, cfg, threads, &out.query);
  return out;
}

LdResult LdFromLabels(const PointCloud& central_map, const PointCloud& query_map, const LdLabels& labels) {
  LdResult res;
  res.nd_strong = WithLabel(central_map, labels.central, kLdStrong);
  res.nd_weak = WithLabel(central_map, labels.central, kLdWeak);
  res.nd_unobserved = WithLabel(central_map, labels.central, kLdUnobserved);
  res.nd_residue = WithLabel(central_map, labels.central, kLdResidue);
  res.pd_strong = WithLabel(query_map, labels.query, kLdStrong);
  res.pd_weak = WithLabel(query_map, labels.query, kLdWeak);
  res.pd_unobserved = WithLabel(query_map, labels.query, kLdUnobserved);
  res.pd_residue = WithLabel(query_map, labels.query, kLdResidue);
  res.central_nd.resize(labels.central.size());
  for (std::size_t i = 0; i < labels.central.size(); ++i) {
    const std::uint8_t l = labels.central[i];
    res.central_nd[i] = l == kLdStrong || l == kLdWeak || l == kLdResidue;
  }
  LdStats& st = res.stats;
  st.central_points = central_map.size();
  st.query_points = query_map.size();
  st.nd_same = std::size_t(std::count(labels.central.begin(), labels.central.end(), kLdSame));
  st.pd_same = std::size_t(std::count(labels.query.begin(), labels.query.end(), kLdSame));
  st.nd_strong = res.nd_strong.size();
  st.nd_weak = res.nd_weak.size();
  st.nd_unobserved = res.nd_unobserved.size();
  st.nd_residue = res.nd_residue.size();
  st.pd_strong = res.pd_strong.size();
  st.pd_weak = res.pd_weak.size();
  st.pd_unobserved = res.pd_unobserved.size();
  st.pd_residue = res.pd_residue.size();
  return res;
}

}  // namespace detail

namespace {

// Says when some of a ring sensor's beams cannot tell their returns from their neighbours'
// (ColumnImage::TellsItsReturns): a beam that passed a point without a return is evidence from
// the others only. A deskewed sweep's near returns, bent by the sensor's motion, may leave none.
void LogBeamsThatTellTheirReturns(const RemovertConfig& cfg) {
  const geometry::SensorModel& m = cfg.sensor_model;
  if (!cfg.SensorResolved() || !m.ring_based || m.azimuth_step_deg <= 0.0) return;
  const int n = detail::ColumnImage::BeamsThatTell(m);
  if (n == m.beams()) return;
  spdlog::warn("LD: {} of {} beams tell their returns from their neighbours' (the scans' elevations scatter {:.3f} deg "
               "about their beams, 3 x that reaches halfway to the next beam: deskewed sweeps without keyframe times?); "
               "a beam that passed a point without a return is evidence from those only",
               n, m.beams(), m.spread_deg);
}

}  // namespace

LdResult DetectLd(const PointCloud& central_map, const PointCloud& query_map,
                  const std::vector<WorldKeyframe>& central_keyframes,
                  const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& user_cfg,
                  int threads) {
  user_cfg.Validate();
  const RemovertConfig cfg = central_keyframes.empty() ? user_cfg : WithSensor(user_cfg, central_keyframes, threads);
  const auto t0 = std::chrono::steady_clock::now();
  spdlog::info("LD: rotation uncertainty between the sessions {:.3f} deg ({}): kd radius {} m + {:.2f} % of the "
               "distance, beam tolerance {} m (own pixel + {:.2f} %)", cfg.LdRotationSigmaDeg(),
               cfg.ld_rotation_sigma_deg > 0.0 ? "ld.rotation_sigma_deg: measured by LT-SLAM or at the given poses, or set" : "pose_sigma_deg",
               cfg.ld_radius_m, 100.0 * cfg.LdRadiusRel(), cfg.ld_beam.tol_m, 100.0 * cfg.LdOwnTolRel());
  LogBeamsThatTellTheirReturns(cfg);
  const detail::LdLabels labels =
      detail::LabelLd(central_map, query_map, detail::Positions(central_keyframes), detail::Positions(query_keyframes),
                      central_keyframes, query_keyframes, cfg, threads);
  LdResult res = detail::LdFromLabels(central_map, query_map, labels);
  res.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace ltm::removert
