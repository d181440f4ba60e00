// Tile jobs from files (tiles.hpp, "from files"): the plan folder, one tile's parts, the merge.
#include "ltmapper/removert/tiles.hpp"

#include "ltmapper/removert/detail.hpp"
#include "ltmapper/removert/tile_files.hpp"

#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace ltm::removert {
namespace {

namespace fs = std::filesystem;
namespace json = io::json;
using detail::Count, detail::Integer, detail::Member;

// plan.json's version: 2 lists each tile's keyframes as runs [first, last] (1 listed every one).
constexpr int kPlanVersion = 2;

void WritePlanJson(const std::string& path, const TilePlanFile& f) {
  json::Writer w;
  w.BeginObject().String("format", "ltmapper tile plan").Int("version", kPlanVersion);
  w.String("session_dir", f.session_dir).String("poses_file", f.poses_file);
  w.String("sensor_session_dir", f.sensor_session_dir);
  w.Int("keyframes", (long long)f.plan.session_keyframes).Number("voxel_m", f.plan.voxel_m);
  w.Int("edge_voxels", f.plan.edge_voxels).Int("margin_voxels", f.plan.margin_voxels).Number("reach_m", f.plan.reach_m);
  w.Number("largest_map_estimate", f.plan.largest_map_estimate);
  w.BeginArray("tiles");
  for (const Tile& t : f.plan.tiles) {
    w.BeginObject().Int("ix", t.ix).Int("iy", t.iy);
    detail::WriteRuns(w, "keyframe_runs", t.keyframes);
    w.EndObject();
  }
  w.EndArray().EndObject();
  io::WriteFileAtomic(path, [&](std::ostream& os) { os << w.str(); });
}

// The edge and tiles of plan.json into `plan`; the margin comes from the config (PlanTiles) and
// must agree, the edge must be one the config allows (TileEdgeChoices).
void ReadTiles(const json::Value& doc, const RemovertConfig& cfg, const std::string& path, TilePlan* plan) {
  using T = json::Value::Type;
  const std::int64_t edge = Integer(Member(doc, "edge_voxels", T::kNumber, path), "edge_voxels", path);
  if (!detail::IsTileEdgeChoice(cfg, edge) ||
      Integer(Member(doc, "margin_voxels", T::kNumber, path), "margin_voxels", path) != plan->margin_voxels)
    throw Error(path, 0, "edge_voxels / margin_voxels differ from what config.yaml gives");
  plan->edge_voxels = edge;
  if (const json::Value* est = doc.Find("largest_map_estimate"); est && est->type == T::kNumber)
    plan->largest_map_estimate = est->num;
  const std::size_t n = Count(Member(doc, "keyframes", T::kNumber, path), "keyframes", path);
  for (const json::Value& jt : Member(doc, "tiles", T::kArray, path).arr) {
    Tile t;
    t.ix = Integer(Member(jt, "ix", T::kNumber, path), "ix", path);
    t.iy = Integer(Member(jt, "iy", T::kNumber, path), "iy", path);
    t.keyframes = detail::ReadRuns(Member(jt, "keyframe_runs", T::kArray, path), n, "a tile's keyframe", path);
    plan->tiles.push_back(std::move(t));
  }
}

void WriteStats(json::Writer& w, const HdStats& st) {
  w.Int("map_points", (long long)st.map_points).Int("candidates", (long long)st.candidates);
  w.Int("reverted", (long long)st.reverted).Int("removed", (long long)st.removed).Int("dilated", (long long)st.dilated);
  w.BeginArray("removed_per_resolution");
  for (std::size_t c : st.removed_per_resolution) w.Number(double(c));
  w.EndArray().Number("seconds_map", st.seconds_map).Number("seconds_votes", st.seconds_votes);
}

HdStats ReadStats(const std::string& path) {
  using T = json::Value::Type;
  const json::Value doc = json::ParseFile(path);
  auto count = [&](const char* key) { return Count(Member(doc, key, T::kNumber, path), key, path); };
  HdStats st;
  st.map_points = count("map_points");
  st.candidates = count("candidates");
  st.reverted = count("reverted");
  st.removed = count("removed");
  st.dilated = count("dilated");
  for (const json::Value& c : Member(doc, "removed_per_resolution", T::kArray, path).arr)
    st.removed_per_resolution.push_back(Count(c, "removed_per_resolution", path));
  st.seconds_map = Member(doc, "seconds_map", T::kNumber, path).num;
  st.seconds_votes = Member(doc, "seconds_votes", T::kNumber, path).num;
  return st;
}

void WriteStatsJson(const std::string& path, const HdStats& st, std::size_t tiles) {
  json::Writer w;
  w.BeginObject().Int("tiles", (long long)tiles);
  WriteStats(w, st);
  w.EndObject();
  io::WriteFileAtomic(path, [&](std::ostream& os) { os << w.str(); });
}

// One map of every tile (`file_in` of its part folder) into `path`, in voxel order.
void MergeMapFile(const std::string& plan_dir, const TilePlan& plan, std::string (*file_in)(const std::string&),
                  std::size_t points, const std::string& path) {
  std::vector<std::string> files;
  std::vector<std::int64_t> columns;
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    files.push_back(file_in(TilePartDir(plan_dir, t)));
    columns.push_back(plan.tiles[t].ix);
  }
  detail::MergePartFiles(files, columns, plan.voxel_m, points, path);
}

