// Viewer::Handle: validation and routing of every request, the JSON and cloud endpoints, and the
// static files. The store is opened read-only per request (SQLite WAL readers see the last
// committed transaction and never block a writer).
#include "ltmapper/view/view.hpp"

#include "internal.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <list>
#include <mutex>
#include <sstream>

namespace ltm::view {

namespace fs = std::filesystem;
using nlohmann::json;

struct Viewer::Impl {
  ViewConfig cfg;
  std::string web_root;  // canonical web_dir
  mutable std::mutex mutex;
  mutable std::list<std::pair<std::string, std::shared_ptr<const std::string>>> cache;  // most recent first

  std::shared_ptr<const std::string> Cached(const std::string& key) const;
  void Remember(const std::string& key, std::shared_ptr<const std::string> body) const;
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

Response Info(const ViewConfig& cfg) {
  const map::Store store = OpenStore(cfg);
  const json j = {{"store", fs::path(cfg.store).filename().string()},
                  {"sessions", SessionsJson(store)},
                  {"latest", store.LatestSession()},
                  {"classes", ClassesJson()},
                  {"session_colors", SessionColorsJson()},
                  {"point_budget", cfg.point_budget},
                  {"max_voxel_m", cfg.max_voxel_m},
                  {"base_voxel_m", cfg.base_voxel_m}};
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
  throw HttpError(400, "layer must be at, live, meta or changes (got '" + name + "')");
}

}  // namespace

// ---------------------------------------------------------------------------------- clouds
Response Viewer::Cloud(const Request& req) const {
  CheckParams(req, {"layer", "session"});
  const std::string layer_name = Param(req, "layer", "at");
  const Layer layer = ParseLayer(layer_name);
  const map::Store store = OpenStore(impl_->cfg);
  const bool by_session = layer == Layer::kAt || layer == Layer::kChanges;
  const int session = by_session ? ParseSession(store, Param(req, "session", "")) : store.LatestSession();
  if (session < 0) throw HttpError(404, impl_->cfg.store + ": the store holds no session yet");
  if (layer == Layer::kChanges && session == 0)
    throw HttpError(404, "session 0 is the map's base: no step changes (ask for session 1 or later)");
  // The state of the store is part of the key: a new integration changes live and meta.
  const auto sessions = store.Sessions();
  const std::string key = layer_name + "/" + std::to_string(session) + "/" + std::to_string(sessions.size()) + "/" +
                          sessions.back().integrated_utc;
  auto body = impl_->Cached(key);
  if (!body) {
    const auto t0 = std::chrono::steady_clock::now();
    double voxel = 0;
    const PointCloud cloud = ServedCloud(store, layer, session, impl_->cfg, &voxel);
    body = std::make_shared<const std::string>(EncodeCloud(cloud, voxel));
    impl_->Remember(key, body);
    spdlog::info("view: {} session {}: {} points at voxel {:.3f} m in {:.2f} s", layer_name, session, cloud.size(),
                 voxel, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return {200, "application/octet-stream", *body};
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
  std::vector<Request> out;
  for (int s = latest; s >= 0; --s) out.push_back({"GET", "/api/cloud", {{"layer", "at"}, {"session", std::to_string(s)}}});
  if (latest >= 0) out.insert(out.begin() + std::min<std::ptrdiff_t>(2, std::ptrdiff_t(out.size())),
                              Request{"GET", "/api/cloud", {{"layer", "meta"}}});
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
