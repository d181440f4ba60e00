// HD removal by remove-then-revert on multi-resolution range images (Removert, Kim & Kim 2020).
//
// Remove: at each removal resolution (fine to coarse) a map point is a candidate when at least
//   remove_min_votes keyframes see through it and those are at least remove_min_ratio of the
//   keyframes with evidence about it (see-through + hit). Fine pixels catch small and thin
//   movers; coarse pixels (min range over a larger solid angle) catch what fine pixels miss
//   between beams. The candidates are the union over resolutions.
// Revert: false removals come from pixel quantisation (grazing ground, silhouette edges, thin
//   poles, pose error): a fine pixel's min range belongs to a different surface than the point.
//   At a coarser revert resolution the pixel's min range includes the nearer neighbours, so a
//   static point is observed as a surface (hit) by many keyframes while a moving object's trace
//   is hit only by the few keyframes that saw the object there. A candidate is reverted when,
//   at some revert resolution, hits >= revert_min_hits and hits >= revert_hit_ratio * S, S being
//   its largest see-through count over the removal resolutions. Only candidates are projected
//   at the revert resolutions, and their hits include returns on their surface plane
//   (hd.revert_surface_max_m): ground seen at a grazing angle is sampled metres apart in range.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <unordered_map>
#include <unordered_set>

