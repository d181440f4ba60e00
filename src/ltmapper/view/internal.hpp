// Request validation and response helpers shared by the view module's .cpp files (not public).
#pragma once

#include "ltmapper/view/view.hpp"

#include <nlohmann/json.hpp>

#include <initializer_list>
#include <stdexcept>
#include <string>

namespace ltm::view {

// A request the server refuses: HTTP status (4xx) and the message sent back.
struct HttpError : std::runtime_error {
  HttpError(int status_, const std::string& message) : std::runtime_error(message), status(status_) {}
  int status;
};

Response Json(const nlohmann::json& j);
// 400 when the request has a parameter not in `allowed`.
void CheckParams(const Request& req, std::initializer_list<const char*> allowed);
std::string Param(const Request& req, const std::string& key, const std::string& fallback);
// A session order ("2", decimal digits only) or name; 400 when malformed, 404 when the store has
// no such session.
int ParseSession(const map::Store& store, const std::string& text);
// The path of a static file below the web folder, without the leading '/': 400 for characters
// outside [A-Za-z0-9._/-], empty segments and segments starting with '.' ("..", hidden files).
std::string CheckStaticPath(const std::string& path, std::size_t max_chars);
std::string ContentType(const std::string& file);
// A layer's cloud before any voxel filter (Store::MapAt, Live, Meta, StepChanges, CoverageCloud).
PointCloud LayerCloud(const map::Store& store, Layer layer, int session);
// The run folder (objects/, aligned/): cfg.run_dir, else the store's folder.
std::string RunDir(const ViewConfig& cfg);

}  // namespace ltm::view

#include <array>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace ltm::view {

// One layer / session of the map cut into tiles (view.hpp TileCells), each tile's points in the
// map's order (so a tile's voxel centroids equal the whole map's), and the encoded tile clouds
// per level, computed on first request.
struct TiledCloud {
  using Key = std::pair<int, int>;  // (ix, iy)
  ViewConfig cfg;
  double tile_edge_m = 0.0;                       // TileCells * base_voxel_m
  std::vector<double> levels;                    // voxel per level, [0] the coarsest (LevelVoxel, then
                                                  // coarser ones in front while over coarse_budget)
  std::vector<Key> keys;                          // ascending
  std::vector<PointCloud> raw;                    // per tile: points and cls (no other arrays)
  std::vector<std::array<float, 6>> bounds;       // per tile: min x, y, z, max x, y, z
  std::vector<std::size_t> coarse_counts;         // per tile: points at level 0
  std::shared_ptr<const std::string> coarse;      // every tile at level 0, in key order, encoded
  std::size_t bytes = 0;                          // memory held (raw + encoded), for the cache

  // -1 when the map has no such tile.
  std::ptrdiff_t Find(const Key& key) const;
  // The encoded cloud of one tile at a level (cached); `points` receives its count.
  std::shared_ptr<const std::string> Encoded(std::size_t tile, int level, std::size_t* points = nullptr) const;
  // Every tile at a level, in key order (level 0: `coarse`).
  std::shared_ptr<const std::string> All(int level) const;

 private:
  // Fills the encoded cache at level 0 (per tile and `coarse`) and coarse_counts.
  void CacheLevel0(const std::vector<PointCloud>& level0);
  mutable std::mutex mutex_;
  mutable std::vector<std::vector<std::shared_ptr<const std::string>>> encoded_;  // [tile][level]
  mutable std::vector<std::vector<std::size_t>> counts_;
  friend std::shared_ptr<TiledCloud> BuildTiles(const PointCloud& raw, const ViewConfig& cfg);
};

// Cuts `raw` (cls optional) into tiles and filters every tile at level 0 (cfg.threads workers).
std::shared_ptr<TiledCloud> BuildTiles(const PointCloud& raw, const ViewConfig& cfg);
// One tile at a level: geometry::VoxelDownsample of its points at tiles.levels[level].
PointCloud TileCloud(const TiledCloud& tiles, std::size_t tile, int level);

}  // namespace ltm::view
