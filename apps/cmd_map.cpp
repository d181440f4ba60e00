// `ltmapper map <sub>`: the LT-map store (init, integrate, live, meta, restore, export, log, fsck,
// objects). Commands parse arguments, load the config and call ltm::map; outputs are atomic.
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/removert/removert.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>

namespace ltm::app {
namespace {

struct MapOptions {
  CommonOptions common;
  std::string store, config, out;
  map::PipelineDirs dirs;
  std::string central, session;
  std::string sensor_session;  // map objects: the session whose scans give the sensor
  std::vector<std::string> set;  // --set key=value overrides
  std::vector<std::string> sessions;
  std::vector<double> box_min, box_max;
  double voxel = -1.0;
  bool meta = false, changes = false;
  std::string from, to, compare;  // map diff
};

map::MapConfig LoadMapConfig(const MapOptions& o) {
  if (o.common.quiet) spdlog::set_level(spdlog::level::warn);
  auto cfg = LoadParams<map::MapConfig>(o.config, o.set);
  if (o.voxel >= 0) cfg.output_voxel_m = o.voxel;
  ValidateConfig(cfg, o.config.empty() ? "map config" : o.config);
  if (!o.common.quiet) spdlog::info("map config:\n{}", ConfigToString(cfg));
  return cfg;
}

map::Region RegionOf(const MapOptions& o, const map::MapConfig& cfg) {
  map::Region r;
  r.voxel_m = cfg.output_voxel_m;
  if (o.box_min.empty() != o.box_max.empty()) throw Error("--min and --max go together");
  if (!o.box_min.empty()) {
    r.use_box = true;
    r.lo = Eigen::Vector3d(o.box_min[0], o.box_min[1], o.box_min[2]);
    r.hi = Eigen::Vector3d(o.box_max[0], o.box_max[1], o.box_max[2]);
    if ((r.lo.array() > r.hi.array()).any()) throw Error("--min must not exceed --max");
  }
  return r;
}

// Readers (everything but integrate) open the store read-only: it may sit on read-only media or
// belong to another user, and reading it must leave no -wal / -shm behind.
map::Store OpenStore(const MapOptions& o, const map::MapConfig& cfg,
                     map::Store::Access access = map::Store::Access::kReadOnly) {
  map::Store s = map::Store::Open(o.store, cfg, access);
  s.set_threads(o.common.threads);
  return s;
}

// "NAME" or an order number.
int ResolveSession(const map::Store& s, const std::string& name) {
  for (const auto& r : s.Sessions())
    if (r.name == name) return r.order;
  try {
    std::size_t used = 0;
    const int k = std::stoi(name, &used);
    if (used == name.size() && k >= 0 && k <= s.LatestSession()) return k;
  } catch (const std::exception&) {
  }
  throw Error(s.path() + ": no session '" + name + "'");
}

void Report(const map::IntegrationResult& r, const std::string& name) {
  spdlog::info(
      "map: session {} '{}' integrated in {:.2f} s: {} new keyframes, {} changed, PD strong {} weak {}, ND strong {} "
      "weak {}, superseded {}, restored {}; {} map points, {} bytes written",
      r.session, name, r.seconds, r.keyframes_new, r.keyframes_changed, r.pd_strong, r.pd_weak, r.nd_strong,
      r.nd_weak, r.superseded, r.restored, r.points, r.bytes);
}

void WriteCloud(const std::string& out, const PointCloud& cloud, const std::string& what) {
  map::WriteLabelledCloud(out, cloud);
  spdlog::info("map: wrote {} ({} points) to {}", what, cloud.size(), out);
}

// A map streamed from the store part by part (the region's voxel applied by tiles): memory is a
// batch of keyframes or a tile, not the map.
void WriteStreamed(const std::string& out, const map::Region& region, int threads,
                   const std::function<void(const map::PartSink&)>& parts, const std::string& what) {
  const std::size_t n = map::WriteLabelledCloudParts(out, region.voxel_m, parts, threads);
  spdlog::info("map: wrote {} ({} points) to {}", what, n, out);
}

// `map diff`: the clouds in --out (the names of an LT-removert pair folder), and with --compare
// the agreement with LT-removert's own pair output.
void RunDiff(const MapOptions& o) {
  const auto cfg = LoadMapConfig(o);
  const map::Store s = OpenStore(o, cfg);
  const map::MapDiff d =
      map::Diff(s, ResolveSession(s, o.from), ResolveSession(s, o.to), RegionOf(o, cfg), o.common.threads);
  io::StagingDir out(o.out, "nd_strong.pcd");
  map::WriteLabelledCloud(out.path() + "/pd_strong.pcd", d.pd_strong);
  map::WriteLabelledCloud(out.path() + "/pd_weak.pcd", d.pd_weak);
  map::WriteLabelledCloud(out.path() + "/nd_strong.pcd", d.nd);
  out.Publish();
  std::cout << "map diff " << o.from << " -> " << o.to << ": PD strong " << d.pd_strong.size() << ", PD weak "
            << d.pd_weak.size() << ", ND " << d.nd.size() << " points in " << d.seconds << " s -> " << o.out << "\n";
  if (o.compare.empty()) return;
  const map::PairAgreement ag = map::CompareWithLdPair(d, o.compare, cfg.nd_match_radius_m);
  const map::Agreement &a_pd = ag.pd, &a_nd = ag.nd;
  std::cout << "| vs " << o.compare << " | diff points | LT-removert points | precision | recall |\n|---|---|---|---|---|\n"
            << "| PD | " << a_pd.got << " | " << a_pd.want << " | " << a_pd.precision << " | " << a_pd.recall << " |\n"
            << "| ND strong | " << a_nd.got << " | " << a_nd.want << " | " << a_nd.precision << " | " << a_nd.recall
            << " |\n" << std::flush;
}

// The `map` subcommands share one options object; Add creates a subcommand with the common
// options (--store, --config, --set, threads) and, when asked, the pipeline folders or a region.
struct MapCommands {
  CLI::App* map_cmd;
  std::shared_ptr<MapOptions> opts;

