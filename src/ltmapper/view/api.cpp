// Viewer::Handle: validation and routing of every request, the JSON and cloud endpoints, and the
// static files. The store is opened read-only per request (SQLite WAL readers see the last
// committed transaction and never block a writer).
#include "ltmapper/view/view.hpp"

#include "internal.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <list>
#include <mutex>
#include <numeric>
#include <sstream>

namespace ltm::view {

namespace fs = std::filesystem;
using nlohmann::json;

struct Viewer::Impl {
  ViewConfig cfg;
  std::string web_root;  // canonical web_dir
  mutable std::mutex mutex;
  mutable std::list<std::pair<std::string, std::shared_ptr<const std::string>>> cache;  // most recent first
  // Tiled clouds, most recent first; one being built is shared by every request that asks for it
  // meanwhile (the page and the warm-up thread never restore the same map twice).
  struct TiledEntry {
    std::string key;
    std::shared_future<std::shared_ptr<const TiledCloud>> tiles;
    std::size_t bytes = 0;  // 0 while being built
  };
  mutable std::list<TiledEntry> tiled;

  std::shared_ptr<const std::string> Cached(const std::string& key) const;
  void Remember(const std::string& key, std::shared_ptr<const std::string> body) const;
  std::shared_ptr<const TiledCloud> Tiled(const std::string& key, const std::function<PointCloud()>& raw) const;
};

std::shared_ptr<const std::string> Viewer::Impl::Cached(const std::string& key) const {
  std::lock_guard<std::mutex> lock(mutex);
  for (auto it = cache.begin(); it != cache.end(); ++it) {
    if (it->first != key) continue;
    cache.splice(cache.begin(), cache, it);
    return it->second;
  }
  return nullptr;
}

void Viewer::Impl::Remember(const std::string& key, std::shared_ptr<const std::string> body) const {
  std::lock_guard<std::mutex> lock(mutex);
  cache.emplace_front(key, std::move(body));
  while (cache.size() > std::size_t(cfg.cache_clouds)) cache.pop_back();
}

std::shared_ptr<const TiledCloud> Viewer::Impl::Tiled(const std::string& key,
                                                     const std::function<PointCloud()>& raw) const {
  std::promise<std::shared_ptr<const TiledCloud>> promise;
  std::shared_future<std::shared_ptr<const TiledCloud>> pending;
  {
    std::lock_guard<std::mutex> lock(mutex);
    for (auto it = tiled.begin(); it != tiled.end(); ++it) {
      if (it->key != key) continue;
      tiled.splice(tiled.begin(), tiled, it);
      pending = it->tiles;
      break;
    }
    if (!pending.valid()) tiled.push_front({key, promise.get_future().share(), 0});
  }
  if (pending.valid()) return pending.get();  // cached, or being built by another request
  try {
    const auto t0 = std::chrono::steady_clock::now();
    std::shared_ptr<const TiledCloud> built = BuildTiles(raw(), cfg);
    promise.set_value(built);
    spdlog::info("view: {}: {} tiles of {:.1f} m, {} points at level 0 ({:.2f} m) in {:.2f} s", key, built->keys.size(),
                 built->tile_edge_m, std::accumulate(built->coarse_counts.begin(), built->coarse_counts.end(), std::size_t(0)),
                 built->levels.front(), std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    std::lock_guard<std::mutex> lock(mutex);
    std::size_t total = 0;
    for (auto it = tiled.begin(); it != tiled.end();) {
      if (it->key == key) it->bytes = built->bytes;
      total += it->bytes;
      const bool over = std::distance(tiled.begin(), it) >= std::max(1, cfg.cache_clouds) ||
                        total > std::size_t(cfg.cache_mb) * (std::size_t(1) << 20);
      if (it != tiled.begin() && it->bytes > 0 && over) {
        total -= it->bytes;
        it = tiled.erase(it);
      } else {
        ++it;
      }
    }
    return built;
  } catch (...) {
    promise.set_exception(std::current_exception());
    std::lock_guard<std::mutex> lock(mutex);
    tiled.remove_if([&key](const TiledEntry& e) { return e.key == key && e.bytes == 0; });
    throw;
  }
}

namespace {

map::Store OpenStore(const ViewConfig& cfg) {
  map::Store s = map::Store::Open(cfg.store, cfg.map, map::Store::Access::kReadOnly);
  s.set_threads(cfg.threads);
  return s;
}

// ------------------------------------------------------------------------------------ info
json ClassesJson() {
  json out = json::array();
  for (int c = 0; c <= int(PointClass::kNDWeak); ++c) {
    const viz::Rgb rgb = viz::ClassColor(PointClass(c));
    out.push_back({{"id", c}, {"name", ToString(PointClass(c))}, {"rgb", {rgb.r, rgb.g, rgb.b}}});
  }
  return out;
}

// The coverage layer's colour (new territory of a step): cyan, apart from every class colour.
constexpr int kCoverageRgb[3] = {40, 200, 210};

// The report's session palette (viz::SessionColor cycles through 10 colours).
json SessionColorsJson() {
  constexpr int kPalette = 10;
  json out = json::array();
  for (int k = 0; k < kPalette; ++k) {
    const viz::Rgb rgb = viz::SessionColor(k);
    out.push_back({rgb.r, rgb.g, rgb.b});
  }
  return out;
}

json SessionsJson(const map::Store& store) {
  json out = json::array();
  for (const auto& s : store.Sessions())
    out.push_back({{"order", s.order}, {"name", s.name}, {"reference", s.reference},
                   {"integrated_utc", s.integrated_utc}, {"points", s.points}, {"pd_strong", s.pd_strong},
                   {"pd_weak", s.pd_weak}, {"nd_strong", s.nd_strong}, {"keyframes_new", s.keyframes_new}});
  return out;
}

json Levels(const ViewConfig& cfg) {
  json out = json::array();
  for (int k = 0; k < cfg.lod_levels; ++k) out.push_back(LevelVoxel(cfg, k));
  return out;
}

Response Info(const ViewConfig& cfg) {
  const map::Store store = OpenStore(cfg);
  const json j = {{"store", fs::path(cfg.store).filename().string()},
                  {"sessions", SessionsJson(store)},
                  {"latest", store.LatestSession()},
                  {"classes", ClassesJson()},
                  {"session_colors", SessionColorsJson()},
                  {"coverage_rgb", {kCoverageRgb[0], kCoverageRgb[1], kCoverageRgb[2]}},
                  {"point_budget", cfg.point_budget},
                  {"max_voxel_m", cfg.max_voxel_m},
                  {"base_voxel_m", cfg.base_voxel_m},
                  {"tile_m", TileCells(cfg) * cfg.base_voxel_m},
                  {"levels", Levels(cfg)}};
  return Json(j);
}

// ---------------------------------------------------------------------------- trajectories
json Positions(const std::vector<Pose>& poses) {
  json out = json::array();
  for (const auto& T : poses) {
    const Eigen::Vector3d t = T.translation();
    out.push_back({t.x(), t.y(), t.z()});
  }
  return out;
}

// Per session: its keyframe positions from aligned/<name>/poses_world.txt when the run folder
// has them (the whole drive), else the map keyframes the session created (store only).
Response Trajectories(const ViewConfig& cfg) {
  const map::Store store = OpenStore(cfg);
  const auto keyframes = store.Keyframes();
  const std::string aligned = io::layout::AlignedDir(RunDir(cfg));
  json sessions = json::array();
  for (const auto& s : store.Sessions()) {
    const std::string file = io::layout::PosesWorldFile(aligned, s.name);
    std::vector<Pose> poses;
    std::string source = "store";
    if (fs::is_regular_file(file)) {
      poses = io::ReadKittiPoses(file);
      source = "aligned";
    } else {
      for (const auto& k : keyframes)
        if (k.session == s.order) poses.push_back(k.T_world_sensor);
    }
    sessions.push_back({{"order", s.order}, {"name", s.name}, {"source", source}, {"positions", Positions(poses)}});
  }
  return Json({{"sessions", sessions}});
}

// -------------------------------------------------------------------------------- objects
Response Objects(const ViewConfig& cfg) {
  const std::string file = io::layout::ObjectsDir(RunDir(cfg)) + "/objects.json";
  if (!fs::is_regular_file(file)) return Json({{"objects", json::array()}, {"source", nullptr}});
  std::ifstream in(file, std::ios::binary);
  json j = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object() || !j.contains("objects") || !j["objects"].is_array())
    throw Error(file + ": not an objects.json ({\"objects\": [...]})");
  return Json({{"objects", j["objects"]}, {"source", file}});
}

Layer ParseLayer(const std::string& name) {
  if (name == "at") return Layer::kAt;
  if (name == "live") return Layer::kLive;
  if (name == "meta") return Layer::kMeta;
  if (name == "changes") return Layer::kChanges;
  if (name == "coverage") return Layer::kCoverage;
  throw HttpError(400, "layer must be at, live, meta, changes or coverage (got '" + name + "')");
}

// What a cloud or tile request names: the layer, its session, and the cache key (the store's
// state is part of it: a new integration changes live and meta).
struct Target {
  Layer layer = Layer::kAt;
  std::string layer_name;
  int session = 0;
  std::string key;
};

Target ParseTarget(const Request& req, const map::Store& store, const std::string& store_path) {
  Target t;
  t.layer_name = Param(req, "layer", "at");
  t.layer = ParseLayer(t.layer_name);
  const bool by_session = t.layer == Layer::kAt || t.layer == Layer::kChanges || t.layer == Layer::kCoverage;
  t.session = by_session ? ParseSession(store, Param(req, "session", "")) : store.LatestSession();
  if (t.session < 0) throw HttpError(404, store_path + ": the store holds no session yet");
  if ((t.layer == Layer::kChanges || t.layer == Layer::kCoverage) && t.session == 0)
    throw HttpError(404, "session 0 is the map's base: no step " + t.layer_name + " (ask for session 1 or later)");
  const auto sessions = store.Sessions();
  t.key = t.layer_name + "/" + std::to_string(t.session) + "/" + std::to_string(sessions.size()) + "/" +
          sessions.back().integrated_utc;
  return t;
}

// "IX_IY" (decimal, optional '-'): 400 when malformed or beyond +-1e9.
TiledCloud::Key ParseTileId(const std::string& text) {
  constexpr std::size_t kMaxDigits = 10;
  constexpr long long kMaxIndex = 1000000000;
  const std::string bad = "tile must be all or IX_IY, two decimal tile indices (got '" + text + "')";
  const std::size_t sep = text.find('_');
  if (sep == std::string::npos) throw HttpError(400, bad);
  const auto index = [&](const std::string& part) {
    const std::size_t neg = !part.empty() && part[0] == '-' ? 1 : 0;
    const std::string digits = part.substr(neg);
    if (digits.empty() || digits.size() > kMaxDigits ||
        !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }))
      throw HttpError(400, bad);
    const long long v = std::stoll(digits);
    if (v > kMaxIndex) throw HttpError(400, "tile index '" + part + "' is out of range");
    return int(neg ? -v : v);
  };
  return {index(text.substr(0, sep)), index(text.substr(sep + 1))};
}

