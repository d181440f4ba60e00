// ltmapper removert: HD removal tile by tile, with memory bounded by the tile (issue #18).
//
// The world's xy plane is cut into square tiles of whole map voxels (tiles.edge_m). A map point
// belongs to the tile whose core holds its voxel. Its HD decision (hd.hpp) reads only
//  - the keyframes within TileReachM of it: its voxel holds returns of keyframes within
//    sensor.max_range_m, and keyframes within submap_radius_m vote on it;
//  - the map points within TileMarginM of it (per axis in xy): the normals of removal candidates
//    and the dilation of removed points around it (TileMarginM lists the terms).
// A tile's job builds the map of the keyframes that reach its core plus margin, clipped to that
// box (the session map's voxels, bit for bit: detail::BuildMap), decides HD on it and keeps the
// points of its core. MergeTiles concatenates the cores in voxel order: RemoveHd's maps.
#pragma once

#include "ltmapper/removert/hd.hpp"
#include "ltmapper/removert/ld.hpp"

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

namespace ltm::removert {

struct Tile {
  std::int64_t ix = 0, iy = 0;         // core: voxels [ix, ix + 1) x [iy, iy + 1) tile edges
  std::vector<std::size_t> keyframes;  // session positions of the keyframes that reach it, ascending
};
struct TilePlan {
  double voxel_m = 0.0;              // [m] map voxel (map_voxel_m)
  std::int64_t edge_voxels = 0;      // tile edge [map voxels]: one of TileEdgeChoices
  double largest_map_estimate = 0.0; // [points] the largest tile's map (core + margin), estimated; 0 = not estimated
  std::int64_t margin_voxels = 0;    // margin around the core [map voxels]
  double reach_m = 0.0;              // [m] keyframes this close (xy) to core + margin belong to the tile
  std::size_t session_keyframes = 0;
  std::vector<Tile> tiles;           // by (ix, iy); only tiles whose core some keyframe reaches
  double EdgeM() const { return double(edge_voxels) * voxel_m; }
};

// [m] How far (xy) a keyframe can affect a map point: max(sensor.max_range_m, submap_radius_m).
double TileReachM(const RemovertConfig& cfg);
// [m] How far (per xy axis) the map points that can change a map point's HD decision lie: the
// largest of (a) a removed point within one voxel (dilation) plus that point's normal
// neighbourhood (ld.normal_radius_m, revert surface hits); (b) a removed body's point within
// hd.dilate_voxels voxels, a body by another removed point within hd.dilate_body_m, plus its
// normal neighbourhood; (c) the local ground of the groundward dilation: cells of hd.dilate_voxels
// voxels, the 3 x 3 cells around the point and around a body's foot up to one cell away (3 cells).
double TileMarginM(const RemovertConfig& cfg);
// [map voxels] The tile edges a plan may have, largest first: tiles.edge_m (0: 2 x the reach),
// then the whole multiples of the finest edge (5 margins: the margin's area stays below the
// core's) below it.
std::vector<std::int64_t> TileEdgeChoices(const RemovertConfig& cfg);
// The tiles of a session (keyframes placed in the world) and the keyframes each reads. With
// tiles.max_map_points > 0, one pass over the scans counts the distinct map voxels per cell of the
// finest edge (DistinctCounter: ~3 % error, ~1 KB a cell) and the plan takes the largest edge of
// TileEdgeChoices whose largest tile map (core + margin) is estimated within it: a job's memory
// follows the bound, not the session (more tiles read the same keyframes where maps are dense).
TilePlan PlanTiles(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg, int threads = 0);
// HD removal of one tile: the static and HD points of its core, stats of its core's points.
// `keyframes` is the whole session (its scans are read only for the tile's keyframes and for the
// sensor estimate, as RemoveHd does); the plan must be PlanTiles' for them and `cfg`.
HdResult RemoveHdTile(const TilePlan& plan, std::size_t tile, const std::vector<WorldKeyframe>& keyframes,
                      const RemovertConfig& cfg, int threads = 0);
// The tiles' results as one: the maps in voxel order (RemoveHd's order), the stats summed. Tiles
// are added in plan order (by ix, then iy); a column of tiles (one ix) holds a contiguous range of
// x voxels, so each column is sorted alone and appended: memory = the merged maps + one column.
class TileMerger {
 public:
  explicit TileMerger(double voxel_m) : voxel_m_(voxel_m) {}
  void Add(const Tile& tile, HdResult part);
  HdResult Finish();

