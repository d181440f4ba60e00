// LD change detection tile by tile (tiles.hpp, "LD tile by tile"): the plan and DetectLdTiled.
#include "ltmapper/removert/tiles.hpp"

#include "ltmapper/removert/detail.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <utility>

namespace ltm::removert {
namespace {

// [map voxels] LdTileMarginM rounded up to whole voxels, + the centroid's voxel.
std::int64_t LdMarginVoxels(const RemovertConfig& cfg) {
  return std::int64_t(std::ceil(LdTileMarginM(cfg) / cfg.map_voxel_m)) + 1;
}

// The tile's core grown by `grow` voxels on every side.
detail::VoxelBox BoxOf(const LdTilePlan& plan, const LdTile& t, std::int64_t grow) {
  const std::int64_t e = plan.edge_voxels;
  return {t.ix * e - grow, t.iy * e - grow, (t.ix + 1) * e + grow, (t.iy + 1) * e + grow};
}

// Calls f(tx) for every tile tx, k cells wide, whose core grown by one cell holds cell c.
template <class F>
void TilesAround(std::int64_t c, std::int64_t k, F&& f) {
  for (std::int64_t t = detail::FloorDiv(c, k) - 1; t <= detail::FloorDiv(c + 1, k); ++t)
    if (t * k - 1 <= c && c < (t + 1) * k + 1) f(t);
}

// [points] The largest window (core + one cell, the margin, on every side) of tiles k cells wide.
std::size_t LargestWindow(const LdCellCounts& counts, std::int64_t k) {
  if (counts.Cells().empty()) return 0;
  std::unordered_map<std::uint64_t, std::size_t> windows;
  for (const auto& [key, n] : counts.Cells()) {
    const auto [cx, cy] = detail::UnpackXY(key);
    TilesAround(cx, k, [&, cy = cy, n = n](std::int64_t tx) {
      TilesAround(cy, k, [&](std::int64_t ty) { windows[detail::PackXY(tx, ty)] += n; });
    });
  }
  std::size_t largest = 0;
  for (const auto& [key, n] : windows) largest = std::max(largest, n);
  return largest;
}

// [cells] The tile edge: the largest whole number of cells (margins) from tiles.edge_m (or 2 x the
// reach) down to one whose largest window is within tiles.max_map_points. LD's margin is wide
// (the residue rule's clusters), so below kFinestEdgeMargins a tile labels more margin than core:
// memory holds to the bound, CPU grows.
std::int64_t ChooseEdgeCells(const LdCellCounts& counts, const RemovertConfig& cfg, std::size_t* largest) {
  const std::int64_t most = std::max<std::int64_t>(1, detail::MostEdgeVoxels(cfg) / counts.CellVoxels());
  for (std::int64_t k = most; k >= 1; --k) {
    *largest = LargestWindow(counts, k);
    if (cfg.tiles_max_map_points == 0 || *largest <= std::size_t(cfg.tiles_max_map_points)) return k;
  }
  spdlog::warn("tiles: the largest LD window of the finest edge (one margin) holds {} points, over "
               "tiles.max_map_points {}", *largest, cfg.tiles_max_map_points);
  return 1;
}

// Point indices of a map by LD cell, each list ascending.
using CellMembers = std::unordered_map<std::uint64_t, std::vector<std::uint32_t>>;
CellMembers MembersByCell(const PointCloud& map, double voxel_m, std::int64_t cell_voxels) {
  CellMembers cells;
  for (std::size_t i = 0; i < map.size(); ++i) {
    const PointXYZI& p = map.points[i];
    cells[detail::PackXY(detail::FloorDiv(detail::VoxelIndex(p.x, voxel_m), cell_voxels),
                         detail::FloorDiv(detail::VoxelIndex(p.y, voxel_m), cell_voxels))]
        .push_back(std::uint32_t(i));
  }
  return cells;
}

// The indices (ascending: map order) of the points in the tile's core + margin.
std::vector<std::uint32_t> WindowOf(const LdTilePlan& plan, const LdTile& t, const CellMembers& cells) {
  const std::int64_t k = plan.edge_voxels / plan.margin_voxels;
  std::vector<std::uint32_t> idx;
  for (std::int64_t cx = t.ix * k - 1; cx < (t.ix + 1) * k + 1; ++cx)
    for (std::int64_t cy = t.iy * k - 1; cy < (t.iy + 1) * k + 1; ++cy)
      if (auto it = cells.find(detail::PackXY(cx, cy)); it != cells.end())
        idx.insert(idx.end(), it->second.begin(), it->second.end());
  std::sort(idx.begin(), idx.end());
  return idx;
}

std::vector<WorldKeyframe> Pick(const std::vector<WorldKeyframe>& kfs, const std::vector<std::size_t>& at) {
  std::vector<WorldKeyframe> out;
  for (std::size_t k : at) out.push_back(kfs[k]);
  return out;
}

// The labels of the window's points (window[j]: map position, label[j]) that are not kLdOutside.
void KeepCore(const std::vector<std::uint32_t>& window, const std::vector<std::uint8_t>& label,
              std::vector<std::uint8_t>* out) {
  for (std::size_t j = 0; j < window.size(); ++j)
    if (label[j] != detail::kLdOutside) (*out)[window[j]] = label[j];
}

// The window's points outside the core labelled kLdOutside.
void MarkOutside(const PointCloud& window, const detail::VoxelBox& core, double voxel_m, std::vector<std::uint8_t>* label) {
  for (std::size_t j = 0; j < window.size(); ++j) {
    const PointXYZI& p = window.points[j];
    if (!core.Contains(detail::VoxelIndex(p.x, voxel_m), detail::VoxelIndex(p.y, voxel_m)))
      (*label)[j] = detail::kLdOutside;
  }
}

// [m] A residue cluster's farthest hop in xy (ResidueGapsAt at sensor.max_range_m).
double ResidueHopM(const RemovertConfig& cfg) { return double(detail::ResidueGapsAt(cfg, cfg.max_range_m).x()); }

}  // namespace

double LdWholeClusterM(const RemovertConfig& cfg) { return (LdTileMarginM(cfg) - ResidueHopM(cfg)) / std::sqrt(2.0); }

double LdTileMarginM(const RemovertConfig& cfg) {
  const double points = std::max({cfg.ld_radius_m, cfg.ld_radius_max_m, cfg.ld_normal_radius_m,
                                  detail::kSurfaceExtentTols * cfg.ld_beam.tol_m,
                                  detail::HitSurfaces::ReachM(cfg.ld_beam)});
  const double l = cfg.ld_residue_length_m;
  const double hop = ResidueHopM(cfg);
  const double clusters = l > 0.0 ? (2.0 + std::sqrt(2.0)) * l + 2.0 * hop : 0.0;
  return points + clusters;
}

LdCellCounts::LdCellCounts(const RemovertConfig& cfg) : voxel_m_(cfg.map_voxel_m), cell_voxels_(LdMarginVoxels(cfg)) {}

void LdCellCounts::Add(const PointCloud& points) {
  for (const PointXYZI& p : points.points)
    ++cells_[detail::PackXY(detail::FloorDiv(detail::VoxelIndex(p.x, voxel_m_), cell_voxels_),
                            detail::FloorDiv(detail::VoxelIndex(p.y, voxel_m_), cell_voxels_))];
}

LdTilePlan PlanLdTiles(const LdCellCounts& counts, const std::vector<WorldKeyframe>& central_keyframes,
                       const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg) {
  cfg.Validate();
  LdTilePlan plan;
  plan.voxel_m = cfg.map_voxel_m;
  plan.margin_voxels = counts.CellVoxels();
  const std::int64_t k = ChooseEdgeCells(counts, cfg, &plan.largest_window);
  plan.edge_voxels = k * plan.margin_voxels;
  std::map<std::pair<std::int64_t, std::int64_t>, LdTile> tiles;
  for (const auto& [key, n] : counts.Cells()) {
    const auto [cx, cy] = detail::UnpackXY(key);
    const std::int64_t tx = detail::FloorDiv(cx, k), ty = detail::FloorDiv(cy, k);
    tiles.try_emplace({tx, ty}, LdTile{tx, ty, {}, {}});
  }
  for (auto& [key, t] : tiles) {
    const detail::VoxelBox window = BoxOf(plan, t, plan.margin_voxels);
    t.central_voters = detail::KeyframesNear(central_keyframes, window, plan.voxel_m, cfg.max_range_m);
    t.query_voters = detail::KeyframesNear(query_keyframes, window, plan.voxel_m, cfg.max_range_m);
    plan.tiles.push_back(std::move(t));
  }
  return plan;
}

detail::VoxelBox detail::LdWindowBox(const LdTilePlan& plan, std::size_t tile) {
  return BoxOf(plan, plan.tiles.at(tile), plan.margin_voxels);
}

detail::LdLabels detail::LabelTile(const LdTilePlan& plan, std::size_t tile, const PointCloud& central_window,
                                   const PointCloud& query_window, const PointCloud& central_positions,
                                   const PointCloud& query_positions, const std::vector<WorldKeyframe>& central_keyframes,
                                   const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg,
                                   int threads) {
  const LdTile& t = plan.tiles.at(tile);
  LdLabels w = LabelLd(central_window, query_window, central_positions, query_positions,
                       Pick(central_keyframes, t.central_voters), Pick(query_keyframes, t.query_voters), cfg, threads);
  const VoxelBox core = BoxOf(plan, t, 0);
  MarkOutside(central_window, core, plan.voxel_m, &w.central);
  MarkOutside(query_window, core, plan.voxel_m, &w.query);
  return w;
}

LdResult DetectLdTile(const LdTilePlan& plan, std::size_t tile, const PointCloud& central_window,
                      const PointCloud& query_window, const std::vector<WorldKeyframe>& central_keyframes,
                      const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& user_cfg, int threads) {
  const RemovertConfig cfg = central_keyframes.empty() ? user_cfg : WithSensor(user_cfg, central_keyframes, threads);
  const auto t0 = std::chrono::steady_clock::now();
  const detail::LdLabels w =
      detail::LabelTile(plan, tile, central_window, query_window, detail::Positions(central_keyframes),
                        detail::Positions(query_keyframes), central_keyframes, query_keyframes, cfg, threads);
  LdResult res = detail::LdFromLabels(central_window, query_window, w);
  auto inside = [](const std::vector<std::uint8_t>& l) {
    return l.size() - std::size_t(std::count(l.begin(), l.end(), detail::kLdOutside));
  };
  res.stats.central_points = inside(w.central);
  res.stats.query_points = inside(w.query);
  res.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

LdResult DetectLdTiled(const PointCloud& central_map, const PointCloud& query_map,
                       const std::vector<WorldKeyframe>& central_keyframes,
                       const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& user_cfg, int threads) {
  user_cfg.Validate();
  const RemovertConfig cfg = central_keyframes.empty() ? user_cfg : WithSensor(user_cfg, central_keyframes, threads);
  const auto t0 = std::chrono::steady_clock::now();
  LdCellCounts counts(cfg);
  counts.Add(central_map);
  counts.Add(query_map);
  const LdTilePlan plan = PlanLdTiles(counts, central_keyframes, query_keyframes, cfg);
  spdlog::info("removert: LD tile by tile: {} tiles of {:.1f} m (margin {:.2f} m), largest window {} points",
               plan.tiles.size(), plan.EdgeM(), double(plan.margin_voxels) * plan.voxel_m, plan.largest_window);
  const CellMembers c_cells = MembersByCell(central_map, plan.voxel_m, plan.margin_voxels);
  const CellMembers q_cells = MembersByCell(query_map, plan.voxel_m, plan.margin_voxels);
  const PointCloud c_pos = detail::Positions(central_keyframes), q_pos = detail::Positions(query_keyframes);
  detail::LdLabels labels{std::vector<std::uint8_t>(central_map.size(), detail::kLdUnchanged),
                          std::vector<std::uint8_t>(query_map.size(), detail::kLdUnchanged)};
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    const std::vector<std::uint32_t> cw = WindowOf(plan, plan.tiles[t], c_cells), qw = WindowOf(plan, plan.tiles[t], q_cells);
    const detail::LdLabels w = detail::LabelTile(plan, t, central_map.select(cw), query_map.select(qw), c_pos, q_pos,
                                                 central_keyframes, query_keyframes, cfg, threads);
    KeepCore(cw, w.central, &labels.central);
    KeepCore(qw, w.query, &labels.query);
  }
  LdResult res = detail::LdFromLabels(central_map, query_map, labels);
  res.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace ltm::removert
