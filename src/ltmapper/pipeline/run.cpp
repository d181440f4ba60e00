#include "ltmapper/pipeline/pipeline.hpp"
#include "ltmapper/pipeline/internal.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/slam/slam.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <optional>
#include <sstream>

namespace ltm::pipeline {
namespace fs = std::filesystem;

namespace detail {

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string SessionName(const std::string& dir) {
  fs::path p(dir);
  if (p.filename().empty()) p = p.parent_path();  // trailing slash
  return p.filename().string();
}

namespace {
template <class Config>
Config LoadStageConfig(const std::string& path, const std::string& what) {
  Config cfg;
  if (!path.empty()) io::LoadConfig(path, cfg);
  ValidateConfig(cfg, path.empty() ? what + " defaults" : path);
  spdlog::info("{} config ({}):\n{}", what, path.empty() ? "defaults" : path, ConfigToString(cfg));
  return cfg;
}
}  // namespace

StageConfigs::StageConfigs(const RunConfig& cfg)
    : slam(LoadStageConfig<slam::SlamConfig>(cfg.slam_config, "LT-SLAM")),
      removert(LoadStageConfig<removert::RemovertConfig>(cfg.removert_config, "LT-removert")),
      map(LoadStageConfig<map::MapConfig>(cfg.map_config, "LT-map")) {}

RunPaths::RunPaths(const std::string& out, const RunConfig& cfg)
    : aligned(io::layout::AlignedDir(out)), changes(io::layout::ChangesDir(out)),
      store((fs::path(out) / cfg.store_name).string()), live((fs::path(out) / "live.pcd").string()),
      meta((fs::path(out) / "meta.pcd").string()), objects(io::layout::ObjectsDir(out)) {}

// A stage's output directory holds this file once the stage returned without error; a run that
// was killed half-way therefore reruns that stage (its own writes are atomic per file).
std::vector<std::string> StageMarkers(const RunPaths& p) {
  return {(fs::path(p.aligned) / "STAGE_DONE").string(), (fs::path(p.changes) / "STAGE_DONE").string(),
          p.store + ".done"};
}

// Each stage's key: the output layout version, the code it ran (CodeId), the sessions, its resolved
// config, and the keys before it (outputs of a run without a manifest never count as finished).
std::vector<std::string> StageKeys(const RunConfig& cfg, const StageConfigs& sc,
                                   const std::vector<std::string>& session_dirs,
                                   const std::vector<std::string>& world_poses) {
  std::vector<std::string> keys(3);
  keys[0] = std::string("layout: manifest-1\ncode: ") + CodeId() + "\nsessions:\n";
  for (const auto& d : session_dirs) keys[0] += "  " + fs::absolute(d).lexically_normal().string() + "\n";
  keys[0] += "slam:\n" + ConfigToString(sc.slam);  // with given poses too: their measure registers loops
  for (const auto& f : world_poses) {  // a digest of each file (std::hash: stable within a build, as the key is)
    const std::string text = io::ReadFileText(f);
    keys[0] += "poses: " + fs::absolute(f).lexically_normal().string() + " " + std::to_string(text.size()) +
               " bytes, hash " + std::to_string(std::hash<std::string>{}(text)) + "\n";
  }
  keys[1] = keys[0] + "removert:\n" + ConfigToString(sc.removert);
  keys[2] = keys[1] + "map:\n" + ConfigToString(sc.map) + "export_maps: " + (cfg.export_maps ? "true" : "false") + "\n";
  return keys;
}

void WarnRoughPoses(const slam::SessionAlignment& a, const removert::RemovertConfig& cfg) {
  if (a.rotation_sigma_deg > cfg.pose_sigma_deg)
    spdlog::warn("run: the given poses of '{}' measure {:.2f} deg of rotation error against the earlier sessions, more "
                 "than LD's prior ({} deg): LD's tolerances widen with it and find fewer changes; LT-SLAM (without "
                 "--poses) may place the session better",
                 a.name, a.rotation_sigma_deg, cfg.pose_sigma_deg);
}

// live.pcd, meta.pcd and objects/ from the store; objects/ is replaced whole (StagingDir), so no
// object of an earlier run survives. Without export, those of an earlier run are removed.
// The object rules' sampling step comes from the sensor LT-removert used (the central session's).
void ExportMaps(const RunPaths& p, const StageConfigs& sc, const std::string& central_dir, bool export_maps,
                int threads) {
  if (!export_maps) {
    for (const auto& f : {p.live, p.meta}) fs::remove(f);
    if (fs::exists(fs::path(p.objects) / "objects.csv")) fs::remove_all(p.objects);
    return;
  }
  const Session central = io::LoadSession(central_dir);
  const removert::RemovertConfig resolved = removert::WithSensor(sc.removert, removert::KeyframesOf(central), threads);
  const map::MapConfig map_cfg = map::WithSensorStep(sc.map, resolved.sensor_model);
  map::Store store = map::Store::Open(p.store, map_cfg);
  // Each step's objects are computed once and kept in the store: an add computes its own step only.
  const std::size_t computed = store.CacheObjects();
  spdlog::info("LT-map: objects of {} step(s) computed, the others read from the store", computed);
  map::Region region;
  region.voxel_m = map_cfg.output_voxel_m;
  map::WriteLabelledCloudParts(p.live, region.voxel_m, [&](const map::PartSink& f) { store.StreamLive(region, f); });
  map::WriteLabelledCloudParts(p.meta, region.voxel_m, [&](const map::PartSink& f) { store.StreamMeta(region, f); });
  io::StagingDir objects(p.objects, "objects.csv");
  std::vector<map::MapObject> rejected;
  const auto objs = store.Objects(&rejected);
  map::WriteObjects(objects.path(), objs, &rejected);
  objects.Publish();
}

MapFigures ReadMapFigures(const RunPaths& p, const map::MapConfig& map_cfg, bool export_maps) {
  MapFigures f;
  {
    const map::Store store = map::Store::Open(p.store, map_cfg, map::Store::Access::kReadOnly);
    const auto totals = store.Totals();
    f.store_bytes = totals.file_bytes;
    f.live = totals.base_points;
  }
  if (!export_maps) return f;
  if (fs::exists(p.live)) f.live = io::ReadPcdPointCount(p.live);  // the header: never the map
  if (fs::exists(p.meta)) f.meta = io::ReadPcdPointCount(p.meta);
  const auto csv = fs::path(p.objects) / "objects.csv";
  if (!fs::exists(csv)) return f;
  std::ifstream in(csv);
  std::size_t lines = 0;
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) ++lines;
  f.objects = lines > 0 ? lines - 1 : 0;  // header line
  return f;
}

}  // namespace detail