 private:
  void FlushColumn();
  double voxel_m_;
  std::int64_t column_ = 0;
  bool started_ = false;
  std::vector<HdResult> pending_;  // the current column's parts
  HdResult out_;
};
// TileMerger over every tile: parts[t] is the result of plan.tiles[t] (computed in any order).
HdResult MergeTiles(const TilePlan& plan, std::vector<HdResult> parts);
// PlanTiles, every tile in turn (each on `threads`), MergeTiles: RemoveHd with the memory of a tile.
HdResult RemoveHdTiled(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg, int threads = 0);

// ---- LD tile by tile (ld_tiles.cpp)
// A point's LD label (DetectLd) reads (a) the other map within ld.radius_max_m and its own map
// within ld.normal_radius_m and 10 ld.beam_tol_m (its surface's extent, detail::kSurfaceExtentTols); (b) with residues on, the clusters of seen-through changes near it:
// a cluster that fits a mover (ld.residue_length_m L across, its box's diagonal >= its xy span) and
// touches a core lies within L of it, the larger clusters that unmark it within 2 L, their ground
// within 3 L; a cluster cut by the window's edge reaches from there to the edge, so with
// (2 + sqrt 2) L + 2 hops (a hop: ld.residue_gap_m, far out the sensor's column gap at
// sensor.max_range_m, detail::ResidueGapsAt) it is no mover's in the window as in truth. The margin is
// (a) + (b).
double LdTileMarginM(const RemovertConfig& cfg);
// [m] The longest residue cluster (longest horizontal edge) a tile's window holds whole wherever it
// touches the core: (LdTileMarginM - a hop) / sqrt 2. Shorter, its xy span is under the margin less
// a hop; one the window cuts reaches to within a hop of the window's edge, so is longer there. The
// rules that judge a cluster as a whole (detail::Residues' trails) judge only those.
double LdWholeClusterM(const RemovertConfig& cfg);
struct LdTile {
  std::int64_t ix = 0, iy = 0;  // core: voxels [ix, ix + 1) x [iy, iy + 1) tile edges
  // positions of the keyframes within sensor.max_range_m of core + margin (they judge occlusion)
  std::vector<std::size_t> central_voters, query_voters;
};
struct LdTilePlan {
  double voxel_m = 0.0;           // [m] map voxel (map_voxel_m)
  std::int64_t edge_voxels = 0;   // tile edge [map voxels]: a whole number of margins
  std::int64_t margin_voxels = 0; // [map voxels] LdTileMarginM rounded up, + the centroid's voxel
  std::size_t largest_window = 0; // [points] both maps in the largest tile's core + margin
  std::vector<LdTile> tiles;      // by (ix, iy); the tiles whose core holds map points
  double EdgeM() const { return double(edge_voxels) * voxel_m; }
};
// Map points per cell of one LD margin, of both maps (counted in memory or streamed from files).
class LdCellCounts {
 public:
  explicit LdCellCounts(const RemovertConfig& cfg);
  void Add(const PointCloud& points);
  std::int64_t CellVoxels() const { return cell_voxels_; }
  const std::unordered_map<std::uint64_t, std::size_t>& Cells() const { return cells_; }