namespace ltm::removert {

void RemovertConfig::Validate(const std::string& where) const {
  ValidateConfig(*this, where);
  auto fail = [&](const std::string& what) { throw Error(where + ": " + what); };
  if (sensor == "table" || !sensor_elevations_deg.empty()) {
    try {
      geometry::ResolveSensor(sensor, sensor_elevations_deg, {}, "sensor");
    } catch (const Error& e) {
      fail(e.what());
    }
  }
  if (!(max_range_m > min_range_m)) fail("sensor.max_range_m must exceed sensor.min_range_m");
  if (remove_resolutions_deg.empty()) fail("hd.remove_resolutions_deg must not be empty");
  if (revert && revert_resolutions_deg.empty())
    fail("hd.revert_resolutions_deg must not be empty when hd.revert is true");
  if (ld_resolutions_deg.empty()) fail("ld.resolutions_deg must not be empty");
}

namespace detail {

std::int64_t VoxelIndex(float v, double voxel_m) { return std::int64_t(std::floor(double(v) / voxel_m)); }

PointCloud ScanForMap(const WorldKeyframe& kf, const RemovertConfig& cfg, const VoxelBox* clip) {
  const auto scan = LoadScan(kf);
  PointCloud local = geometry::RangeFilter(*scan, cfg.min_range_m, cfg.max_range_m);
  local.cls.clear();
  local.session.clear();
  local.object.clear();
  geometry::TransformInPlace(local, kf.T_world_sensor);
  if (clip) {
    std::vector<bool> inside(local.size());
    for (std::size_t i = 0; i < local.size(); ++i)
      inside[i] = clip->Contains(VoxelIndex(local.points[i].x, cfg.map_voxel_m),
                                 VoxelIndex(local.points[i].y, cfg.map_voxel_m));
    local = local.select(inside);
  }
  return geometry::VoxelDownsample(local, cfg.map_voxel_m, 1);
}

namespace {

// Per-voxel means of two voxelised clouds (a before b).
PointCloud MeanOfTwo(PointCloud a, PointCloud b, double voxel_m, int threads) {
  const std::size_t split = a.size();
  std::vector<PointCloud> both;
  both.push_back(std::move(a));
  both.push_back(std::move(b));
  return geometry::VoxelDownsampleRuns(Concatenate(std::move(both), threads), {0, split}, voxel_m, threads);
}

// Bit length of x: the level of the lowest common ancestor of two leaves whose ids differ by x.
int BitLength(std::uint64_t x) {
  int n = 0;
  for (; x != 0; x >>= 1) ++n;
  return n;
}

}  // namespace

PointCloud BuildMap(const std::vector<WorldKeyframe>& keyframes, const std::vector<std::size_t>& slots,
                    const RemovertConfig& cfg, int threads, const VoxelBox* clip) {
  if (slots.size() != keyframes.size()) throw Error("removert: one session slot per keyframe");
  for (std::size_t k = 1; k < slots.size(); ++k)
    if (slots[k] <= slots[k - 1]) throw Error("removert: keyframe slots must ascend");
  // Pending subtrees, bottom to top of the stack; `join` = level of the common ancestor with the
  // subtree below. A new batch first folds every pending subtree that joins below its own join.
  struct Pending {
    PointCloud map;
    int join;
  };
  std::vector<Pending> stack;
  auto fold = [&] {
    Pending top = std::move(stack.back());
    stack.pop_back();
    stack.back().map = MeanOfTwo(std::move(stack.back().map), std::move(top.map), cfg.map_voxel_m, threads);
  };
  std::size_t last_batch = 0;
  for (std::size_t b = 0; b < keyframes.size();) {
    const std::size_t batch = slots[b] / kMapBatch;
    std::size_t e = b;
    while (e < keyframes.size() && slots[e] / kMapBatch == batch) ++e;
    std::vector<PointCloud> parts(e - b);
    ParallelFor(e - b, threads, [&](std::size_t k) { parts[k] = ScanForMap(keyframes[b + k], cfg, clip); });
    std::vector<std::size_t> part_runs;
    std::size_t at = 0;
    for (const auto& p : parts) part_runs.push_back(at), at += p.size();
    const PointCloud merged = Concatenate(std::move(parts), threads);
    const int join = stack.empty() ? 0 : BitLength(std::uint64_t(batch ^ last_batch));
    while (stack.size() >= 2 && stack.back().join < join) fold();
    stack.push_back({geometry::VoxelDownsampleRuns(merged, part_runs, cfg.map_voxel_m, threads), join});
    last_batch = batch;
    b = e;
  }
  while (stack.size() >= 2) fold();
  return stack.empty() ? PointCloud{} : std::move(stack.back().map);
}

}  // namespace detail

PointCloud BuildSessionMap(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                           int threads) {
  std::vector<std::size_t> slots(keyframes.size());
  for (std::size_t k = 0; k < slots.size(); ++k) slots[k] = k;
  return detail::BuildMap(keyframes, slots, cfg, threads, nullptr);
}

namespace {

// The removed points that have removed points at least body_m / 2 above or below them within
// body_m: points of removed bodies that stand up from the ground (a mover), not of removed flat
// patches (ground the votes got wrong).
PointCloud BodyPoints(const PointCloud& removed, double body_m, int threads) {
  if (removed.empty()) return removed;
  const geometry::KdTree tree(removed);
  std::vector<std::uint8_t> bottom(removed.size(), 0);
  detail::ParallelFor(removed.size(), threads, [&](std::size_t i) {
    const PointXYZI& p = removed.points[i];
    for (const auto& [j, d2] : tree.Radius(p.xyz(), float(body_m)))
      if (std::fabs(removed.points[j].z - p.z) >= float(0.5 * body_m)) {
        bottom[i] = 1;
        return;
      }
  });
  std::vector<bool> keep(removed.size());
  for (std::size_t i = 0; i < removed.size(); ++i) keep[i] = bottom[i] != 0;
  return removed.select(keep);
}

// A cell's integer coordinates packed into one key, 21 bits per axis: cells 2^21 apart share a
// key (callers treat a key as a hint, never as the answer).
std::int64_t PackCell(std::int64_t x, std::int64_t y, std::int64_t z) {
  constexpr std::int64_t kMask = (std::int64_t(1) << 21) - 1;
  return (x & kMask) | ((y & kMask) << 21) | ((z & kMask) << 42);
}

// Per map point: 1 when it is not in `dynamic` and lies within radius_m of a point of `seeds`.
std::vector<std::uint8_t> GrowMask(const PointCloud& map, const std::vector<bool>& dynamic, const PointCloud& seeds,
                                   double radius_m, int threads) {
  std::vector<std::uint8_t> grow(map.size(), 0);
  if (seeds.empty() || radius_m <= 0.0) return grow;
  const geometry::KdTree tree(seeds);
  const float r2 = float(radius_m * radius_m);
  // Cells touched by some seed's ball: most map points are far from every seed and skip the
  // kd-tree after one hash lookup. Any cell edge >= 2 radii works (a ball then touches at most
  // 2 cells per axis, found from its bounding box's corners); keys keep 21 bits per axis, so
  // cells 2^21 apart share a key: a wasted kd-tree query, never a wrong answer (the kd-tree decides).
  constexpr double kCellRadii = 4.0;
  const double cell = kCellRadii * radius_m;
  auto key = PackCell;
  auto index = [&](float v, double off) { return std::int64_t(std::floor((double(v) + off) / cell)); };
  std::unordered_set<std::int64_t> touched;
  for (const PointXYZI& q : seeds.points)
    for (int dx = -1; dx <= 1; dx += 2)
      for (int dy = -1; dy <= 1; dy += 2)
        for (int dz = -1; dz <= 1; dz += 2)
          touched.insert(key(index(q.x, dx * radius_m), index(q.y, dy * radius_m), index(q.z, dz * radius_m)));
  const std::size_t chunk = 8192;
  detail::ParallelFor((map.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
    const std::size_t b = c * chunk, e = std::min(map.size(), b + chunk);
    std::uint32_t j = 0;
    float d2 = 0.f;
    for (std::size_t i = b; i < e; ++i) {
      const PointXYZI& p = map.points[i];
      if (dynamic[i] || !touched.count(key(index(p.x, 0.0), index(p.y, 0.0), index(p.z, 0.0)))) continue;
      if (tree.Nearest(p.xyz(), &j, &d2) && d2 <= r2) grow[i] = 1;
    }
  });
  return grow;
}

// 2D cells of `cell_m` over the map's xy (PackCell with z = 0).
std::int64_t CellKey(float x, float y, double cell_m) {
  return PackCell(std::int64_t(std::floor(double(x) / cell_m)), std::int64_t(std::floor(double(y) / cell_m)), 0);
}

// Per map point: 1 when it is not in `dynamic`, more than clearance_m above the local ground (the
// lowest map point within about radius_m in xy) and under a foot of `bodies` (a point at most
// reach_m above the local ground, within radius_m of it in xy). A mover's lowest parts, next to
// the ground, are never seen through: the beam below them returns from the ground in front of
// them. What stands between a removed body's foot and the ground under it is that body; the
// ground layer itself stays, and so does a wall under a patch removed higher up (blurred walls of
// motion-distorted sweeps lost 0.7-1 % more of the static map when every body point reached down).
std::vector<std::uint8_t> GroundwardMask(const PointCloud& map, const std::vector<bool>& dynamic,
                                         const PointCloud& bodies, double radius_m, double reach_m,
                                         double clearance_m, int threads) {
  std::vector<std::uint8_t> grow(map.size(), 0);
  if (bodies.empty() || radius_m <= 0.0) return grow;
  geometry::LowestGrid low(radius_m);
  low.Add(map);
  auto ground_near = [&](const PointXYZI& p) { return detail::GroundNear(low, p); };
  std::unordered_map<std::int64_t, std::vector<std::uint32_t>> body_cells;  // the bodies' feet
  for (std::size_t j = 0; j < bodies.size(); ++j) {
    const PointXYZI& b = bodies.points[j];
    if (b.z - ground_near(b) <= float(reach_m)) body_cells[CellKey(b.x, b.y, radius_m)].push_back(std::uint32_t(j));
  }
  const float r2 = float(radius_m * radius_m);
  auto under_body = [&](const PointXYZI& p) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy) {
        const auto it = body_cells.find(CellKey(p.x + float(dx * radius_m), p.y + float(dy * radius_m), radius_m));
        if (it == body_cells.end()) continue;
        for (std::uint32_t j : it->second) {
          const PointXYZI& b = bodies.points[j];
          const float ex = b.x - p.x, ey = b.y - p.y;
          if (b.z > p.z && ex * ex + ey * ey <= r2) return true;
        }
      }
    return false;
  };
  const std::size_t chunk = 8192;
  detail::ParallelFor((map.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
    for (std::size_t i = c * chunk; i < std::min(map.size(), (c + 1) * chunk); ++i) {
      const PointXYZI& p = map.points[i];
      if (!dynamic[i] && under_body(p) && p.z > ground_near(p) + float(clearance_m)) grow[i] = 1;
    }
  });
  return grow;
}