std::string Absolute(const std::string& path) { return path.empty() ? path : fs::absolute(path).lexically_normal().string(); }

}  // namespace

TilePlan WriteTilePlan(const std::string& plan_dir, const std::string& session_dir, const std::string& poses_file,
                       const RemovertConfig& cfg, int threads, const std::string& sensor_session_dir) {
  cfg.Validate();
  TilePlanFile f{Absolute(session_dir), Absolute(poses_file), Absolute(sensor_session_dir), cfg, {}};
  f.plan = PlanTiles(LoadWorldKeyframes(f.session_dir, f.poses_file), cfg, threads);
  io::StagingDir staging(plan_dir, "plan.json");
  io::SaveConfigFields(detail::ConfigFileIn(staging.path()), FieldsOf(f.cfg));
  WritePlanJson(detail::PlanFileIn(staging.path()), f);
  staging.Publish();
  return f.plan;
}

TilePlanFile ReadTilePlan(const std::string& plan_dir) {
  using T = json::Value::Type;
  const std::string path = detail::PlanFileIn(plan_dir);
  const json::Value doc = json::ParseFile(path);
  if (Member(doc, "format", T::kString, path).str != "ltmapper tile plan")
    throw Error(path, 0, "not a tile plan (format is not 'ltmapper tile plan')");
  if (Integer(Member(doc, "version", T::kNumber, path), "version", path) != kPlanVersion)
    throw Error(path, 0, "a tile plan of another version (this build reads version " + std::to_string(kPlanVersion) +
                                 "): plan the tiles again");
  TilePlanFile f;
  io::LoadConfig(detail::ConfigFileIn(plan_dir), f.cfg);
  f.cfg.Validate(detail::ConfigFileIn(plan_dir));
  f.session_dir = Member(doc, "session_dir", T::kString, path).str;
  f.poses_file = Member(doc, "poses_file", T::kString, path).str;
  if (doc.Find("sensor_session_dir"))  // optional: plans without it take the sensor from their session
    f.sensor_session_dir = Member(doc, "sensor_session_dir", T::kString, path).str;
  f.plan = PlanTiles({}, f.cfg);
  f.plan.session_keyframes = Count(Member(doc, "keyframes", T::kNumber, path), "keyframes", path);
  ReadTiles(doc, f.cfg, path, &f.plan);
  return f;
}

std::string TilePartDir(const std::string& plan_dir, std::size_t tile) {
  std::ostringstream name;
  name << plan_dir << "/parts/tile_" << std::setw(6) << std::setfill('0') << tile;
  return name.str();
}

std::size_t RunTileJobs(const std::string& plan_dir, std::vector<std::size_t> tiles, int threads, bool force) {
  const TilePlanFile f = ReadTilePlan(plan_dir);
  // The session and the sensor once for every tile.
  const std::vector<WorldKeyframe> kfs = LoadWorldKeyframes(f.session_dir, f.poses_file);
  const RemovertConfig cfg = WithSensor(
      f.cfg, f.sensor_session_dir.empty() ? kfs : LoadWorldKeyframes(f.sensor_session_dir, ""), threads);
  return detail::RunUndoneTiles(plan_dir, std::move(tiles), f.plan.tiles.size(), force, [&](std::size_t tile,
                                                                                          const std::string& dir) {
    const HdResult res = RemoveHdTile(f.plan, tile, kfs, cfg, threads);
    io::WritePcd(io::layout::StaticMapIn(dir), res.static_map);
    io::WritePcd(io::layout::HdMapIn(dir), res.hd_map);
    WriteStatsJson(detail::TileJsonIn(dir), res.stats, 1);  // last: the tile is done
    spdlog::info("tiles: tile {} of {}: {} keyframes, {} static + {} HD points", tile, f.plan.tiles.size(),
                 f.plan.tiles[tile].keyframes.size(), res.static_map.size(), res.hd_map.size());
  });
}

bool RunTileJob(const std::string& plan_dir, std::size_t tile, int threads, bool force) {
  return RunTileJobs(plan_dir, {tile}, threads, force) == 1;
}

HdStats MergeTileJobs(const std::string& plan_dir, const std::string& out_dir) {
  const TilePlanFile f = ReadTilePlan(plan_dir);
  HdStats st;
  for (const std::string& done : detail::DoneTiles(plan_dir, f.plan.tiles.size()))  // before writing anything
    detail::AddHdStats(ReadStats(done), &st);
  io::StagingDir staging(out_dir, "report.json");
  const std::size_t hd = st.removed + st.dilated;
  MergeMapFile(plan_dir, f.plan, io::layout::StaticMapIn, st.map_points - hd, io::layout::StaticMapIn(staging.path()));
  MergeMapFile(plan_dir, f.plan, io::layout::HdMapIn, hd, io::layout::HdMapIn(staging.path()));
  WriteStatsJson(staging.path() + "/report.json", st, f.plan.tiles.size());
  staging.Publish();
  return st;
}