// A level's syntax (400); whether the layer has it is checked against its tiles (404).
int ParseLevel(const std::string& text) {
  if (text.empty()) throw HttpError(400, "level is required (0 the coarsest; /api/tiles lists the levels)");
  if (text.size() > 2 || !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; }))
    throw HttpError(400, "level must be a number of at most 2 digits (got '" + text + "')");
  return std::stoi(text);
}

std::string TileId(const TiledCloud::Key& k) { return std::to_string(k.first) + "_" + std::to_string(k.second); }

}  // namespace

// ---------------------------------------------------------------------------------- clouds
Response Viewer::Cloud(const Request& req) const {
  CheckParams(req, {"layer", "session"});
  const map::Store store = OpenStore(impl_->cfg);
  const Target t = ParseTarget(req, store, impl_->cfg.store);
  auto body = impl_->Cached(t.key);
  if (!body) {
    const auto t0 = std::chrono::steady_clock::now();
    double voxel = 0;
    const PointCloud cloud = ServedCloud(store, t.layer, t.session, impl_->cfg, &voxel);
    body = std::make_shared<const std::string>(EncodeCloud(cloud, voxel));
    impl_->Remember(t.key, body);
    spdlog::info("view: {} session {}: {} points at voxel {:.3f} m in {:.2f} s", t.layer_name, t.session, cloud.size(),
                 voxel, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return {200, "application/octet-stream", *body};
}

namespace {
void CheckTiledLayer(const Target& t) {
  if (t.layer == Layer::kChanges || t.layer == Layer::kCoverage)
    throw HttpError(400, "layer " + t.layer_name + " is not tiled: ask /api/cloud for it");
}
}  // namespace

// ----------------------------------------------------------------------------------- tiles
Response Viewer::Tiles(const Request& req) const {
  CheckParams(req, {"layer", "session"});
  const map::Store store = OpenStore(impl_->cfg);
  const Target t = ParseTarget(req, store, impl_->cfg.store);
  CheckTiledLayer(t);
  const auto tiles = impl_->Tiled(t.key, [&] { return LayerCloud(store, t.layer, t.session); });
  json list = json::array();
  std::size_t raw_total = 0, coarse_total = 0;
  for (std::size_t k = 0; k < tiles->keys.size(); ++k) {
    const auto& b = tiles->bounds[k];
    list.push_back({{"id", TileId(tiles->keys[k])}, {"ix", tiles->keys[k].first}, {"iy", tiles->keys[k].second},
                    {"lo", {b[0], b[1], b[2]}}, {"hi", {b[3], b[4], b[5]}}, {"points", tiles->raw[k].size()},
                    {"coarse", tiles->coarse_counts[k]}});
    raw_total += tiles->raw[k].size();
    coarse_total += tiles->coarse_counts[k];
  }
  return Json({{"layer", t.layer_name}, {"session", t.session}, {"tile_m", tiles->tile_edge_m},
               {"levels", tiles->levels}, {"points", raw_total}, {"coarse_points", coarse_total},
               {"tiles", list}});
}

Response Viewer::Tile(const Request& req) const {
  CheckParams(req, {"layer", "session", "tile", "level"});
  const std::string tile_text = Param(req, "tile", "");
  if (tile_text.empty()) throw HttpError(400, "tile is required (all, or IX_IY from /api/tiles)");
  const bool all = tile_text == "all";
  const TiledCloud::Key id = all ? TiledCloud::Key{0, 0} : ParseTileId(tile_text);
  const int level = ParseLevel(Param(req, "level", ""));
  const map::Store store = OpenStore(impl_->cfg);
  const Target t = ParseTarget(req, store, impl_->cfg.store);
  CheckTiledLayer(t);
  const auto tiles = impl_->Tiled(t.key, [&] { return LayerCloud(store, t.layer, t.session); });
  if (level >= int(tiles->levels.size()))
    throw HttpError(404, "no level " + std::to_string(level) + ": the levels of " + t.layer_name + " session " +
                             std::to_string(t.session) + " are 0.." + std::to_string(tiles->levels.size() - 1));
  if (all) return {200, "application/octet-stream", *tiles->All(level)};
  const std::ptrdiff_t k = tiles->Find(id);
  if (k < 0) throw HttpError(404, "no tile " + tile_text + " in " + t.layer_name + " session " + std::to_string(t.session) +
                                      " (/api/tiles lists the tiles)");
  return {200, "application/octet-stream", *tiles->Encoded(std::size_t(k), level)};
}

// ---------------------------------------------------------------------------------- static
Response Viewer::Static(const Request& req) const {
  const std::string rel = req.path == "/" ? "index.html" : CheckStaticPath(req.path, std::size_t(impl_->cfg.max_path_chars));
  const fs::path file = fs::path(impl_->web_root) / rel;
  std::error_code ec;
  const fs::path real = fs::canonical(file, ec);
  if (ec || !fs::is_regular_file(real)) throw HttpError(404, "no file '" + req.path + "'");
  const std::string real_s = real.string();
  if (real_s.compare(0, impl_->web_root.size() + 1, impl_->web_root + "/") != 0)
    throw HttpError(403, "'" + req.path + "' is outside the web folder");
  constexpr std::uintmax_t kMiB = 1u << 20;
  if (fs::file_size(real) > std::uintmax_t(impl_->cfg.max_static_mb) * kMiB)
    throw HttpError(413, "'" + req.path + "' is too large");
  std::ifstream in(real, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return {200, ContentType(rel), ss.str()};
}

// -------------------------------------------------------------------------------- routing
Viewer::Viewer(ViewConfig cfg) : impl_(std::make_unique<Impl>()) {
  if (!fs::is_regular_file(cfg.store)) throw Error(cfg.store + ": no such map store");
  (void)OpenStore(cfg);  // schema check: a wrong file fails now, not at the first request
  if (!fs::is_regular_file(fs::path(cfg.web_dir) / "index.html"))
    throw Error(cfg.web_dir + ": no index.html (the viewer's web files; built into BUILD/web)");
  ValidateConfig(cfg, "view config");
  if (cfg.max_voxel_m < cfg.base_voxel_m) throw Error("view config: max_voxel_m must be >= base_voxel_m");
  impl_->web_root = fs::canonical(cfg.web_dir).string();
  impl_->cfg = std::move(cfg);
}

Viewer::~Viewer() = default;

std::vector<Request> Viewer::WarmRequests() const {
  const int latest = OpenStore(impl_->cfg).LatestSession();
  const auto coarse = [](std::map<std::string, std::string> q) {
    q["tile"] = "all";
    q["level"] = "0";
    return Request{"GET", "/api/tile", std::move(q)};
  };
  std::vector<Request> out;
  for (int s = latest; s >= 0; --s) out.push_back(coarse({{"layer", "at"}, {"session", std::to_string(s)}}));
  if (latest >= 0) out.insert(out.begin() + std::min<std::ptrdiff_t>(2, std::ptrdiff_t(out.size())), coarse({{"layer", "meta"}}));
  if (out.size() > std::size_t(impl_->cfg.cache_clouds)) out.resize(std::size_t(impl_->cfg.cache_clouds));
  return out;
}
const ViewConfig& Viewer::config() const { return impl_->cfg; }

Response Viewer::Route(const Request& req) const {
  if (req.method != "GET" && req.method != "HEAD") throw HttpError(405, "only GET is served");
  const std::size_t max_path = std::size_t(impl_->cfg.max_path_chars), max_query = std::size_t(impl_->cfg.max_query_chars);
  if (req.path.size() > max_path) throw HttpError(414, "request path too long");
  for (const auto& [k, v] : req.query)
    if (k.size() > max_query || v.size() > max_query)
      throw HttpError(400, "query parameter '" + k.substr(0, max_query) + "' too long");
  if (req.path == "/api/cloud") return Cloud(req);
  if (req.path == "/api/tiles") return Tiles(req);
  if (req.path == "/api/tile") return Tile(req);
  CheckParams(req, {});  // no other endpoint takes parameters
  if (req.path == "/api/info") return Info(impl_->cfg);
  if (req.path == "/api/trajectories") return Trajectories(impl_->cfg);
  if (req.path == "/api/objects") return Objects(impl_->cfg);
  if (req.path.rfind("/api/", 0) == 0) throw HttpError(404, "no endpoint '" + req.path + "'");
  return Static(req);
}

Response Viewer::Handle(const Request& req) const {
  try {
    return Route(req);
  } catch (const HttpError& e) {
    return {e.status, "text/plain; charset=utf-8", std::string(e.what()) + "\n"};
  } catch (const std::exception& e) {  // store or file errors: the server's fault, not the request's
    return {500, "text/plain; charset=utf-8", std::string(e.what()) + "\n"};
  }
}

}  // namespace ltm::view