// Removal candidates: points with enough see-through votes at some removal resolution.
struct Candidates {
  std::vector<std::uint32_t> index;  // map indices
  std::vector<double> s_max;         // their strongest removal evidence over the resolutions
  std::vector<bool> at;              // [candidate * levels + level]: a candidate at that removal resolution
};
Candidates FindCandidates(const VisibilityVotes& votes, std::size_t n, const RemovertConfig& cfg) {
  const int n_remove = int(cfg.remove_resolutions_deg.size());
  Candidates c;
  std::vector<bool> level_hit(std::size_t(n_remove), false);
  for (std::size_t i = 0; i < n; ++i) {
    bool is_cand = false;
    double sm = 0;
    for (int l = 0; l < n_remove; ++l) {
      const double s = votes.See(l, i), h = votes.Hit(l, i);
      sm = std::max(sm, s);
      level_hit[std::size_t(l)] = s >= cfg.remove_min_votes && s >= cfg.remove_min_ratio * (s + h);
      is_cand = is_cand || level_hit[std::size_t(l)];
    }
    if (!is_cand) continue;
    c.index.push_back(std::uint32_t(i));
    c.s_max.push_back(sm);
    c.at.insert(c.at.end(), level_hit.begin(), level_hit.end());
  }
  return c;
}