namespace detail {

std::string TileJsonIn(const std::string& part_dir) { return part_dir + "/tile.json"; }


// The member `key` of an object, of the given type; ltm::Error naming the file otherwise.
const json::Value& Member(const json::Value& obj, const std::string& key, json::Value::Type type,
                          const std::string& path) {
  const json::Value* v = obj.Find(key);
  if (!v || v->type != type) throw Error(path, 0, "missing or mistyped key '" + key + "'");
  return *v;
}
// A non-negative integer member.
std::size_t Count(const json::Value& v, const std::string& what, const std::string& path) {
  if (v.type != json::Value::Type::kNumber || !(v.num >= 0) || v.num != std::floor(v.num) || v.num > 9e15)
    throw Error(path, 0, what + " must be a non-negative integer");
  return std::size_t(v.num);
}
std::int64_t Integer(const json::Value& v, const std::string& what, const std::string& path) {
  if (v.type != json::Value::Type::kNumber || v.num != std::floor(v.num) || std::fabs(v.num) > 9e15)
    throw Error(path, 0, what + " must be an integer");
  return std::int64_t(v.num);
}

void WriteRuns(json::Writer& w, const std::string& key, const std::vector<std::size_t>& positions) {
  w.BeginArray(key);
  for (std::size_t b = 0, e = 0; b < positions.size(); b = e) {  // [first, last] of consecutive positions
    for (e = b + 1; e < positions.size() && positions[e] == positions[e - 1] + 1; ++e) {}
    w.BeginArray().Number(double(positions[b])).Number(double(positions[e - 1])).EndArray();
  }
  w.EndArray();
}

std::vector<std::size_t> ReadRuns(const json::Value& runs, std::size_t n, const std::string& what,
                                  const std::string& path) {
  using T = json::Value::Type;
  std::vector<std::size_t> out;
  for (const json::Value& run : runs.arr) {
    if (run.type != T::kArray || run.arr.size() != 2) throw Error(path, 0, what + " run must be [first, last]");
    const std::size_t first = Count(run.arr[0], what, path), last = Count(run.arr[1], what, path);
    if (last >= n || first > last || (!out.empty() && first <= out.back()))
      throw Error(path, 0, what + " runs must ascend below " + std::to_string(n));
    for (std::size_t k = first; k <= last; ++k) out.push_back(k);
  }
  return out;
}

std::size_t RunUndoneTiles(const std::string& plan_dir, std::vector<std::size_t> tiles, std::size_t plan_tiles,
                           bool force, const std::function<void(std::size_t, const std::string&)>& run) {
  if (tiles.empty())
    for (std::size_t t = 0; t < plan_tiles; ++t) tiles.push_back(t);
  for (std::size_t tile : tiles)
    if (tile >= plan_tiles)
      throw Error(PlanFileIn(plan_dir), 0,
                  "no tile " + std::to_string(tile) + " in it (tile " + std::to_string(tile) + " of a plan with " +
                      std::to_string(plan_tiles) + " tiles)");
  std::size_t ran = 0;
  for (std::size_t tile : tiles) {
    const std::string dir = TilePartDir(plan_dir, tile);
    if (!force && fs::exists(TileJsonIn(dir))) {
      spdlog::info("tiles: tile {} is done ({})", tile, TileJsonIn(dir));
      continue;
    }
    fs::remove(TileJsonIn(dir));
    io::MakeDirs(dir);
    run(tile, dir);
    ++ran;
  }
  return ran;
}

std::vector<std::string> DoneTiles(const std::string& plan_dir, std::size_t tiles) {
  std::vector<std::string> done;
  for (std::size_t t = 0; t < tiles; ++t) {
    done.push_back(TileJsonIn(TilePartDir(plan_dir, t)));
    if (!fs::exists(done.back())) throw Error(done.back(), 0, "tile " + std::to_string(t) + " is not done");
  }
  return done;
}

void MergePartFiles(const std::vector<std::string>& files, const std::vector<std::int64_t>& columns, double voxel_m,
                    std::size_t points, const std::string& path) {
  io::WritePcdPieces(path, points, [&](const auto& write) {
    for (std::size_t b = 0, e = 0; b < files.size(); b = e) {
      std::vector<io::PcdPieceReader> readers;
      for (e = b; e < files.size() && columns[e] == columns[b]; ++e) readers.emplace_back(files[e]);
      std::vector<PointCloud> pieces(readers.size());
      std::vector<PieceSource> column;
      for (std::size_t t = 0; t < readers.size(); ++t)
        column.push_back([&, t]() -> const PointCloud* {
          return readers[t].Next(kReadPiece, &pieces[t]) ? &pieces[t] : nullptr;
        });
      MergeInVoxelOrder(std::move(column), voxel_m, write);
    }
  });
}

}  // namespace detail

}  // namespace ltm::removert
