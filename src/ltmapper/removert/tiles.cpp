// HD removal tile by tile (tiles.hpp): the plan, one tile's job and the merge.
#include "ltmapper/removert/tiles.hpp"

#include "ltmapper/removert/detail.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <functional>
#include <cmath>
#include <map>
#include <utility>

namespace ltm::removert {

double TileReachM(const RemovertConfig& cfg) { return std::max(cfg.max_range_m, cfg.submap_radius_m); }

double TileMarginM(const RemovertConfig& cfg) {
  const bool surface = cfg.revert && cfg.revert_surface_max_m > 0.0;
  const double normals = surface ? cfg.ld_normal_radius_m : 0.0;
  if (cfg.dilate_voxels <= 0.0) return normals;
  const double near = std::min(1.0, cfg.dilate_voxels) * cfg.map_voxel_m + normals;
  if (cfg.dilate_voxels <= 1.0) return near;
  const double body = cfg.DilateM() + cfg.dilate_body_m + normals;
  const double ground = 3.0 * cfg.DilateM();
  return std::max({near, body, ground});
}

namespace {

// The tile edge in map voxels: tiles.edge_m, or 2 x the reach, rounded to whole voxels.
std::int64_t EdgeVoxels(const RemovertConfig& cfg) {
  const double edge_m = cfg.tiles_edge_m > 0.0 ? cfg.tiles_edge_m : 2.0 * TileReachM(cfg);
  return std::max<std::int64_t>(1, std::int64_t(std::llround(edge_m / cfg.map_voxel_m)));
}

// The tile's core grown by `grow` voxels on every side.
detail::VoxelBox BoxOf(const TilePlan& plan, const Tile& t, std::int64_t grow) {
  const std::int64_t e = plan.edge_voxels;
  return {t.ix * e - grow, t.iy * e - grow, (t.ix + 1) * e + grow, (t.iy + 1) * e + grow};
}

// xy distance from (x, y) to a voxel box [m].
double DistanceTo(const detail::VoxelBox& b, double voxel_m, double x, double y) {
  const double dx = std::max({double(b.x0) * voxel_m - x, 0.0, x - double(b.x1) * voxel_m});
  const double dy = std::max({double(b.y0) * voxel_m - y, 0.0, y - double(b.y1) * voxel_m});
  return std::hypot(dx, dy);
}

// The plan must be the one of these keyframes and this config (a plan file of another session or
// other map voxel / tile keys would give another map).
void CheckPlan(const TilePlan& plan, std::size_t tile, const std::vector<WorldKeyframe>& keyframes,
               const RemovertConfig& cfg) {
  if (tile >= plan.tiles.size())
    throw Error("tiles: tile " + std::to_string(tile) + " of a plan with " + std::to_string(plan.tiles.size()) +
                " tiles");
  if (plan.session_keyframes != keyframes.size())
    throw Error("tiles: the plan is for " + std::to_string(plan.session_keyframes) + " keyframes, the session has " +
                std::to_string(keyframes.size()));
  const TilePlan expected = PlanTiles({}, cfg);
  if (plan.voxel_m != expected.voxel_m || plan.edge_voxels != expected.edge_voxels ||
      plan.margin_voxels != expected.margin_voxels || plan.reach_m != expected.reach_m)
    throw Error("tiles: the plan was made with other map_voxel_m / tiles.edge_m / margin keys than this config");
  for (std::size_t k : plan.tiles[tile].keyframes)
    if (k >= keyframes.size()) throw Error("tiles: tile " + std::to_string(tile) + " names keyframe " + std::to_string(k));
}

// The keyframes that vote on the box's points: within submap_radius_m of them (+ one voxel for float
// rounding). The others of the tile (up to sensor.max_range_m away) only add returns to its map;
// building their range images would be wasted.
std::vector<WorldKeyframe> Voters(const std::vector<WorldKeyframe>& kfs, const detail::VoxelBox& box, double voxel_m,
                                  const RemovertConfig& cfg) {
  std::vector<WorldKeyframe> voters;
  for (const WorldKeyframe& kf : kfs) {
    const Eigen::Vector3d c = kf.T_world_sensor.translation();
    if (DistanceTo(box, voxel_m, c.x(), c.y()) <= cfg.submap_radius_m + voxel_m) voters.push_back(kf);
  }
  return voters;
}

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

namespace detail {

void MergeInVoxelOrder(const std::vector<PointCloud>& parts, double voxel_m,
                       const std::function<void(const PointCloud&)>& emit) {
  using Key = std::array<std::int64_t, 3>;
  auto key = [&](const PointXYZI& p) {
    return Key{VoxelIndex(p.x, voxel_m), VoxelIndex(p.y, voxel_m), VoxelIndex(p.z, voxel_m)};
  };
  struct Head {
    Key key;
    std::size_t part, i;
    bool operator>(const Head& o) const { return key != o.key ? key > o.key : part > o.part; }
  };
  std::vector<Head> heap;
  for (std::size_t r = 0; r < parts.size(); ++r)
    if (!parts[r].empty()) heap.push_back({key(parts[r].points[0]), r, 0});
  const auto later = std::greater<Head>();
  std::make_heap(heap.begin(), heap.end(), later);
  PointCloud piece;
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    Head& h = heap.back();
    piece.points.push_back(parts[h.part].points[h.i]);
    if (++h.i < parts[h.part].size()) {
      h.key = key(parts[h.part].points[h.i]);
      std::push_heap(heap.begin(), heap.end(), later);
    } else {
      heap.pop_back();
    }
    if (piece.size() == kMergePiece || heap.empty()) {
      emit(piece);
      piece.points.clear();
    }
  }
}

void AddHdStats(const HdStats& s, HdStats* sum) {
  if (sum->removed_per_resolution.size() < s.removed_per_resolution.size())
    sum->removed_per_resolution.resize(s.removed_per_resolution.size(), 0);
  for (std::size_t l = 0; l < s.removed_per_resolution.size(); ++l)
    sum->removed_per_resolution[l] += s.removed_per_resolution[l];
  sum->map_points += s.map_points;
  sum->candidates += s.candidates;
  sum->reverted += s.reverted;
  sum->removed += s.removed;
  sum->dilated += s.dilated;
  sum->seconds_map += s.seconds_map;
  sum->seconds_votes += s.seconds_votes;
}

}  // namespace detail

TilePlan PlanTiles(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg) {
  cfg.Validate();
  TilePlan plan;
  plan.voxel_m = cfg.map_voxel_m;
  plan.edge_voxels = EdgeVoxels(cfg);
  plan.margin_voxels = std::int64_t(std::ceil(TileMarginM(cfg) / cfg.map_voxel_m)) + 1;  // + the centroid's voxel
  plan.reach_m = TileReachM(cfg) + cfg.map_voxel_m;  // + float rounding of world-frame returns
  plan.session_keyframes = keyframes.size();
  const double edge_m = plan.EdgeM(), span_m = plan.reach_m + double(plan.margin_voxels) * plan.voxel_m;
  std::map<std::pair<std::int64_t, std::int64_t>, Tile> tiles;
  for (std::size_t k = 0; k < keyframes.size(); ++k) {
    const Eigen::Vector3d c = keyframes[k].T_world_sensor.translation();
    const auto lo_x = std::int64_t(std::floor((c.x() - span_m) / edge_m)), hi_x = std::int64_t(std::floor((c.x() + span_m) / edge_m));
    const auto lo_y = std::int64_t(std::floor((c.y() - span_m) / edge_m)), hi_y = std::int64_t(std::floor((c.y() + span_m) / edge_m));
    for (std::int64_t ix = lo_x; ix <= hi_x; ++ix)
      for (std::int64_t iy = lo_y; iy <= hi_y; ++iy) {
        Tile t{ix, iy, {}};
        if (DistanceTo(BoxOf(plan, t, plan.margin_voxels), plan.voxel_m, c.x(), c.y()) > plan.reach_m) continue;
        auto it = tiles.try_emplace({ix, iy}, std::move(t)).first;
        it->second.keyframes.push_back(k);
      }
  }
  // Only tiles whose core some keyframe reaches can hold map points.
  for (auto& [key, t] : tiles) {
    const bool core_reached = std::any_of(t.keyframes.begin(), t.keyframes.end(), [&](std::size_t k) {
      const Eigen::Vector3d c = keyframes[k].T_world_sensor.translation();
      return DistanceTo(BoxOf(plan, t, 0), plan.voxel_m, c.x(), c.y()) <= plan.reach_m;
    });
    if (core_reached) plan.tiles.push_back(std::move(t));
  }
  return plan;
}

HdResult RemoveHdTile(const TilePlan& plan, std::size_t tile, const std::vector<WorldKeyframe>& keyframes,
                      const RemovertConfig& user_cfg, int threads) {
  const RemovertConfig cfg = WithSensor(user_cfg, keyframes);
  CheckPlan(plan, tile, keyframes, cfg);
  const Tile& t = plan.tiles[tile];
  std::vector<WorldKeyframe> kfs;
  for (std::size_t k : t.keyframes) kfs.push_back(keyframes[k]);
  const auto t0 = std::chrono::steady_clock::now();
  const detail::VoxelBox region = BoxOf(plan, t, plan.margin_voxels), core = BoxOf(plan, t, 0);
  const PointCloud map = detail::BuildMap(kfs, t.keyframes, cfg, threads, &region);
  const double seconds_map = Since(t0);
  const detail::HdDecision decision = detail::DecideHd(map, Voters(kfs, region, plan.voxel_m, cfg), cfg, threads);
  std::vector<bool> in_core(map.size());
  for (std::size_t i = 0; i < map.size(); ++i)
    in_core[i] = core.Contains(detail::VoxelIndex(map.points[i].x, plan.voxel_m),
                               detail::VoxelIndex(map.points[i].y, plan.voxel_m));
  HdResult res = detail::SplitHd(map, decision, &in_core);
  res.stats.seconds_map = seconds_map;
  res.stats.seconds_votes = Since(t0) - seconds_map;
  return res;
}

void TileMerger::Add(const Tile& tile, HdResult part) {
  if (started_ && tile.ix < column_) throw Error("tiles: merge the tiles in plan order (by ix)");
  if (started_ && tile.ix != column_) FlushColumn();
  started_ = true;
  column_ = tile.ix;
  pending_.push_back(std::move(part));
}

void TileMerger::FlushColumn() {
  std::vector<PointCloud> static_maps, hd_maps;
  for (HdResult& p : pending_) {
    static_maps.push_back(std::move(p.static_map));
    hd_maps.push_back(std::move(p.hd_map));
    detail::AddHdStats(p.stats, &out_.stats);
  }
  pending_.clear();
  detail::MergeInVoxelOrder(static_maps, voxel_m_, [&](const PointCloud& piece) { out_.static_map.append(piece); });
  detail::MergeInVoxelOrder(hd_maps, voxel_m_, [&](const PointCloud& piece) { out_.hd_map.append(piece); });
}

HdResult TileMerger::Finish() {
  FlushColumn();
  return std::move(out_);
}

HdResult MergeTiles(const TilePlan& plan, std::vector<HdResult> parts) {
  if (parts.size() != plan.tiles.size())
    throw Error("tiles: " + std::to_string(parts.size()) + " results for " + std::to_string(plan.tiles.size()) + " tiles");
  TileMerger merger(plan.voxel_m);
  for (std::size_t t = 0; t < parts.size(); ++t) merger.Add(plan.tiles[t], std::move(parts[t]));
  return merger.Finish();
}

HdResult RemoveHdTiled(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& user_cfg, int threads) {
  user_cfg.Validate();
  const RemovertConfig cfg = keyframes.empty() ? user_cfg : WithSensor(user_cfg, keyframes);
  const TilePlan plan = PlanTiles(keyframes, cfg);
  TileMerger merger(plan.voxel_m);
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) merger.Add(plan.tiles[t], RemoveHdTile(plan, t, keyframes, cfg, threads));
  return merger.Finish();
}

}  // namespace ltm::removert