// The candidates' surfaces for the revert's surface hits: their normals from the whole map, and
// *takes_hits, whether a candidate's plane takes them. A level surface (ground) always does. An
// upright one only where the map without the candidates holds an upright plane parallel to it
// (normals within 45 deg): a walker going along the line of sight leaves an upright trail of its
// own points, whose "plane" holds the walker's later returns metres along it, so a surface of
// candidates alone would vouch for itself. A wall keeps its plane. A trail over open ground has
// none and is judged by its returns alone (one within the normal radius of a parallel wall still
// takes them).
std::vector<Eigen::Vector3f> RevertSurfaces(const PointCloud& map, const Candidates& cand, const PointCloud& cpts,
                                            const RemovertConfig& cfg, int threads, std::vector<bool>* takes_hits) {
  const double r = cfg.ld_normal_radius_m;
  std::vector<Eigen::Vector3f> normals = detail::EstimateNormals(cpts, map, r, threads);
  std::vector<bool> rest_mask = geometry::WithinRadius(map, cpts, r, threads), rest_planar;  // what the normals read
  for (std::uint32_t i : cand.index) rest_mask[i] = false;
  const std::vector<Eigen::Vector3f> rest = detail::EstimateNormals(cpts, map.select(rest_mask), r, threads, &rest_planar);
  takes_hits->assign(cpts.size(), true);
  for (std::size_t j = 0; j < cpts.size(); ++j)
    if (std::fabs(normals[j].z()) < detail::kUprightNormalZ)
      (*takes_hits)[j] = rest_planar[j] && std::fabs(rest[j].z()) < detail::kUprightNormalZ &&
                         std::fabs(rest[j].dot(normals[j])) >= detail::kParallelCos;
  return normals;
}

// Revert: only the candidates are projected again, at the coarser resolutions, counting hits
// on their surface plane (RevertSurfaces), so grazing ground is observed as a surface.
std::vector<bool> Revert(const PointCloud& map, const Candidates& cand, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads) {
  std::vector<bool> reverted(cand.index.size(), false);
  if (!cfg.revert || cand.index.empty()) return reverted;
  const PointCloud cpts = map.select(cand.index);
  VisibilityOptions opt;
  std::vector<Eigen::Vector3f> normals;
  std::vector<bool> takes_hits;
  if (cfg.revert_surface_max_m > 0.0) {
    normals = RevertSurfaces(map, cand, cpts, cfg, threads, &takes_hits);
    opt.normals = &normals;
    opt.surface_at = &takes_hits;
    opt.surface_max_m = cfg.revert_surface_max_m;
  }
  const VisibilityVotes rv = CountVisibility(cpts, keyframes, cfg.revert_resolutions_deg, cfg, threads, opt);
  for (std::size_t j = 0; j < cand.index.size(); ++j)
    for (int l = 0; l < rv.levels && !reverted[j]; ++l) {
      const double h = rv.Hit(l, j);
      reverted[j] = h >= cfg.revert_min_hits && h >= cfg.revert_hit_ratio * cand.s_max[j];
    }
  return reverted;
}