  CLI::App* Add(const std::string& name, const std::string& help, bool dirs = false, bool region = false) const {
    MapOptions& o = *opts;
    CLI::App* c = map_cmd->add_subcommand(name, help);
    AddCommonOptions(*c, o.common);
    c->add_option("--store", o.store, "Map store file (NAME.ltmap)")->required();
    c->add_option("--config", o.config, "params_ltmap.yaml (every key optional)");
    c->add_option("--set", o.set, "Override a config key, e.g. --set object_sensor_step_deg=1.33 (repeatable)");
    if (dirs) {
      c->add_option("--aligned", o.dirs.aligned, "LT-SLAM output dir (aligned/)")->required();
      c->add_option("--changes", o.dirs.changes, "LT-removert output dir (changes/)")->required();
      c->add_option("--sessions", o.dirs.sessions, "Input session dirs root (optional: keyframe numbering)");
      c->add_option("--central", o.central,
                    "Central session name (default: the run's first session in aligned/manifest.yaml)");
    }
    if (region) {
      c->add_option("--min", o.box_min, "Box lower corner x y z [m] (world)")->expected(3);
      c->add_option("--max", o.box_max, "Box upper corner x y z [m] (world)")->expected(3);
      c->add_option("--voxel", o.voxel, "Output voxel size [m] (overrides output_voxel_m; 0 = all points)");
    }
    return c;
  }
};

void SetupInit(const MapCommands& m) {
  auto opts = m.opts;
  m.Add("init", "Create the store with the central session as base", true)->callback([opts] {
    const MapOptions& o = *opts;
    Report(map::InitFromDirs(o.store, LoadMapConfig(o), o.dirs, o.central, o.common.threads), "central");
  });
}

// The query sessions `integrate` works on: those named, else every aligned one not in the store.
std::vector<std::string> SessionsToIntegrate(const MapOptions& o, const map::Store& store) {
  if (!o.sessions.empty()) return o.sessions;
  std::vector<std::string> done, todo;
  for (const auto& s : store.Sessions()) done.push_back(s.name);
  for (const auto& n : map::AlignedSessions(o.dirs, store.Sessions().at(0).name))
    if (std::find(done.begin(), done.end(), n) == done.end()) todo.push_back(n);
  return todo;
}

void SetupIntegrate(const MapCommands& m) {
  auto opts = m.opts;
  auto* integ = m.Add("integrate", "Integrate query sessions (one transaction each); creates the store when missing", true);
  integ->add_option("--session", opts->sessions, "Query session(s) to integrate (default: all not yet integrated)");
  integ->callback([opts] {
    const MapOptions& o = *opts;
    const auto cfg = LoadMapConfig(o);
    if (!std::filesystem::exists(o.store)) Report(map::InitFromDirs(o.store, cfg, o.dirs, o.central, o.common.threads), "central");
    map::Store store = OpenStore(o, cfg, map::Store::Access::kReadWrite);
    const std::vector<std::string> todo = SessionsToIntegrate(o, store);
    for (const auto& name : todo) Report(map::IntegrateFromDirs(store, o.dirs, name), name);
    if (todo.empty()) spdlog::info("map: nothing to integrate");
  });
}

// live / meta / restore / export: one cloud of the store written to --out.
void SetupClouds(const MapCommands& m) {
  auto opts = m.opts;
  MapOptions& o = *opts;
  auto* live = m.Add("live", "Write the live map (latest state, all PD)", false, true);
  live->add_option("--out", o.out, "Output .pcd or .ply")->required();
  live->callback([opts] {
    const auto cfg = LoadMapConfig(*opts);
    const map::Store s = OpenStore(*opts, cfg);
    const map::Region r = RegionOf(*opts, cfg);
    WriteStreamed(opts->out, r, opts->common.threads, [&](const map::PartSink& f) { s.StreamLive(r, f); }, "live map");
  });
  auto* meta = m.Add("meta", "Write the meta map (strong PD only, seen-through space carved)", false, true);
  meta->add_option("--out", o.out, "Output .pcd or .ply")->required();
  meta->callback([opts] {
    const auto cfg = LoadMapConfig(*opts);
    const map::Store s = OpenStore(*opts, cfg);
    const map::Region r = RegionOf(*opts, cfg);
    WriteStreamed(opts->out, r, opts->common.threads, [&](const map::PartSink& f) { s.StreamMeta(r, f); }, "meta map");
  });
  auto* restore = m.Add("restore", "Write the map as it was at a session (chained inverse deltas)", false, true);
  restore->add_option("--session", o.session, "Session name or order")->required();
  restore->add_option("--out", o.out, "Output .pcd or .ply")->required();
  restore->callback([opts] {
    const auto cfg = LoadMapConfig(*opts);
    const map::Store s = OpenStore(*opts, cfg);
    const int k = ResolveSession(s, opts->session);
    const map::Region r = RegionOf(*opts, cfg);
    WriteStreamed(opts->out, r, opts->common.threads, [&](const map::PartSink& f) { s.StreamMapAt(k, r, f); },
                  "map as of session " + std::to_string(k));
  });
}

void RunExport(const MapOptions& o) {
  const auto cfg = LoadMapConfig(o);
  const map::Store s = OpenStore(o, cfg);
  const map::Region r = RegionOf(o, cfg);
  if (o.meta + o.changes > 1) throw Error("export: --meta and --changes exclude each other");
  if (o.changes) {
    if (o.session.empty()) throw Error("export --changes needs --session");
    WriteCloud(o.out, s.StepChanges(ResolveSession(s, o.session), r), "changes");
  } else if (o.meta) {
    WriteStreamed(o.out, r, o.common.threads, [&](const map::PartSink& f) { s.StreamMeta(r, f); }, "meta map");
  } else {
    const int k = o.session.empty() ? s.LatestSession() : ResolveSession(s, o.session);
    WriteStreamed(o.out, r, o.common.threads, [&](const map::PartSink& f) { s.StreamMapAt(k, r, f); },
                  "map as of session " + std::to_string(k));
  }
}

void SetupExport(const MapCommands& m) {
  auto opts = m.opts;
  MapOptions& o = *opts;
  auto* exp = m.Add("export", "Export the live map (or --session / --meta / --changes) with class and session fields",
                    false, true);
  exp->add_option("--session", o.session, "State as of this session (with --changes: that step's changes)");
  exp->add_flag("--meta", o.meta, "Export the meta map");
  exp->add_flag("--changes", o.changes, "Export one step's PD / ND points (needs --session)");
  exp->add_option("--out", o.out, "Output .pcd or .ply")->required();
  exp->callback([opts] { RunExport(*opts); });
}

// `map diff` options (RunDiff).
void SetupDiff(const MapCommands& m) {
  auto opts = m.opts;
  MapOptions& o = *opts;
  auto* diff = m.Add("diff", "Changes between the map as of two sessions, composed from the stored deltas (virtual LD)",
                     false, true);
  diff->add_option("--from", o.from, "Earlier state: session name or order")->required();
  diff->add_option("--to", o.to, "Later state: session name or order")->required();
  diff->add_option("--out", o.out, "Output directory: pd_strong.pcd, pd_weak.pcd, nd_strong.pcd")->required();
  diff->add_option("--compare", o.compare,
                   "An LT-removert pair folder of the same two sessions: print precision / recall against it "
                   "(points within nd_match_radius_m)");
  diff->callback([opts] { RunDiff(*opts); });
}

void RunFsck(const MapOptions& o) {
  const map::Store s = OpenStore(o, map::MapConfig());
  const map::FsckReport r = s.Fsck();
  for (const auto& p : r.problems) std::cout << "problem: " << p << '\n';
  std::cout << "fsck " << o.store << ": " << (r.ok ? "ok" : "FAILED") << " (" << r.sessions << " sessions, "
            << r.keyframes << " keyframes, " << r.blobs << " blobs, " << r.points << " points, " << r.bytes
            << " blob bytes)" << std::endl;
  if (!r.ok) throw Error(o.store + ": fsck found " + std::to_string(r.problems.size()) + " problem(s)");
}

void SetupInspect(const MapCommands& m) {
  auto opts = m.opts;
  m.Add("log", "Sessions, keyframes, points, bytes and changes per step")->callback([opts] {
    map::MapConfig cfg;
    if (!opts->config.empty()) io::LoadConfig(opts->config, cfg);
    std::cout << map::FormatLog(OpenStore(*opts, cfg)) << std::flush;
  });
  m.Add("fsck", "Verify schema, integrity, every blob's checksum and references")->callback([opts] { RunFsck(*opts); });
}

void RunObjects(const MapOptions& o) {
  auto cfg = LoadMapConfig(o);
  if (!o.sensor_session.empty()) {
    const removert::RemovertConfig defaults;
    const Session session = io::LoadSession(o.sensor_session);
    cfg = map::WithSensorStep(cfg, removert::WithSensor(defaults, removert::KeyframesOf(session)).sensor_model);
  }
  const map::Store s = OpenStore(o, cfg);
  std::vector<map::MapObject> rejected;
  const auto objs = s.Objects(&rejected);
  map::WriteObjects(o.out, objs, &rejected);
  spdlog::info("map: {} objects written to {} ({} clusters rejected, rejected.csv)", objs.size(), o.out,
               rejected.size());
}

void SetupObjects(const MapCommands& m) {
  auto opts = m.opts;
  auto* objects = m.Add("objects",
                        "Changed objects per step: clusters of strong ND / PD in observed space that pass the "
                        "geometric rules (clouds + CSV/JSON, rejected.csv)");
  objects->add_option("--out", opts->out, "Output directory")->required();
  objects->add_option("--session", opts->sensor_session,
                      "A session directory whose scans give the sensor (object_sensor_step_deg: 0)");
  objects->callback([opts] { RunObjects(*opts); });
}

void Setup(CLI::App& parent) {
  auto* map_cmd = parent.add_subcommand("map", "LT-map: delta-map store, live / meta maps, restore, objects");
  map_cmd->require_subcommand(1);
  const MapCommands m{map_cmd, std::make_shared<MapOptions>()};
  SetupInit(m);
  SetupIntegrate(m);
  SetupClouds(m);
  SetupExport(m);
  SetupDiff(m);
  SetupInspect(m);
  SetupObjects(m);
}

LTM_COMMAND(60, Setup);

}  // namespace
}  // namespace ltm::app
