// `ltmapper add`: one more drive into an existing map (pipeline.hpp, AddSession).
#include "ltmapper/io/io.hpp"
#include "ltmapper/pipeline/internal.hpp"
#include "ltmapper/pipeline/pipeline.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <sstream>

namespace ltm::pipeline {
namespace fs = std::filesystem;
using namespace detail;

namespace {

// The map in out_dir must be a finished run: its manifest, its changes and its store.
io::RunManifest ReadFinishedRun(const RunPaths& p, const std::string& out_dir) {
  if (!io::HasRunManifest(p.aligned))
    throw Error(out_dir + ": no map here (" + io::layout::ManifestFile(p.aligned) +
                " not found): build one first with `ltmapper run --sessions CENTRAL QUERY ... --out " + out_dir + "`");
  if (!fs::exists(p.store) || !fs::exists(StageMarkers(p)[2]))
    throw Error(p.store + ": the map store is missing or unfinished: finish the run first (`ltmapper run` again)");
  return io::ReadRunManifest(p.aligned);
}

bool InStore(const RunPaths& p, const map::MapConfig& cfg, const std::string& name) {
  const map::Store store = map::Store::Open(p.store, cfg, map::Store::Access::kReadOnly);
  for (const auto& s : store.Sessions())
    if (s.name == name) return true;
  return false;
}

// A session an earlier add left in the manifest but not in the store is dropped from both the
// manifest and aligned/ (it is added again from the start).
void ForgetUnfinished(io::RunManifest* m, const RunPaths& p, const std::string& name) {
  const auto it = std::find_if(m->sessions.begin(), m->sessions.end(), [&](const auto& s) { return s.name == name; });
  if (it == m->sessions.end()) return;
  if (it == m->sessions.begin()) throw Error("session '" + name + "' is the map's central session");
  spdlog::info("add: '{}' is in the run manifest but not in the store: adding it again", name);
  m->sessions.erase(it);
  fs::remove_all(fs::path(p.aligned) / name);
}

std::vector<Pose> WorldPoses(const RunPaths& p, const std::string& name) {
  return io::ReadKittiPoses(io::layout::PosesWorldFile(p.aligned, name));
}

// The aligned sessions to try as the fixed reference: the central first, then the others newest
// first (a drive that misses the central may still overlap a later one).
std::vector<io::ManifestSession> ReferenceOrder(const io::RunManifest& m) {
  std::vector<io::ManifestSession> refs = m.Aligned();
  if (refs.size() > 1) std::reverse(refs.begin() + 1, refs.end());
  return refs;
}

// A session of the map, loaded under its run name (its world poses are in aligned/).
Session MapSession(const io::ManifestSession& ref) {
  Session s = io::LoadSession(ref.dir);
  s.name = ref.name;
  return s;
}

// LT-SLAM of the new session against the map's sessions held fixed; throws when none aligns it.
slam::SessionAlignment AlignNewSession(const io::RunManifest& m, const RunPaths& p, const Session& query,
                                       const slam::SlamConfig& cfg, int threads, AddReport* rep) {
  std::vector<std::string> reasons;
  for (const auto& ref : ReferenceOrder(m)) {
    const Session world = slam::WorldReference(MapSession(ref), WorldPoses(p, ref.name), cfg);
    spdlog::info("add: aligning '{}' to '{}' ({} keyframes, world poses held fixed)", query.name, ref.name,
                 world.keyframes.size());
    const slam::SlamResult res = slam::AlignToReference(world, query, cfg, threads);
    rep->registrations += res.registrations;
    if (res.sessions[1].aligned) {
      rep->aligned_to = ref.name;
      rep->loops_accepted = res.sessions[1].loops_accepted;
      return res.sessions[1];
    }
    reasons.push_back(ref.name + ": " + res.sessions[1].reason);
  }
  std::string why;
  for (const auto& r : reasons) why += "\n  " + r;
  throw Error("add: session '" + query.name + "' (" + query.dir + ") is NOT aligned to any session of the map; "
              "nothing was changed:" + why);
}

// The new session placed by its given world poses, their rotation error measured against the
// map's sessions in ReferenceOrder: the first at whose world poses a loop verifies.
slam::SessionAlignment PlaceNewSession(const io::RunManifest& m, const RunPaths& p, const Session& query,
                                       const std::string& pose_file, const slam::SlamConfig& cfg,
                                       const removert::RemovertConfig& removert_cfg, int threads, AddReport* rep) {
  const slam::SessionAlignment placed = slam::GivenAlignment(query, pose_file);
  for (const auto& ref : ReferenceOrder(m)) {
    const Session world = MapSession(ref);
    slam::SlamResult res;
    res.sessions.resize(2);
    res.sessions[0].name = ref.name;
    res.sessions[0].aligned = true;
    res.sessions[0].T_world_sensor = WorldPoses(p, ref.name);
    res.sessions[1] = placed;
    slam::MeasureGivenPoses({world, query}, res, cfg, threads);
    rep->registrations += res.registrations;
    if (res.sessions[1].rotation_sigma_deg > 0.0) {
      WarnRoughPoses(res.sessions[1], removert_cfg);
      rep->aligned_to = ref.name + " (given poses)";
      rep->loops_accepted = res.sessions[1].loops_accepted;
      return res.sessions[1];
    }
  }
  rep->aligned_to = "given poses, not measured";
  return placed;
}

// aligned/<name>/ replaced whole.
void PublishAlignment(const RunPaths& p, const slam::SessionAlignment& a) {
  io::StagingDir staging((fs::path(p.aligned) / a.name).string(), "poses_world.txt");
  const fs::path tmp(staging.path());
  slam::WriteSessionAlignment(tmp.parent_path().string(), tmp.filename().string(), a);
  staging.Publish();
}

// LT-removert for the new session (last in the manifest's aligned sessions).
void AddChanges(const io::RunManifest& m, const RunPaths& p, const removert::RemovertConfig& cfg, int threads) {
  const removert::RunSessions run = removert::SessionsOfRun(m, p.aligned);
  removert::AddToRemovertStage(removert::WithAlignment(cfg, m, run.names), run.dirs, run.poses, p.changes, threads);
}

void Integrate(const RunPaths& p, const map::MapConfig& cfg, const std::string& name, int threads) {
  map::Store store = map::Store::Open(p.store, cfg);
  store.set_threads(threads);
  map::PipelineDirs dirs;
  dirs.aligned = p.aligned;
  dirs.changes = p.changes;
  const auto r = map::IntegrateFromDirs(store, dirs, name);
  spdlog::info("add: integrated '{}': {} changed keyframes, {} new, PD {}+{} ND {}+{} in {:.2f} s", name,
               r.keyframes_changed, r.keyframes_new, r.pd_strong, r.pd_weak, r.nd_strong, r.nd_weak, r.seconds);
}

// The markers of `run` with the grown session list: a later run of these sessions resumes.
void MarkGrownRun(const RunConfig& cfg, const StageConfigs& sc, const RunPaths& p, const io::RunManifest& m) {
  std::vector<std::string> dirs;
  for (const auto& s : m.sessions) dirs.push_back(s.dir);
  const auto keys = StageKeys(cfg, sc, dirs);
  const auto markers = StageMarkers(p);
  for (std::size_t i = 0; i < keys.size(); ++i) MarkStageDone(markers[i], keys[i]);
}

void WriteAddReport(const std::string& out_dir, const AddReport& r) {
  const std::string text = FormatAddReport(r);
  io::WriteFileAtomic((fs::path(out_dir) / "add_report.md").string(), [&](std::ostream& os) { os << text; });
}

}  // namespace

AddReport AddSession(const RunConfig& cfg, const std::string& out_dir, const std::string& session_dir, int threads,
                     const std::string& world_poses) {
  ValidateConfig(cfg, "run config");
  if (!fs::is_directory(session_dir)) throw Error(session_dir, 0, "session directory not found");
  const auto t0 = std::chrono::steady_clock::now();
  const RunPaths p(out_dir, cfg);
  io::RunManifest m = ReadFinishedRun(p, out_dir);
  io::MakeWritableDir(out_dir);
  const StageConfigs sc(cfg);
  AddReport rep;
  rep.session = SessionName(session_dir);
  if (InStore(p, sc.map, rep.session)) {
    rep.already_in_map = true;
    spdlog::info("add: '{}' is already in the map {}: nothing to do", rep.session, p.store);
    return rep;
  }
  ForgetUnfinished(&m, p, rep.session);
  rep.store_bytes_before = ReadMapFigures(p, sc.map, false).store_bytes;

  auto t = std::chrono::steady_clock::now();
  Session query = io::LoadSession(session_dir);
  query.name = rep.session;
  const slam::SessionAlignment aligned = world_poses.empty()
                                             ? AlignNewSession(m, p, query, sc.slam, threads, &rep)
                                             : PlaceNewSession(m, p, query, world_poses, sc.slam, sc.removert, threads, &rep);
  PublishAlignment(p, aligned);
  rep.seconds_slam = Since(t);

  t = std::chrono::steady_clock::now();
  m.sessions.push_back(
      {rep.session, fs::absolute(session_dir).lexically_normal().string(), true, "", aligned.rotation_sigma_deg});
  AddChanges(m, p, sc.removert, threads);
  rep.seconds_removert = Since(t);

  t = std::chrono::steady_clock::now();
  io::WriteRunManifest(p.aligned, m);  // the store reads the session order from it
  Integrate(p, sc.map, rep.session, threads);
  ExportMaps(p, sc, m.sessions[0].dir, cfg.export_maps, threads);
  MarkGrownRun(cfg, sc, p, m);
  rep.seconds_map = Since(t);

  FinishReport(rep, ReadMapFigures(p, sc.map, cfg.export_maps), t0);
  WriteAddReport(out_dir, rep);
  return rep;
}

std::string FormatAddReport(const AddReport& r) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(1) << "# ltmapper add: " << r.session << "\n\n";
  if (r.already_in_map) {
    os << "Already in the map: nothing was done.\n";
    return os.str();
  }
  os << "| step | time [s] |\n|---|---|\n| LT-SLAM (aligned to " << r.aligned_to << ", " << r.loops_accepted
     << " loops, " << r.registrations << " GICP) | " << r.seconds_slam << " |\n| LT-removert (HD + one pair) | "
     << r.seconds_removert << " |\n| LT-map (integrate + export) | " << r.seconds_map << " |\n| total | "
     << r.seconds << " |\n\n- store: " << r.store_bytes_before << " -> " << r.store_bytes << " bytes (+"
     << (r.store_bytes >= r.store_bytes_before ? r.store_bytes - r.store_bytes_before : 0)
     << ")\n- live map points: " << r.map_points_live << ", objects: " << r.objects << "\n- peak memory "
     << std::setprecision(0) << r.peak_rss_bytes / 1048576.0 << " MiB\n";
  return os.str();
}

}  // namespace ltm::pipeline