namespace {
using namespace detail;
const std::vector<std::string> kStages = {"slam", "removert", "map"};

// Index of the first stage to run: `from_stage` when given, else the first whose marker does
// not hold its key.
std::size_t FirstStage(const RunConfig& cfg, const std::vector<std::string>& markers,
                       const std::vector<std::string>& keys) {
  if (cfg.from_stage != "auto") {
    for (std::size_t i = 0; i < kStages.size(); ++i)
      if (kStages[i] == cfg.from_stage) return i;
  }
  for (std::size_t i = 0; i < markers.size(); ++i) {
    if (StageDone(markers[i], keys[i])) continue;
    if (fs::exists(markers[i]))
      spdlog::info("run: {} finished with other inputs or parameters: running it again", kStages[i]);
    return i;
  }
  return markers.size();
}

}  // namespace

void MarkStageDone(const std::string& marker, const std::string& key) {
  io::WriteFileAtomic(marker, [&](std::ostream& os) { os << key; });
}

bool StageDone(const std::string& marker, const std::string& key) {
  std::ifstream in(marker, std::ios::binary);
  if (!in) return false;
  std::ostringstream text;
  text << in.rdbuf();
  return text.str() == key;
}

namespace {

// Which sessions LT-SLAM aligned, from its run manifest (never from which files exist).
void ReadAligned(const std::string& aligned_dir, RunReport* report) {
  if (!io::HasRunManifest(aligned_dir))
    throw Error(io::layout::ManifestFile(aligned_dir) + ": not found (" + aligned_dir +
                " was written by an older ltmapper): run again with --from slam");
  const io::RunManifest m = io::ReadRunManifest(aligned_dir);
  if (m.sessions.size() != report->sessions.size())
    throw Error(io::layout::ManifestFile(aligned_dir) + ": lists " + std::to_string(m.sessions.size()) +
                " sessions, the run has " + std::to_string(report->sessions.size()));
  if (!m.sessions[0].aligned)
    throw Error(io::layout::ManifestFile(aligned_dir) + ": the central session is not aligned");
  for (const auto& s : m.sessions) (s.aligned ? report->aligned : report->not_aligned).push_back(s.name);
  if (report->aligned.size() < 2)
    throw Error(aligned_dir + ": no query session could be aligned to the central one '" + report->sessions[0] +
                "'; see " + aligned_dir + "/report.md");
}

// LT-map: the store rebuilt from the stage outputs, in the manifest's session order.
void BuildStore(const RunPaths& p, const map::MapConfig& map_cfg, const RunReport& report, int threads) {
  // Integrating is one transaction per session, but a partially integrated store from a killed
  // run is simply replaced.
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(p.store + suffix);
  map::PipelineDirs dirs;
  dirs.aligned = p.aligned;
  dirs.changes = p.changes;
  map::InitFromDirs(p.store, map_cfg, dirs, report.aligned[0], threads);
  map::Store store = map::Store::Open(p.store, map_cfg);
  store.set_threads(threads);
  for (std::size_t i = 1; i < report.aligned.size(); ++i) {
    const auto r = map::IntegrateFromDirs(store, dirs, report.aligned[i]);
    spdlog::info("run: integrated '{}': {} changed keyframes, {} new, PD {}+{} ND {}+{} in {:.2f} s",
                 report.aligned[i], r.keyframes_changed, r.keyframes_new, r.pd_strong, r.pd_weak, r.nd_strong,
                 r.nd_weak, r.seconds);
  }
}

void WriteRunReport(const std::string& out_dir, const RunReport& report) {
  const std::string text = FormatRunReport(report);
  io::WriteFileAtomic((fs::path(out_dir) / "run_report.md").string(), [&](std::ostream& os) { os << text; });
  io::json::Writer w;
  w.BeginObject().Int("sessions", report.sessions.size()).Int("aligned", report.aligned.size());
  w.Int("not_aligned", report.not_aligned.size()).BeginObject("stages");
  for (const auto& st : report.stages)
    w.BeginObject(st.stage).Bool("skipped", st.skipped).Number("seconds", st.seconds).EndObject();
  w.EndObject().Int("live_points", report.map_points_live).Int("meta_points", report.map_points_meta);
  w.Int("objects", report.objects).Int("store_bytes", report.store_bytes);
  w.Number("seconds", report.seconds).Int("peak_rss_bytes", report.peak_rss_bytes).EndObject();
  io::WriteFileAtomic((fs::path(out_dir) / "run_report.json").string(), [&](std::ostream& os) { os << w.str(); });
}

// Runs stage `i` unless it is before `first` (finished, same key): times it and writes its marker.
template <class F>
void Stage(std::size_t i, std::size_t first, const std::string& marker, const std::string& key,
           const std::string& what, RunReport* report, F run) {
  if (i < first) {
    spdlog::info("run [{}/3] {}: finished output found, skipped", i + 1, what);
    report->stages.push_back({kStages[i], true, 0.0});
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  fs::remove(marker);
  run();
  MarkStageDone(marker, key);
  report->stages.push_back({kStages[i], false, Since(t0)});
}

}  // namespace

RunReport RunPipeline(const RunConfig& cfg, const std::vector<std::string>& session_dirs,
                      const std::string& out_dir, int threads, const std::vector<std::string>& world_poses) {
  ValidateConfig(cfg, "run config");
  if (session_dirs.size() < 2)
    throw Error("run: need a central and at least one query session, got " +
                std::to_string(session_dirs.size()) + " session directories");
  for (const auto& d : session_dirs)
    if (!fs::is_directory(d)) throw Error(d, 0, "session directory not found");

  const auto t_run = std::chrono::steady_clock::now();
  RunReport report;
  for (const auto& d : session_dirs) report.sessions.push_back(SessionName(d));
  io::MakeWritableDir(out_dir);  // before any stage (and before --from removes a stage's outputs)
  const RunPaths p(out_dir, cfg);
  const StageConfigs sc(cfg);
  const auto& slam_cfg = sc.slam;
  const auto& rem_cfg = sc.removert;
  const auto& map_cfg = sc.map;
  // Given poses are checked before any stage's output is touched.
  std::optional<slam::GivenPoses> given;
  if (!world_poses.empty()) given = slam::ReadGivenPoses(session_dirs, world_poses);
  const std::vector<std::string> keys = StageKeys(cfg, sc, session_dirs, world_poses);
  // A marker lies in its stage folder (written once the folder is published; a rerun replaces it).
  const std::vector<std::string> markers = StageMarkers(p);
  const std::size_t first = FirstStage(cfg, markers, keys);

  Stage(0, first, markers[0], keys[0], "LT-SLAM", &report, [&] {
    if (given) {
      spdlog::info("run [1/3] world poses given: {} sessions -> {}", session_dirs.size(), p.aligned);
      for (const auto& a : slam::WriteGivenPoses(slam_cfg, std::move(*given), p.aligned, threads).sessions)
        WarnRoughPoses(a, rem_cfg);
      return;
    }
    spdlog::info("run [1/3] LT-SLAM: {} sessions -> {}", session_dirs.size(), p.aligned);
    const auto res = slam::RunSlamStage(slam_cfg, session_dirs, p.aligned, threads);
    for (const auto& s : res.sessions)
      if (!s.aligned) spdlog::warn("run: session '{}' NOT aligned: {}", s.name, s.reason);
  });
  ReadAligned(p.aligned, &report);
  Stage(1, first, markers[1], keys[1], "LT-removert", &report, [&] {
    spdlog::info("run [2/3] LT-removert: {} aligned sessions -> {}", report.aligned.size(), p.changes);
    removert::RunRemovertStageOnRun(rem_cfg, p.aligned, p.changes, threads);
  });
  Stage(2, first, markers[2], keys[2], "LT-map", &report, [&] {
    spdlog::info("run [3/3] LT-map: -> {}", p.store);
    BuildStore(p, map_cfg, report, threads);
    ExportMaps(p, sc, session_dirs[0], cfg.export_maps, threads);
  });
  const MapFigures fig = ReadMapFigures(p, map_cfg, cfg.export_maps);
  FinishReport(report, fig, t_run);
  report.map_points_meta = fig.meta;
  WriteRunReport(out_dir, report);
  return report;
}

std::string FormatRunReport(const RunReport& r) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(1);
  os << "# ltmapper run\n\n| stage | status | time [s] |\n|---|---|---|\n";
  for (const auto& s : r.stages)
    os << "| " << s.stage << " | " << (s.skipped ? "resumed (skipped)" : "ran") << " | " << s.seconds << " |\n";
  os << "\n- sessions: " << r.sessions.size() << " (central: " << (r.sessions.empty() ? "" : r.sessions[0])
     << ")\n- aligned: " << r.aligned.size() << "\n";
  for (const auto& n : r.not_aligned) os << "- NOT aligned: " << n << " (see aligned/report.md)\n";
  os << "- live map points: " << r.map_points_live << ", meta map points: " << r.map_points_meta
     << "\n- objects: " << r.objects << "\n- store: " << r.store_bytes << " bytes\n- total: " << r.seconds
     << " s, peak memory " << std::setprecision(0) << r.peak_rss_bytes / 1048576.0 << " MiB\n";
  return os.str();
}

}  // namespace ltm::pipeline
