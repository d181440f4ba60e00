// LD tile jobs from files (tiles.hpp, "LD from files"): a pair's LD plan over the sessions' HD
// tile plans, one LD tile's parts (its window read from the HD tiles' parts), the merge.
#include "ltmapper/removert/tiles.hpp"

#include "ltmapper/removert/detail.hpp"
#include "ltmapper/removert/tile_files.hpp"

#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace ltm::removert {
namespace {

namespace fs = std::filesystem;
namespace json = io::json;
using detail::Count, detail::Integer, detail::Member;

constexpr const char* kLdPlanFormat = "ltmapper LD tile plan";
constexpr int kLdPlanVersion = 1;


// The pair's clouds: a tile's part files, the merge's output files (the stage's pair files).
struct LdCloud {
  const char* file;
  PointCloud LdResult::*cloud;
  std::size_t LdStats::*count;
};
constexpr LdCloud kLdClouds[] = {
    {"nd_strong.pcd", &LdResult::nd_strong, &LdStats::nd_strong},
    {"nd_weak.pcd", &LdResult::nd_weak, &LdStats::nd_weak},
    {"pd_strong.pcd", &LdResult::pd_strong, &LdStats::pd_strong},
    {"pd_weak.pcd", &LdResult::pd_weak, &LdStats::pd_weak},
    {"pd_unobserved.pcd", &LdResult::pd_unobserved, &LdStats::pd_unobserved},
    {"nd_residue.pcd", &LdResult::nd_residue, &LdStats::nd_residue},
    {"pd_residue.pcd", &LdResult::pd_residue, &LdStats::pd_residue},
};
// LdStats' counts by their JSON keys.
constexpr std::pair<const char*, std::size_t LdStats::*> kLdCounts[] = {
    {"central_points", &LdStats::central_points}, {"query_points", &LdStats::query_points},
    {"nd_strong", &LdStats::nd_strong},           {"nd_weak", &LdStats::nd_weak},
    {"pd_strong", &LdStats::pd_strong},           {"pd_weak", &LdStats::pd_weak},
    {"pd_unobserved", &LdStats::pd_unobserved},   {"nd_unobserved", &LdStats::nd_unobserved},
    {"pd_same", &LdStats::pd_same},               {"nd_same", &LdStats::nd_same},
    {"nd_residue", &LdStats::nd_residue},         {"pd_residue", &LdStats::pd_residue},
};

void WriteLdStatsJson(const std::string& path, const LdStats& st, std::size_t tiles) {
  json::Writer w;
  w.BeginObject().Int("tiles", (long long)tiles);
  for (const auto& [key, count] : kLdCounts) w.Int(key, (long long)(st.*count));
  w.Number("seconds", st.seconds).EndObject();
  io::WriteFileAtomic(path, [&](std::ostream& os) { os << w.str(); });
}

void AddLdStatsJson(const std::string& path, LdStats* sum) {
  const json::Value doc = json::ParseFile(path);
  for (const auto& [key, count] : kLdCounts)
    sum->*count += Count(Member(doc, key, json::Value::Type::kNumber, path), key, path);
  sum->seconds += Member(doc, "seconds", json::Value::Type::kNumber, path).num;
}

// The HD tiles' parts (static_map.pcd) of a session's plan whose core meets `box` (null: all),
// each read a piece at a time, keeping the points in the box (null: all): f(piece).
template <class F>
void ForHdParts(const std::string& hd_plan_dir, const TilePlan& hd, const detail::VoxelBox* box, F&& f) {
  const std::int64_t e = hd.edge_voxels;
  PointCloud piece, kept;
  for (std::size_t t = 0; t < hd.tiles.size(); ++t) {
    const Tile& tile = hd.tiles[t];
    if (box && (tile.ix * e >= box->x1 || (tile.ix + 1) * e <= box->x0 || tile.iy * e >= box->y1 ||
                (tile.iy + 1) * e <= box->y0))
      continue;
    io::PcdPieceReader reader(io::layout::StaticMapIn(TilePartDir(hd_plan_dir, t)));
    while (reader.Next(detail::kReadPiece, &piece)) {
      kept.points.clear();
      for (const PointXYZI& p : piece.points)
        if (!box || box->Contains(detail::VoxelIndex(p.x, hd.voxel_m), detail::VoxelIndex(p.y, hd.voxel_m)))
          kept.points.push_back(p);
      f(t, kept);
    }
  }
}

// A session's HD-free map in the box, from its HD tiles' parts, in voxel order (the merged map's order).
PointCloud ReadWindow(const std::string& hd_plan_dir, const TilePlan& hd, const detail::VoxelBox& box) {
  std::vector<PointCloud> parts(hd.tiles.size());
  ForHdParts(hd_plan_dir, hd, &box, [&](std::size_t t, const PointCloud& kept) { parts[t].append(kept); });
  PointCloud out;
  detail::MergeInVoxelOrder(parts, hd.voxel_m, [&](const PointCloud& piece) { out.append(piece); });
  return out;
}

void WriteLdPlanJson(const std::string& path, const LdTilePlanFile& f, std::size_t nc, std::size_t nq) {
  json::Writer w;
  w.BeginObject().String("format", kLdPlanFormat).Int("version", kLdPlanVersion);
  w.String("central_plan", f.central_plan).String("query_plan", f.query_plan);
  w.Int("central_keyframes", (long long)nc).Int("query_keyframes", (long long)nq);
  w.Number("voxel_m", f.plan.voxel_m).Int("edge_voxels", f.plan.edge_voxels).Int("margin_voxels", f.plan.margin_voxels);
  w.Int("largest_window", (long long)f.plan.largest_window).BeginArray("tiles");
  for (const LdTile& t : f.plan.tiles) {
    w.BeginObject().Int("ix", t.ix).Int("iy", t.iy);
    detail::WriteRuns(w, "central_voter_runs", t.central_voters);
    detail::WriteRuns(w, "query_voter_runs", t.query_voters);
    w.EndObject();
  }
  w.EndArray().EndObject();
  io::WriteFileAtomic(path, [&](std::ostream& os) { os << w.str(); });
}

// The sessions of the pair: each HD plan and its keyframes (scans read on demand).
struct PairSessions {
  TilePlanFile central, query;
  std::vector<WorldKeyframe> central_kfs, query_kfs;
};
// The two plans' configs must be one, but for the LD rotation tolerance: each session's plan carries
// that of the pair it is the query of (ForPair), and the pair's LD takes the query's.
PairSessions LoadPair(const std::string& central_plan, const std::string& query_plan) {
  PairSessions p{ReadTilePlan(central_plan), ReadTilePlan(query_plan), {}, {}};
  RemovertConfig central = p.central.cfg, query = p.query.cfg;
  query.ld_rotation_sigma_deg = central.ld_rotation_sigma_deg;
  if (FieldsToString(FieldsOf(central)) != FieldsToString(FieldsOf(query)))
    throw Error(detail::ConfigFileIn(query_plan), 0, "differs from " + detail::ConfigFileIn(central_plan) +
                                               ": plan both sessions' HD tiles with one config (but for "
                                               "ld.rotation_sigma_deg)");
  p.central_kfs = LoadWorldKeyframes(p.central.session_dir, p.central.poses_file);
  p.query_kfs = LoadWorldKeyframes(p.query.session_dir, p.query.poses_file);
  return p;
}

std::string Absolute(const std::string& path) { return fs::absolute(path).lexically_normal().string(); }

}  // namespace