 private:
  double voxel_m_;
  std::int64_t cell_voxels_;
  std::unordered_map<std::uint64_t, std::size_t> cells_;  // points by xy cell
};
// The LD tiles of a pair: the largest edge (tiles.edge_m or 2 x the reach, then every whole number
// of margins down to one) whose largest window (both maps' points in core + margin, counted
// exactly) holds at most tiles.max_map_points (0: the largest edge), and each tile's voters.
LdTilePlan PlanLdTiles(const LdCellCounts& counts, const std::vector<WorldKeyframe>& central_keyframes,
                       const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg);
// One LD tile: DetectLd's clouds of the points in its core (in window order), given each map's
// points in its core + margin (in map order) and the whole sessions' keyframes; stats of the core.
LdResult DetectLdTile(const LdTilePlan& plan, std::size_t tile, const PointCloud& central_window,
                      const PointCloud& query_window, const std::vector<WorldKeyframe>& central_keyframes,
                      const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg, int threads = 0);
// DetectLd tile by tile: each tile labels the maps' points in its core + margin against its voters
// and keeps its core's labels; the same clouds, stats and central_nd as DetectLd (seconds: the
// whole call). Memory: the maps (given whole) and one tile's window.
LdResult DetectLdTiled(const PointCloud& central_map, const PointCloud& query_map,
                       const std::vector<WorldKeyframe>& central_keyframes,
                       const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg, int threads = 0);

// ---- from files: `ltmapper tiles` and the Dask driver (python/ltmapper_dask.py)
// A plan folder holds plan.json (session folder, pose file, tiles with their keyframes) and
// config.yaml (the params). A tile's job writes <plan>/parts/tile_NNNNNN/: static_map.pcd,
// hd_map.pcd, then tile.json (its stats), each to a temporary name renamed into place. A tile is
// done exactly when its tile.json exists: a killed job leaves none and is simply run again.
struct TilePlanFile {
  std::string session_dir, poses_file;  // poses_file "": the session's own poses
  std::string sensor_session_dir;       // the session whose scans give the sensor ("": this one)
  RemovertConfig cfg;
  TilePlan plan;
};
// Plans the session's tiles into a fresh `plan_dir` (replaced whole when it holds a plan.json;
// any other non-empty folder is an error naming it). Returns the plan. `sensor_session_dir`: the
// session whose scans give the sensor model when it is estimated (the stage's central; "": this).
TilePlan WriteTilePlan(const std::string& plan_dir, const std::string& session_dir, const std::string& poses_file,
                       const RemovertConfig& cfg, int threads = 0, const std::string& sensor_session_dir = "");
// ltm::Error naming the file when plan.json or config.yaml is missing or malformed.
TilePlanFile ReadTilePlan(const std::string& plan_dir);
std::string TilePartDir(const std::string& plan_dir, std::size_t tile);
// One tile's job; skipped (false) when its tile.json exists, unless `force`.
bool RunTileJob(const std::string& plan_dir, std::size_t tile, int threads = 0, bool force = false);
// The jobs of `tiles` (empty: every tile) one after another, the plan, session and sensor read once;
// returns how many ran (the others were done).
std::size_t RunTileJobs(const std::string& plan_dir, std::vector<std::size_t> tiles, int threads = 0,
                        bool force = false);
// Every tile's parts merged (MergeTiles) into out_dir: static_map.pcd, hd_map.pcd, report.json.
// ltm::Error naming the tile.json of the first tile not done.
HdStats MergeTileJobs(const std::string& plan_dir, const std::string& out_dir);

// ---- LD from files: a pair's LD tiles over its sessions' HD tile plans (ld_tile_jobs.cpp)
// The pair's sessions are planned and run tile by tile first (`tiles plan` + `tiles run`, one
// config for both). An LD plan folder holds plan.json (the two HD plan folders, the LD tiles and
// their voters) and config.yaml (the central plan's). An LD tile's job reads its window from the
// HD tiles' parts (static_map.pcd of the HD tiles whose core meets it; memory: the window) and
// writes <plan>/parts/tile_NNNNNN/ with the pair's clouds (nd_strong, nd_weak, pd_strong, pd_weak,
// pd_unobserved, nd_residue, pd_residue .pcd), then tile.json; the merge writes those clouds
// (RunRemovertStage's pair files, bit for bit) and report.json.
struct LdTilePlanFile {
  std::string central_plan, query_plan;  // HD tile plan folders (absolute)
  RemovertConfig cfg;
  LdTilePlan plan;
};
// Plans the pair's LD tiles into a fresh `plan_dir` from one pass over the HD parts of both
// sessions (every HD tile must be done; their configs must be equal: ltm::Error naming the file).
LdTilePlan WriteLdTilePlan(const std::string& plan_dir, const std::string& central_plan_dir,
                           const std::string& query_plan_dir);
// Whether `plan_dir` holds an LD tile plan (else, e.g., an HD tile plan).
bool IsLdTilePlan(const std::string& plan_dir);
LdTilePlanFile ReadLdTilePlan(const std::string& plan_dir);
// One LD tile's job; skipped (false) when its tile.json exists, unless `force`.
bool RunLdTileJob(const std::string& plan_dir, std::size_t tile, int threads = 0, bool force = false);
// The LD jobs of `tiles` (empty: every tile), the plans, sessions and sensor read once; how many ran.
std::size_t RunLdTileJobs(const std::string& plan_dir, std::vector<std::size_t> tiles, int threads = 0,
                          bool force = false);
// Every LD tile's parts merged into out_dir; ltm::Error naming the tile.json of the first tile not done.
LdStats MergeLdTileJobs(const std::string& plan_dir, const std::string& out_dir);

}  // namespace ltm::removert
