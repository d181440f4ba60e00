#include "ltmapper/pipeline/pipeline.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/slam/slam.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace ltm::pipeline {
namespace fs = std::filesystem;

namespace {

// A stage's output directory holds this file once the stage returned without error; a run that
// was killed half-way therefore reruns that stage (its own writes are atomic per file).
constexpr const char* kDoneMarker = "STAGE_DONE";
const std::vector<std::string> kStages = {"slam", "removert", "map"};

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string SessionName(const std::string& dir) {
  fs::path p(dir);
  if (p.filename().empty()) p = p.parent_path();  // trailing slash
  return p.filename().string();
}

template <class Config>
Config LoadStageConfig(const std::string& path, const std::string& what) {
  Config cfg;
  if (!path.empty()) io::LoadConfig(path, cfg);
  ValidateConfig(cfg, path.empty() ? what + " defaults" : path);
  spdlog::info("{} config ({}):\n{}", what, path.empty() ? "defaults" : path, ConfigToString(cfg));
  return cfg;
}

std::string Marker(const std::string& dir) { return (fs::path(dir) / kDoneMarker).string(); }

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

RunReport RunPipeline(const RunConfig& cfg, const std::vector<std::string>& session_dirs,
                      const std::string& out_dir, int threads) {
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
  const std::string aligned_dir = (fs::path(out_dir) / "aligned").string();
  const std::string changes_dir = (fs::path(out_dir) / "changes").string();
  const std::string store_path = (fs::path(out_dir) / cfg.store_name).string();
  const auto slam_cfg = LoadStageConfig<slam::SlamConfig>(cfg.slam_config, "LT-SLAM");
  const auto rem_cfg = LoadStageConfig<removert::RemovertConfig>(cfg.removert_config, "LT-removert");
  const auto map_cfg = LoadStageConfig<map::MapConfig>(cfg.map_config, "LT-map");
  // Each stage's key: the sessions, its resolved config, and the keys before it.
  std::vector<std::string> keys(3);
  keys[0] = "sessions:\n";
  for (const auto& d : session_dirs) keys[0] += "  " + fs::absolute(d).lexically_normal().string() + "\n";
  keys[0] += "slam:\n" + ConfigToString(slam_cfg);
  keys[1] = keys[0] + "removert:\n" + ConfigToString(rem_cfg);
  keys[2] = keys[1] + "map:\n" + ConfigToString(map_cfg) + "export_maps: " + (cfg.export_maps ? "true" : "false") + "\n";
  const std::vector<std::string> markers = {Marker(aligned_dir), Marker(changes_dir), store_path + ".done"};
  const std::size_t first = FirstStage(cfg, markers, keys);

  // ------------------------------------------------------------------------ 1. LT-SLAM
  auto t0 = std::chrono::steady_clock::now();
  if (first <= 0) {
    spdlog::info("run [1/3] LT-SLAM: {} sessions -> {}", session_dirs.size(), aligned_dir);
    fs::remove(markers[0]);
    const auto res = slam::RunSlamStage(slam_cfg, session_dirs, aligned_dir, threads);
    for (const auto& s : res.sessions)
      if (!s.aligned) spdlog::warn("run: session '{}' NOT aligned: {}", s.name, s.reason);
    MarkStageDone(markers[0], keys[0]);
    report.stages.push_back({"slam", false, Since(t0)});
  } else {
    spdlog::info("run [1/3] LT-SLAM: finished output found in {}, skipped", aligned_dir);
    report.stages.push_back({"slam", true, 0.0});
  }
  // Which sessions have world poses (the central always; queries when aligned).
  std::vector<std::string> aligned_dirs, poses_files;
  for (std::size_t i = 0; i < session_dirs.size(); ++i) {
    const std::string poses = (fs::path(aligned_dir) / report.sessions[i] / "poses_world.txt").string();
    if (fs::exists(poses)) {
      aligned_dirs.push_back(session_dirs[i]);
      poses_files.push_back(poses);
      report.aligned.push_back(report.sessions[i]);
    } else {
      if (i == 0) throw Error(poses, 0, "LT-SLAM wrote no poses for the central session");
      report.not_aligned.push_back(report.sessions[i]);
    }
  }
  if (aligned_dirs.size() < 2)
    throw Error(aligned_dir + ": no query session could be aligned to the central one '" +
                report.sessions[0] + "'; see " + aligned_dir + "/report.md");

  // --------------------------------------------------------------------- 2. LT-removert
  t0 = std::chrono::steady_clock::now();
  if (first <= 1) {
    spdlog::info("run [2/3] LT-removert: {} aligned sessions -> {}", aligned_dirs.size(), changes_dir);
    fs::remove(markers[1]);
    removert::RunRemovertStage(rem_cfg, aligned_dirs, poses_files, changes_dir, threads);
    MarkStageDone(markers[1], keys[1]);
    report.stages.push_back({"removert", false, Since(t0)});
  } else {
    spdlog::info("run [2/3] LT-removert: finished output found in {}, skipped", changes_dir);
    report.stages.push_back({"removert", true, 0.0});
  }

  // --------------------------------------------------------------------------- 3. LT-map
  t0 = std::chrono::steady_clock::now();
  if (first <= 2) {
    spdlog::info("run [3/3] LT-map: -> {}", store_path);
    fs::remove(markers[2]);
    // The store is rebuilt from the stage outputs: integrating is one transaction per session,
    // but a partially integrated store from a killed run is simply replaced.
    for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(store_path + suffix);
    map::PipelineDirs dirs;
    dirs.aligned = aligned_dir;
    dirs.changes = changes_dir;
    dirs.sessions = fs::path(session_dirs[0]).parent_path().string();
    map::InitFromDirs(store_path, map_cfg, dirs, report.aligned[0], threads);
    map::Store store = map::Store::Open(store_path, map_cfg);
    store.set_threads(threads);
    for (std::size_t i = 1; i < report.aligned.size(); ++i) {
      const auto r = map::IntegrateFromDirs(store, dirs, report.aligned[i]);
      spdlog::info("run: integrated '{}': {} changed keyframes, {} new, PD {}+{} ND {}+{} in {:.2f} s",
                   report.aligned[i], r.keyframes_changed, r.keyframes_new, r.pd_strong, r.pd_weak,
                   r.nd_strong, r.nd_weak, r.seconds);
    }
    if (cfg.export_maps) {
      map::Region region;
      region.voxel_m = map_cfg.output_voxel_m;
      map::WriteLabelledCloud((fs::path(out_dir) / "live.pcd").string(), store.Live(region));
      map::WriteLabelledCloud((fs::path(out_dir) / "meta.pcd").string(), store.Meta(region));
      map::WriteObjects((fs::path(out_dir) / "objects").string(), store.Objects());
    }
    MarkStageDone(markers[2], keys[2]);
    report.stages.push_back({"map", false, Since(t0)});
  } else {
    spdlog::info("run [3/3] LT-map: finished store found at {}, skipped", store_path);
    report.stages.push_back({"map", true, 0.0});
  }

  {
    const map::Store store = map::Store::Open(store_path, map_cfg, map::Store::Access::kReadOnly);
    const auto totals = store.Totals();
    report.store_bytes = totals.file_bytes;
    report.map_points_live = totals.base_points;
  }
  if (cfg.export_maps) {
    const auto live = (fs::path(out_dir) / "live.pcd").string();
    const auto meta = (fs::path(out_dir) / "meta.pcd").string();
    if (fs::exists(live)) report.map_points_live = io::ReadPcd(live).size();
    if (fs::exists(meta)) report.map_points_meta = io::ReadPcd(meta).size();
    const auto csv = fs::path(out_dir) / "objects" / "objects.csv";
    if (fs::exists(csv)) {
      std::ifstream in(csv);
      std::string line;
      std::size_t lines = 0;
      while (std::getline(in, line))
        if (!line.empty()) ++lines;
      report.objects = lines > 0 ? lines - 1 : 0;  // header line
    }
  }
  report.seconds = Since(t_run);
  report.peak_rss_bytes = PeakRssBytes();

  const std::string text = FormatRunReport(report);
  io::WriteFileAtomic((fs::path(out_dir) / "run_report.md").string(), [&](std::ostream& os) { os << text; });
  io::WriteFileAtomic((fs::path(out_dir) / "run_report.json").string(), [&](std::ostream& os) {
    os << "{\n  \"sessions\": " << report.sessions.size() << ",\n  \"aligned\": " << report.aligned.size()
       << ",\n  \"not_aligned\": " << report.not_aligned.size() << ",\n  \"stages\": {";
    for (std::size_t i = 0; i < report.stages.size(); ++i)
      os << (i ? ", " : "") << "\"" << report.stages[i].stage << "\": {\"skipped\": "
         << (report.stages[i].skipped ? "true" : "false") << ", \"seconds\": " << report.stages[i].seconds << "}";
    os << "},\n  \"live_points\": " << report.map_points_live << ",\n  \"meta_points\": " << report.map_points_meta
       << ",\n  \"objects\": " << report.objects << ",\n  \"store_bytes\": " << report.store_bytes
       << ",\n  \"seconds\": " << report.seconds << ",\n  \"peak_rss_bytes\": " << report.peak_rss_bytes << "\n}\n";
  });
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