std::string detail::LdCloudFile(PointCloud LdResult::*cloud) {
  for (const LdCloud& c : kLdClouds)
    if (c.cloud == cloud) return c.file;
  throw Error("LdCloudFile: not one of the pair's LD clouds");
}

std::vector<std::string> detail::LdPairCloudFiles() {
  std::vector<std::string> files;
  for (const LdCloud& c : kLdClouds) files.push_back(c.file);
  return files;
}

LdTilePlan WriteLdTilePlan(const std::string& plan_dir, const std::string& central_plan_dir,
                           const std::string& query_plan_dir) {
  LdTilePlanFile f{Absolute(central_plan_dir), Absolute(query_plan_dir), {}, {}};
  const PairSessions p = LoadPair(f.central_plan, f.query_plan);
  detail::DoneTiles(f.central_plan, p.central.plan.tiles.size());
  detail::DoneTiles(f.query_plan, p.query.plan.tiles.size());
  // The central's config (its sensor), with the LD tolerance of the query's plan (ForPair).
  RemovertConfig pair_cfg = p.central.cfg;
  pair_cfg.ld_rotation_sigma_deg = p.query.cfg.ld_rotation_sigma_deg;
  f.cfg = WithSensor(pair_cfg, p.central_kfs);
  LdCellCounts counts(f.cfg);
  auto count = [&](std::size_t, const PointCloud& piece) { counts.Add(piece); };
  ForHdParts(f.central_plan, p.central.plan, nullptr, count);
  ForHdParts(f.query_plan, p.query.plan, nullptr, count);
  f.plan = PlanLdTiles(counts, p.central_kfs, p.query_kfs, f.cfg);
  io::StagingDir staging(plan_dir, "plan.json");
  RemovertConfig saved = pair_cfg;  // as the HD plans have it (the sensor resolved by each job)
  io::SaveConfigFields(detail::ConfigFileIn(staging.path()), FieldsOf(saved));
  WriteLdPlanJson(detail::PlanFileIn(staging.path()), f, p.central_kfs.size(), p.query_kfs.size());
  staging.Publish();
  return f.plan;
}

