// ltmapper view: the evolving map in the browser (issue #19). A small HTTP API over a map store
// (read-only, opened per request) plus the static page in web/ (three.js). Request handling is a
// plain function (Viewer::Handle) so it is tested without sockets; the socket server
// (cpp-httplib) lives only in server.cpp. Wire formats: docs/FORMATS.md ("Viewer API").
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/map/map.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace ltm::view {

struct ViewConfig {
  std::string store;    // NAME.ltmap (opened read-only per request)
  std::string run_dir;  // OUT of `ltmapper run` (objects/, aligned/); "" = the store's folder
  std::string web_dir;  // index.html, viewer.js, three/ (the build tree's web/)
  // Level of detail: clouds are voxel-filtered at base_voxel_m, coarser when that gives more
  // than point_budget points (the voxel grows until the cloud fits). 2 M points of float32 xyz +
  // class are 26 MB to send and 0.8 s for headless chromium to fetch and split by class: the
  // demo map (3.4 M points at 0.1 m) is served at 0.136 m and its first frame comes in seconds.
  double base_voxel_m = 0.1;         // [m] finest voxel served (the maps' output_voxel_m)
  int point_budget = 2000000;        // [points] most points in one cloud response
  double max_voxel_m = 20.0;         // [m] the coarsest voxel LOD may reach
  int cache_clouds = 6;              // clouds kept in memory (slider back and forth)
  // Tiled level of detail (/api/tiles, /api/tile): the map cut into square XY tiles of tile_m
  // (rounded to whole base voxels), each served at lod_levels voxel sizes: level 0 the coarsest
  // (base_voxel_m * 2^(lod_levels-1)), the last level base_voxel_m. The page draws level 0 of
  // the whole map first, then finer levels of the tiles near the camera within point_budget.
  double tile_m = 32.0;              // [m] tile edge
  int lod_levels = 4;                // voxel levels per tile (4: 0.8, 0.4, 0.2, 0.1 m)
  // Level 0 of the whole layer holds at most this many points: while it holds more, a coarser
  // level (voxel doubled) goes in front, as long as its voxel still nests in the tiles (a 13.5 M
  // point map: 1.19 M points at 0.8 m, 0.30 M at 1.6 m; the page's first frame draws level 0).
  int coarse_budget = 500000;        // [points]
  int cache_mb = 1024;               // [MiB] tiled clouds kept in memory (at least the newest;
                                     // ~17 bytes a map point + level 0, finer levels not counted)
  int max_query_chars = 64;          // longest accepted query value [characters]
  int max_path_chars = 256;          // longest accepted request path [characters]
  int max_static_mb = 64;            // [MiB] largest static file served
  int threads = 0;                   // restore / voxel threads (0 = all cores)
  map::MapConfig map;  // meta map carving (meta_carve_radius_m); the encoding comes from the store

  template <class V>
  void Visit(V& v) {
    v("base_voxel_m", base_voxel_m, "m", 0.001, 100.0);
    v("point_budget", point_budget, "points", 1000, 100000000);
    v("max_voxel_m", max_voxel_m, "m", 0.001, 1000.0);
    v("cache_clouds", cache_clouds, "", 0, 1000);
    v("tile_m", tile_m, "m", 1.0, 100000.0);
    v("lod_levels", lod_levels, "", 1, 12);
    v("coarse_budget", coarse_budget, "points", 1, 100000000);
    v("cache_mb", cache_mb, "MiB", 1, 1000000);
    v("max_query_chars", max_query_chars, "characters", 1, 4096);
    v("max_path_chars", max_path_chars, "characters", 1, 4096);
    v("max_static_mb", max_static_mb, "MiB", 1, 4096);
  }
};

struct Request {
  std::string method = "GET";
  std::string path;                          // decoded path, e.g. "/api/cloud"
  std::map<std::string, std::string> query;  // decoded query parameters
};

struct Response {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
};

// Which cloud a request asks for: the map as of a session (rollback), the latest map, the meta
// map, the changes one session step made (Store::StepChanges: PD added, ND removed / kept), or
// the step's coverage difference: the points of the map keyframes the step created, i.e. new
// territory the reference session never observed (Store: keyframes whose session is the step).
enum class Layer { kAt, kLive, kMeta, kChanges, kCoverage };

// The coverage layer of step `session` unfiltered (world frame, cls as stored): every keyframe
// the step created, as of that step.
PointCloud CoverageCloud(const map::Store& store, int session);

// Tiled level of detail. Tile (ix, iy) holds the points whose base-voxel cell c = floor(x /
// base_voxel_m) (likewise y) lies in [ix * n, (ix + 1) * n), n = TileCells(cfg): no base voxel
// straddles two tiles, so the tiles at the finest level together are exactly the whole map
// filtered at base_voxel_m.
int TileCells(const ViewConfig& cfg);
// The voxel of a level (0 = coarsest) before coarse_budget adds levels: base_voxel_m *
// 2^(lod_levels - 1 - level). A layer's own levels come with its tile index (/api/tiles).
double LevelVoxel(const ViewConfig& cfg, int level);

// The cloud served for a layer and session: the store's map voxel-filtered at the first voxel
// (base_voxel_m, then larger) whose result fits point_budget. Equals
// store.MapAt(session, Region{voxel_m = *voxel_m}) (Live / Meta likewise; StepChanges, which
// takes no voxel, through geometry::VoxelDownsample at *voxel_m).
PointCloud ServedCloud(const map::Store& store, Layer layer, int session, const ViewConfig& cfg,
                       double* voxel_m);

// Binary cloud: "LTMC", uint32 version (1), uint32 n, float32 voxel_m, n x float32 (x, y, z),
// n x uint8 class (core PointClass), all little endian. DecodeCloud throws ltm::Error on any
// inconsistency.
std::string EncodeCloud(const PointCloud& cloud, double voxel_m);
PointCloud DecodeCloud(const std::string& bytes, double* voxel_m = nullptr);

class Viewer {
 public:
  // Checks that the store opens and web_dir holds index.html; throws ltm::Error naming the file.
  explicit Viewer(ViewConfig cfg);
  ~Viewer();
  Viewer(const Viewer&) = delete;
  Viewer& operator=(const Viewer&) = delete;

  // GET /api/info | /api/cloud?layer=at|live|meta|changes|coverage&session=N |
  // /api/tiles?layer=at|live|meta&session=N | /api/tile?layer=..&session=N&tile=IX_IY|all&level=K |
  // /api/trajectories | /api/objects, or a static file under web_dir ("/" = index.html). Bad requests -> 4xx with a message; store
  // errors -> 500 with the message. Never throws; safe to call from several threads.
  Response Handle(const Request& req) const;
  // The requests worth answering before a page asks (Handle fills the cache): the latest
  // session's tiles at level 0 (what the page opens on), then the older sessions newest first and
  // the meta map, as many as cache_clouds holds.
  std::vector<Request> WarmRequests() const;
  const ViewConfig& config() const;

 private:
  Response Route(const Request& req) const;
  Response Cloud(const Request& req) const;
  Response Tiles(const Request& req) const;
  Response Tile(const Request& req) const;
  Response Static(const Request& req) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Serves `viewer` on host:port (0 = any free port) until the process is stopped; it writes
// nothing, so a signal may end it at any time. Throws ltm::Error when the address cannot be
// bound. `on_ready(port)` runs once listening, with the bound port.
void Serve(const Viewer& viewer, const std::string& host, int port, const std::function<void(int)>& on_ready = {});

}  // namespace ltm::view
