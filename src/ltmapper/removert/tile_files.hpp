// Private to the removert module (not installed): what the plan files of HD tiles (tile_jobs.cpp)
// and of LD tiles (ld_tile_jobs.cpp) share: typed JSON members, runs of positions, the part
// folders and the merge of the parts into one file.
#pragma once

#include "ltmapper/io/json.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace ltm::removert::detail {

// The member `key` of an object, of the given type; ltm::Error naming the file otherwise.
const io::json::Value& Member(const io::json::Value& obj, const std::string& key, io::json::Value::Type type,
                              const std::string& path);
// A non-negative integer / an integer; ltm::Error naming the file and `what` otherwise.
std::size_t Count(const io::json::Value& v, const std::string& what, const std::string& path);
std::int64_t Integer(const io::json::Value& v, const std::string& what, const std::string& path);
// Ascending positions as an array `key` of runs [first, last] of consecutive ones.
void WriteRuns(io::json::Writer& w, const std::string& key, const std::vector<std::size_t>& positions);
// The positions of an array of runs: ascending, each below n; ltm::Error naming the file otherwise.
std::vector<std::size_t> ReadRuns(const io::json::Value& runs, std::size_t n, const std::string& what,
                                  const std::string& path);
// A plan folder's plan.json and config.yaml (HD and LD plans alike).
inline std::string PlanFileIn(const std::string& plan_dir) { return plan_dir + "/plan.json"; }
inline std::string ConfigFileIn(const std::string& plan_dir) { return plan_dir + "/config.yaml"; }
// Points read from a part or a merged cloud at once (16 B each).
constexpr std::size_t kReadPiece = std::size_t(1) << 14;
// A part folder's tile.json: written last, the tile is done exactly when it exists.
std::string TileJsonIn(const std::string& part_dir);
// run(tile, part_dir) for each of `tiles` (empty: all `plan_tiles` of the plan) not done (every one
// with `force`), its tile.json removed first (not done while its parts are rewritten; `run` writes
// it last); returns how many ran. A tile outside the plan is an ltm::Error naming plan.json, before
// any part folder is touched.
std::size_t RunUndoneTiles(const std::string& plan_dir, std::vector<std::size_t> tiles, std::size_t plan_tiles,
                           bool force, const std::function<void(std::size_t, const std::string&)>& run);
// Every tile of the plan done (ltm::Error naming the first missing tile.json); their tile.json paths.
std::vector<std::string> DoneTiles(const std::string& plan_dir, std::size_t tiles);
// The clouds files[t] (each in voxel order) into one PCD at `path` of `points` points in voxel
// order: tiles in plan order, columns[t] (their ix) ascending; one column at a time, each part
// read a piece at a time (memory: one piece per tile of a column).
void MergePartFiles(const std::vector<std::string>& files, const std::vector<std::int64_t>& columns, double voxel_m,
                    std::size_t points, const std::string& path);

}  // namespace ltm::removert::detail