bool IsLdTilePlan(const std::string& plan_dir) {
  const std::string path = detail::PlanFileIn(plan_dir);
  if (!fs::exists(path)) return false;
  const json::Value doc = json::ParseFile(path);
  const json::Value* format = doc.Find("format");
  return format && format->type == json::Value::Type::kString && format->str == kLdPlanFormat;
}

LdTilePlanFile ReadLdTilePlan(const std::string& plan_dir) {
  using T = json::Value::Type;
  const std::string path = detail::PlanFileIn(plan_dir);
  const json::Value doc = json::ParseFile(path);
  if (Member(doc, "format", T::kString, path).str != kLdPlanFormat)
    throw Error(path, 0, std::string("not an LD tile plan (format is not '") + kLdPlanFormat + "')");
  if (Integer(Member(doc, "version", T::kNumber, path), "version", path) != kLdPlanVersion)
    throw Error(path, 0, "an LD tile plan of another version: plan the LD tiles again");
  LdTilePlanFile f;
  io::LoadConfig(detail::ConfigFileIn(plan_dir), f.cfg);
  f.cfg.Validate(detail::ConfigFileIn(plan_dir));
  f.central_plan = Member(doc, "central_plan", T::kString, path).str;
  f.query_plan = Member(doc, "query_plan", T::kString, path).str;
  f.plan.voxel_m = f.cfg.map_voxel_m;
  // The margin depends on the sensor (the residues' farthest hop), which the tile jobs resolve from
  // the central's scans: RunLdTileJobs checks it against the resolved config.
  f.plan.margin_voxels = Integer(Member(doc, "margin_voxels", T::kNumber, path), "margin_voxels", path);
  f.plan.edge_voxels = Integer(Member(doc, "edge_voxels", T::kNumber, path), "edge_voxels", path);
  if (f.plan.margin_voxels <= 0 || f.plan.edge_voxels <= 0 || f.plan.edge_voxels % f.plan.margin_voxels != 0)
    throw Error(path, 0, "edge_voxels is no positive multiple of margin_voxels");
  f.plan.largest_window = Count(Member(doc, "largest_window", T::kNumber, path), "largest_window", path);
  const std::size_t nc = Count(Member(doc, "central_keyframes", T::kNumber, path), "central_keyframes", path);
  const std::size_t nq = Count(Member(doc, "query_keyframes", T::kNumber, path), "query_keyframes", path);
  for (const json::Value& jt : Member(doc, "tiles", T::kArray, path).arr) {
    LdTile t;
    t.ix = Integer(Member(jt, "ix", T::kNumber, path), "ix", path);
    t.iy = Integer(Member(jt, "iy", T::kNumber, path), "iy", path);
    t.central_voters = detail::ReadRuns(Member(jt, "central_voter_runs", T::kArray, path), nc, "a central voter", path);
    t.query_voters = detail::ReadRuns(Member(jt, "query_voter_runs", T::kArray, path), nq, "a query voter", path);
    f.plan.tiles.push_back(std::move(t));
  }
  return f;
}

