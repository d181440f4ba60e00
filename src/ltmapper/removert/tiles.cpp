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
#include <unordered_map>

#include <spdlog/spdlog.h>

namespace ltm::removert {

double TileReachM(const RemovertConfig& cfg) { return std::max(cfg.max_range_m, cfg.submap_radius_m); }

double TileMarginM(const RemovertConfig& cfg) {
  const bool surface = cfg.revert && cfg.revert_surface_max_m > 0.0;
  const double normals = surface ? cfg.ld_normal_radius_m : 0.0;
  double dilation = normals;
  if (cfg.dilate_voxels > 0.0) dilation = std::min(1.0, cfg.dilate_voxels) * cfg.map_voxel_m + normals;
  if (cfg.dilate_voxels > 1.0) {
    const double body = cfg.DilateM() + cfg.dilate_body_m + normals;
    const double ground = 3.0 * cfg.DilateM();
    dilation = std::max({dilation, body, ground});
  }
  if (cfg.body_max_m <= 0.0) return dilation;
  // CompleteBodies: a point's cluster reaches sqrt(2) body lengths (its xy box) and one gap
  // (dilate_body_m) beyond, the returns it is chosen from one body length more, the ground of each
  // the lowest map point two cells of dilate_body_m away.
  return dilation + (1.0 + std::sqrt(2.0)) * cfg.body_max_m + 3.0 * cfg.dilate_body_m;
}

namespace {

// The tile's core grown by `grow` voxels on every side.
detail::VoxelBox BoxOf(const TilePlan& plan, const Tile& t, std::int64_t grow) {
  const std::int64_t e = plan.edge_voxels;
  return {t.ix * e - grow, t.iy * e - grow, (t.ix + 1) * e + grow, (t.iy + 1) * e + grow};
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
  if (plan.voxel_m != expected.voxel_m || !detail::IsTileEdgeChoice(cfg, plan.edge_voxels) ||
      plan.margin_voxels != expected.margin_voxels || plan.reach_m != expected.reach_m)
    throw Error("tiles: the plan was made with other map_voxel_m / tiles.edge_m / margin keys than this config");
  for (std::size_t k : plan.tiles[tile].keyframes)
    if (k >= keyframes.size()) throw Error("tiles: tile " + std::to_string(tile) + " names keyframe " + std::to_string(k));
}

// The keyframes that vote on the box's points: within submap_radius_m of them. The others of the
// tile (up to sensor.max_range_m away) only add returns to its map; building their range images
// would be wasted.
std::vector<WorldKeyframe> Voters(const std::vector<WorldKeyframe>& kfs, const detail::VoxelBox& box, double voxel_m,
                                  const RemovertConfig& cfg) {
  std::vector<WorldKeyframe> voters;
  for (std::size_t k : detail::KeyframesNear(kfs, box, voxel_m, cfg.submap_radius_m)) voters.push_back(kfs[k]);
  return voters;
}

// [map voxels] TileMarginM rounded up to whole voxels, + the centroid's voxel.
std::int64_t MarginVoxels(const RemovertConfig& cfg) {
  return std::int64_t(std::ceil(TileMarginM(cfg) / cfg.map_voxel_m)) + 1;
}

// [map voxels] The finest tile edge the plan may choose, the cell its counts are kept in.
std::int64_t FineCellVoxels(const RemovertConfig& cfg) {
  return std::max<std::int64_t>(1, detail::kFinestEdgeMargins * MarginVoxels(cfg));
}

// Distinct map voxels (map points) per xy cell of a grid, estimated (DistinctCounter).
struct CellCounts {
  std::int64_t cell_voxels = 1;
  std::unordered_map<std::uint64_t, DistinctCounter> cells;  // by PackXY(cell x, cell y)
};

// Every keyframe's scan for the map (detail::ScanForMap) counted into each grid: one pass over the
// scans, a batch of keyframes at a time (memory: the batch's voxels and the counters).
void CountMapVoxels(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg, int threads,
                    std::vector<CellCounts>* grids) {
  const std::size_t batch = detail::kMapBatch;
  for (std::size_t b = 0; b < keyframes.size(); b += batch) {
    const std::size_t e = std::min(keyframes.size(), b + batch);
    struct Voxel {
      std::int64_t x, y;
      std::uint64_t hash;  // of (x, y, z), computed once for every grid
    };
    std::vector<std::vector<Voxel>> voxels(e - b);
    ParallelFor(e - b, threads, [&](std::size_t k) {
      const PointCloud scan = detail::ScanForMap(keyframes[b + k], cfg, nullptr);
      voxels[k].reserve(scan.size());
      for (const PointXYZI& p : scan.points) {
        const std::int64_t x = detail::VoxelIndex(p.x, cfg.map_voxel_m), y = detail::VoxelIndex(p.y, cfg.map_voxel_m);
        const auto z = std::uint64_t(detail::VoxelIndex(p.z, cfg.map_voxel_m));
        voxels[k].push_back({x, y, MixHash(MixHash(MixHash(std::uint64_t(x)) ^ std::uint64_t(y)) ^ z)});
      }
    });
    for (CellCounts& g : *grids) {
      std::uint64_t last_key = 0;
      DistinctCounter* last = nullptr;  // a scan's points come in runs of one cell
      for (const auto& scan : voxels)
        for (const Voxel& v : scan) {
          const std::uint64_t key =
              detail::PackXY(detail::FloorDiv(v.x, g.cell_voxels), detail::FloorDiv(v.y, g.cell_voxels));
          if (!last || key != last_key) last = &g.cells[key], last_key = key;
          last->Add(v.hash);
        }
    }
  }
}

// The largest estimated map (core + margin) of the tiles `edge` voxels wide made of whole cells of
// `grid` (edge a multiple of its cell): the union of each tile's cells, plus the margin's share.
double LargestTileMap(const CellCounts& grid, std::int64_t edge, std::int64_t margin) {
  const std::int64_t n = edge / grid.cell_voxels;
  std::unordered_map<std::uint64_t, DistinctCounter> tiles;
  for (const auto& [key, counter] : grid.cells) {
    const auto [cx, cy] = detail::UnpackXY(key);
    tiles[detail::PackXY(detail::FloorDiv(cx, n), detail::FloorDiv(cy, n))].Merge(counter);
  }
  double largest = 0.0;
  for (const auto& [key, counter] : tiles) largest = std::max(largest, counter.Estimate());
  const double grown = double(edge + 2 * margin) / double(edge);
  return largest * grown * grown;
}

// The largest tile edge among TileEdgeChoices whose largest tile map is estimated within
// tiles.max_map_points (the finest when none is), from one counting pass over the scans.
void ChooseEdge(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg, int threads, TilePlan* plan) {
  const std::vector<std::int64_t> edges = TileEdgeChoices(cfg);
  std::vector<CellCounts> grids(1);
  grids[0].cell_voxels = edges[0];
  if (edges.size() > 1) grids.push_back(CellCounts{FineCellVoxels(cfg), {}});
  CountMapVoxels(keyframes, cfg, threads, &grids);
  for (std::int64_t edge : edges) {
    const CellCounts& grid = edge == edges[0] ? grids[0] : grids[1];
    plan->edge_voxels = edge;
    plan->largest_map_estimate = LargestTileMap(grid, edge, plan->margin_voxels);
    if (plan->largest_map_estimate <= double(cfg.tiles_max_map_points)) return;
  }
  spdlog::warn("tiles: the largest tile map of the finest edge ({:.1f} m) is estimated at {:.0f} points, over "
               "tiles.max_map_points {}", plan->EdgeM(), plan->largest_map_estimate, cfg.tiles_max_map_points);
}

// Each keyframe into the tiles it reaches (core + margin within reach_m); only tiles whose core
// some keyframe reaches can hold map points.
void AssignKeyframes(const std::vector<WorldKeyframe>& keyframes, TilePlan* out) {
  TilePlan& plan = *out;
  const double edge_m = plan.EdgeM(), span_m = plan.reach_m + double(plan.margin_voxels) * plan.voxel_m;
  std::map<std::pair<std::int64_t, std::int64_t>, Tile> tiles;
  for (std::size_t k = 0; k < keyframes.size(); ++k) {
    const Eigen::Vector3d c = keyframes[k].T_world_sensor.translation();
    const auto lo_x = std::int64_t(std::floor((c.x() - span_m) / edge_m)), hi_x = std::int64_t(std::floor((c.x() + span_m) / edge_m));
    const auto lo_y = std::int64_t(std::floor((c.y() - span_m) / edge_m)), hi_y = std::int64_t(std::floor((c.y() + span_m) / edge_m));
    for (std::int64_t ix = lo_x; ix <= hi_x; ++ix)
      for (std::int64_t iy = lo_y; iy <= hi_y; ++iy) {
        Tile t{ix, iy, {}};
        if (BoxOf(plan, t, plan.margin_voxels).DistanceM(plan.voxel_m, c.x(), c.y()) > plan.reach_m) continue;
        auto it = tiles.try_emplace({ix, iy}, std::move(t)).first;
        it->second.keyframes.push_back(k);
      }
  }
  for (auto& entry : tiles) {
    Tile& t = entry.second;  // a reference, not a structured binding: C++17 lambdas cannot capture those (clang)
    const bool core_reached = std::any_of(t.keyframes.begin(), t.keyframes.end(), [&](std::size_t k) {
      const Eigen::Vector3d c = keyframes[k].T_world_sensor.translation();
      return BoxOf(plan, t, 0).DistanceM(plan.voxel_m, c.x(), c.y()) <= plan.reach_m;
    });
    if (core_reached) plan.tiles.push_back(std::move(t));
  }
}

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

namespace detail {

std::vector<std::size_t> KeyframesNear(const std::vector<WorldKeyframe>& kfs, const VoxelBox& box, double voxel_m,
                                       double radius_m) {
  std::vector<std::size_t> near;
  for (std::size_t k = 0; k < kfs.size(); ++k) {
    const Eigen::Vector3d c = kfs[k].T_world_sensor.translation();
    if (box.DistanceM(voxel_m, c.x(), c.y()) <= radius_m + voxel_m) near.push_back(k);
  }
  return near;
}

std::int64_t MostEdgeVoxels(const RemovertConfig& cfg) {
  const double edge_m = cfg.tiles_edge_m > 0.0 ? cfg.tiles_edge_m : 2.0 * TileReachM(cfg);
  return std::max<std::int64_t>(1, std::int64_t(std::llround(edge_m / cfg.map_voxel_m)));
}

void MergeInVoxelOrder(std::vector<PieceSource> parts, double voxel_m, const std::function<void(const PointCloud&)>& emit) {
  using Key = std::array<std::int64_t, 3>;
  auto key = [&](const PointXYZI& p) {
    return Key{VoxelIndex(p.x, voxel_m), VoxelIndex(p.y, voxel_m), VoxelIndex(p.z, voxel_m)};
  };
  struct Head {
    Key key;
    std::size_t part, i;
    bool operator>(const Head& o) const { return key != o.key ? key > o.key : part > o.part; }
  };
  std::vector<const PointCloud*> piece_of(parts.size(), nullptr);
  auto next_piece = [&](std::size_t r) {  // the part's next non-empty piece, or null
    do piece_of[r] = parts[r]();
    while (piece_of[r] && piece_of[r]->empty());
    return piece_of[r] != nullptr;
  };
  std::vector<Head> heap;
  for (std::size_t r = 0; r < parts.size(); ++r)
    if (next_piece(r)) heap.push_back({key(piece_of[r]->points[0]), r, 0});
  const auto later = std::greater<Head>();
  std::make_heap(heap.begin(), heap.end(), later);
  PointCloud out;
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    Head& h = heap.back();
    out.points.push_back(piece_of[h.part]->points[h.i]);
    if (++h.i < piece_of[h.part]->size() || (next_piece(h.part) && (h.i = 0, true))) {
      h.key = key(piece_of[h.part]->points[h.i]);
      std::push_heap(heap.begin(), heap.end(), later);
    } else {
      heap.pop_back();
    }
    if (out.size() == kMergePiece || heap.empty()) {
      emit(out);
      out.points.clear();
    }
  }
}

void MergeInVoxelOrder(const std::vector<PointCloud>& parts, double voxel_m,
                       const std::function<void(const PointCloud&)>& emit) {
  std::vector<PieceSource> sources;
  for (const PointCloud& p : parts) sources.push_back([&p, given = false]() mutable -> const PointCloud* {
    if (given) return nullptr;
    given = true;
    return &p;
  });
  MergeInVoxelOrder(std::move(sources), voxel_m, emit);
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

bool detail::IsTileEdgeChoice(const RemovertConfig& cfg, std::int64_t edge_voxels) {
  const std::vector<std::int64_t> edges = TileEdgeChoices(cfg);
  return std::find(edges.begin(), edges.end(), edge_voxels) != edges.end();
}

std::vector<std::int64_t> TileEdgeChoices(const RemovertConfig& cfg) {
  const std::int64_t most = detail::MostEdgeVoxels(cfg);
  const std::int64_t cell = FineCellVoxels(cfg);
  std::vector<std::int64_t> edges = {most};
  for (std::int64_t n = most / cell; n >= 1; --n)
    if (n * cell < most) edges.push_back(n * cell);
  return edges;
}

TilePlan PlanTiles(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg, int threads) {
  cfg.Validate();
  TilePlan plan;
  plan.voxel_m = cfg.map_voxel_m;
  plan.edge_voxels = detail::MostEdgeVoxels(cfg);
  plan.margin_voxels = MarginVoxels(cfg);
  plan.reach_m = TileReachM(cfg) + cfg.map_voxel_m;  // + float rounding of world-frame returns
  plan.session_keyframes = keyframes.size();
  if (!keyframes.empty() && cfg.tiles_max_map_points > 0) ChooseEdge(keyframes, cfg, threads, &plan);
  AssignKeyframes(keyframes, &plan);
  return plan;
}

HdResult RemoveHdTile(const TilePlan& plan, std::size_t tile, const std::vector<WorldKeyframe>& keyframes,
                      const RemovertConfig& user_cfg, int threads) {
  const RemovertConfig cfg = WithSensor(user_cfg, keyframes, threads);
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
  const RemovertConfig cfg = keyframes.empty() ? user_cfg : WithSensor(user_cfg, keyframes, threads);
  const TilePlan plan = PlanTiles(keyframes, cfg, threads);
  TileMerger merger(plan.voxel_m);
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) merger.Add(plan.tiles[t], RemoveHdTile(plan, t, keyframes, cfg, threads));
  return merger.Finish();
}

}  // namespace ltm::removert
