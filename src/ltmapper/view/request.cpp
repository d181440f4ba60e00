// Request validation helpers (internal.hpp).
#include "internal.hpp"

#include <algorithm>
#include <filesystem>

namespace ltm::view {

namespace {
constexpr std::size_t kMaxSessionDigits = 9;  // fits an int; a store never holds 10^9 sessions
}  // namespace

Response Json(const nlohmann::json& j) { return {200, "application/json", j.dump()}; }

void CheckParams(const Request& req, std::initializer_list<const char*> allowed) {
  for (const auto& [k, v] : req.query)
    if (std::none_of(allowed.begin(), allowed.end(), [&k = k](const char* a) { return k == a; }))
      throw HttpError(400, "unknown query parameter '" + k + "' for " + req.path);
}

std::string Param(const Request& req, const std::string& key, const std::string& fallback) {
  const auto it = req.query.find(key);
  return it == req.query.end() ? fallback : it->second;
}

int ParseSession(const map::Store& store, const std::string& text) {
  if (text.empty()) throw HttpError(400, "session is required (an order number or a session name)");
  const auto sessions = store.Sessions();
  for (const auto& s : sessions)
    if (s.name == text) return s.order;
  const bool digits = std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (!digits) throw HttpError(404, "no session named '" + text + "' in the store");
  if (text.size() > kMaxSessionDigits) throw HttpError(400, "session number '" + text + "' is out of range");
  const int order = std::stoi(text);
  if (order > store.LatestSession())
    throw HttpError(404, "no session " + text + ": the store holds sessions 0.." + std::to_string(store.LatestSession()));
  return order;
}

std::string CheckStaticPath(const std::string& path, std::size_t max_chars) {
  if (path.size() > max_chars) throw HttpError(414, "request path too long");
  if (path.empty() || path[0] != '/') throw HttpError(400, "path must start with '/'");
  const auto ok = [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
           c == '-' || c == '/';
  };
  if (!std::all_of(path.begin(), path.end(), ok)) throw HttpError(400, "path has characters outside [A-Za-z0-9._/-]");
  std::size_t start = 1;
  while (start <= path.size()) {
    const std::size_t end = std::min(path.find('/', start), path.size());
    const std::string seg = path.substr(start, end - start);
    if (seg.empty() || seg[0] == '.') throw HttpError(400, "path segment '" + seg + "' is not allowed");
    start = end + 1;
  }
  return path.substr(1);
}

std::string ContentType(const std::string& file) {
  const std::string ext = std::filesystem::path(file).extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  return "application/octet-stream";
}

std::string RunDir(const ViewConfig& cfg) {
  if (!cfg.run_dir.empty()) return cfg.run_dir;
  const std::filesystem::path parent = std::filesystem::path(cfg.store).parent_path();
  return parent.empty() ? "." : parent.string();
}

}  // namespace ltm::view