std::size_t RunLdTileJobs(const std::string& plan_dir, std::vector<std::size_t> tiles, int threads, bool force) {
  const LdTilePlanFile f = ReadLdTilePlan(plan_dir);
  // The pair's sessions and the sensor (the central's scans) once for every tile.
  const PairSessions p = LoadPair(f.central_plan, f.query_plan);
  const RemovertConfig cfg = WithSensor(f.cfg, p.central_kfs, threads);
  if (LdCellCounts(cfg).CellVoxels() != f.plan.margin_voxels)
    throw Error(detail::PlanFileIn(plan_dir), 0,
                "margin_voxels differs from what config.yaml and the central's scans give: plan the LD tiles again");
  return detail::RunUndoneTiles(plan_dir, std::move(tiles), f.plan.tiles.size(), force, [&](std::size_t tile,
                                                                                          const std::string& dir) {
    const detail::VoxelBox window = detail::LdWindowBox(f.plan, tile);
    const LdResult res = DetectLdTile(f.plan, tile, ReadWindow(f.central_plan, p.central.plan, window),
                                      ReadWindow(f.query_plan, p.query.plan, window), p.central_kfs, p.query_kfs,
                                      cfg, threads);
    for (const LdCloud& c : kLdClouds) io::WritePcd(dir + "/" + c.file, res.*c.cloud);
    WriteLdStatsJson(detail::TileJsonIn(dir), res.stats, 1);  // last: the tile is done
    spdlog::info("tiles: LD tile {} of {}: {} central + {} query points in its core; ND strong {} weak {}, PD strong "
                 "{} weak {}", tile, f.plan.tiles.size(), res.stats.central_points, res.stats.query_points,
                 res.stats.nd_strong, res.stats.nd_weak, res.stats.pd_strong, res.stats.pd_weak);
  });
}

bool RunLdTileJob(const std::string& plan_dir, std::size_t tile, int threads, bool force) {
  return RunLdTileJobs(plan_dir, {tile}, threads, force) == 1;
}

LdStats MergeLdTileJobs(const std::string& plan_dir, const std::string& out_dir) {
  const LdTilePlanFile f = ReadLdTilePlan(plan_dir);
  LdStats st;
  for (const std::string& done : detail::DoneTiles(plan_dir, f.plan.tiles.size())) AddLdStatsJson(done, &st);
  std::vector<std::int64_t> columns;
  for (const LdTile& t : f.plan.tiles) columns.push_back(t.ix);
  io::StagingDir staging(out_dir, "report.json");
  for (const LdCloud& c : kLdClouds) {
    std::vector<std::string> files;
    for (std::size_t t = 0; t < f.plan.tiles.size(); ++t) files.push_back(TilePartDir(plan_dir, t) + "/" + c.file);
    detail::MergePartFiles(files, columns, f.plan.voxel_m, st.*c.count, staging.path() + "/" + c.file);
  }
  WriteLdStatsJson(staging.path() + "/report.json", st, f.plan.tiles.size());
  staging.Publish();
  return st;
}

}  // namespace ltm::removert