// Dilation: the map points next to a removed point go too (a wheel's or a foot's contact with
// the ground shares its voxels with the ground): one map voxel around every removed point, and
// hd.dilate_voxels around the points of removed bodies (BodyPoints), not around removed patches
// of flat ground, and from a body's foot (within dilate_body_m of the ground) down to one map
// voxel above the ground (GroundwardMask). Decided against the removed set before dilation: no
// transitive growth. The points it adds become HdDecision::kDilated in *state.
void Dilate(const PointCloud& map, const RemovertConfig& cfg, int threads, const std::vector<bool>& removed_mask,
            std::vector<std::uint8_t>* state) {
  const PointCloud removed = map.select(removed_mask);
  std::vector<std::uint8_t> grow = GrowMask(map, removed_mask, removed, std::min(1.0, cfg.dilate_voxels) * cfg.map_voxel_m, threads);
  if (cfg.dilate_voxels > 1.0) {
    const PointCloud bodies = BodyPoints(removed, cfg.dilate_body_m, threads);
    const std::vector<std::uint8_t> body = GrowMask(map, removed_mask, bodies, cfg.DilateM(), threads);
    const std::vector<std::uint8_t> down =
        GroundwardMask(map, removed_mask, bodies, cfg.DilateM(), cfg.dilate_body_m, cfg.map_voxel_m, threads);
    for (std::size_t i = 0; i < grow.size(); ++i) grow[i] |= body[i] | down[i];
  }
  for (std::size_t i = 0; i < map.size(); ++i)
    if (grow[i]) (*state)[i] = detail::HdDecision::kDilated;
}

}  // namespace

namespace detail {

HdDecision DecideHd(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& user_cfg,
                    int threads) {
  user_cfg.Validate();
  const RemovertConfig cfg = keyframes.empty() ? user_cfg : WithSensor(user_cfg, keyframes, threads);
  const VisibilityVotes votes = CountVisibility(map, keyframes, cfg.remove_resolutions_deg, cfg, threads);
  const Candidates cand = FindCandidates(votes, map.size(), cfg);
  const std::vector<bool> reverted = Revert(map, cand, keyframes, cfg, threads);
  HdDecision d;
  d.levels = int(cfg.remove_resolutions_deg.size());
  d.state.assign(map.size(), HdDecision::kStatic);
  d.candidate_at.assign(map.size() * std::size_t(d.levels), false);
  std::vector<bool> dynamic(map.size(), false);
  for (std::size_t j = 0; j < cand.index.size(); ++j) {
    const std::size_t i = cand.index[j];
    const std::size_t levels = std::size_t(d.levels);
    for (std::size_t l = 0; l < levels; ++l) d.candidate_at[i * levels + l] = cand.at[j * levels + l];
    d.state[i] = reverted[j] ? HdDecision::kReverted : HdDecision::kRemoved;
    dynamic[i] = !reverted[j];
  }
  if (cfg.dilate_voxels > 0.0 && std::find(dynamic.begin(), dynamic.end(), true) != dynamic.end())
    Dilate(map, cfg, threads, dynamic, &d.state);
  CompleteBodies(map, keyframes, cfg, votes, threads, &d.state);
  return d;
}

HdResult SplitHd(const PointCloud& map, const HdDecision& d, const std::vector<bool>* include) {
  HdResult res;
  HdStats& st = res.stats;
  st.removed_per_resolution.assign(std::size_t(d.levels), 0);
  std::vector<bool> keep(map.size(), false), removed(map.size(), false);
  for (std::size_t i = 0; i < map.size(); ++i) {
    if (include && !(*include)[i]) continue;
    ++st.map_points;
    bool candidate = false;
    for (int l = 0; l < d.levels; ++l)
      if (d.candidate_at[i * std::size_t(d.levels) + std::size_t(l)]) {
        ++st.removed_per_resolution[std::size_t(l)];
        candidate = true;
      }
    st.candidates += candidate ? 1 : 0;
    const std::uint8_t s = d.state[i];
    st.reverted += s == HdDecision::kReverted ? 1 : 0;
    st.removed += s == HdDecision::kRemoved ? 1 : 0;
    st.dilated += s == HdDecision::kDilated ? 1 : 0;
    removed[i] = s == HdDecision::kRemoved || s == HdDecision::kDilated;
    keep[i] = !removed[i];
  }
  res.static_map = map.select(keep);
  res.hd_map = map.select(removed);
  return res;
}

}  // namespace detail

HdResult RemoveHdFromMap(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads) {
  const auto t0 = std::chrono::steady_clock::now();
  HdResult res = detail::SplitHd(map, detail::DecideHd(map, keyframes, cfg, threads), nullptr);
  res.stats.seconds_votes = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

HdResult RemoveHd(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                  int threads) {
  cfg.Validate();
  const auto t0 = std::chrono::steady_clock::now();
  const PointCloud map = BuildSessionMap(keyframes, cfg, threads);
  const double t_map = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  HdResult res = RemoveHdFromMap(map, keyframes, cfg, threads);
  res.stats.seconds_map = t_map;
  return res;
}

}  // namespace ltm::removert
