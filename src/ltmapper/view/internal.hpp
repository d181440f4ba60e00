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
// The run folder (objects/, aligned/): cfg.run_dir, else the store's folder.
std::string RunDir(const ViewConfig& cfg);

}  // namespace ltm::view
