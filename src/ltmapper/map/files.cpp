// File layer: LT-SLAM and LT-removert outputs (docs/FORMATS.md) -> Store integration.
#include "ltmapper/map/files.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <unistd.h>

namespace ltm::map {
namespace {

namespace fs = std::filesystem;

// A store is built as "<store>.tmp-<pid>" (plus SQLite's -wal / -shm / -journal) and renamed.
constexpr const char* kTempInfix = ".tmp-";
constexpr std::size_t kMaxPidDigits = 9;  // pid_max is at most 2^22 (7 digits): longer is no pid

void RemoveStoreFiles(const std::string& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) fs::remove(path + suffix, ec);
}

// Removes the temporaries of `store_path` left by creating processes that no longer run (a
// kill during `map init` left "<store>.tmp-<pid>" and a -wal of up to tens of MB behind).
void RemoveStaleTemps(const std::string& store_path) {
  const fs::path store(store_path);
  const fs::path dir = store.has_parent_path() ? store.parent_path() : fs::path(".");
  const std::string prefix = store.filename().string() + kTempInfix;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = name.substr(prefix.size());
    const std::size_t digits = rest.find_first_not_of("0123456789");
    const std::string suffix = digits == std::string::npos ? "" : rest.substr(digits);
    if (digits == 0 || rest.size() - suffix.size() > kMaxPidDigits) continue;  // not "<pid>[suffix]"
    if (suffix != "" && suffix != "-wal" && suffix != "-shm" && suffix != "-journal") continue;
    const pid_t pid = pid_t(std::stol(rest.substr(0, rest.size() - suffix.size())));
    if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // alive (or another user's): not ours to remove
    spdlog::info("map: removing {} (left by process {}, which no longer runs)", entry.path().string(), pid);
    fs::remove(entry.path(), ec);
  }
}

PointCloud ReadIfExists(const std::string& path) {
  return fs::exists(path) ? io::ReadPcd(path) : PointCloud{};
}

std::size_t PointsIfExists(const std::string& path) {
  return fs::exists(path) ? io::ReadPcdPointCount(path) : 0;
}

PointCloud WithClass(PointCloud c, PointClass cls) {
  c.cls.assign(c.size(), cls);
  c.session.clear();
  c.object.clear();
  return c;
}

// keyframes.csv of a pair: kind,session,index,<6 counts>,<12 pose numbers>. Returns
// (kind, index) -> T_world_sensor.
std::map<std::pair<std::string, int>, Pose> ReadKeyframesCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (LT-removert keyframe list)");
  std::map<std::pair<std::string, int>, Pose> out;
  std::string line;
  std::size_t no = 0;
  while (std::getline(in, line)) {
    ++no;
    if (no == 1 || line.empty()) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string t; std::getline(ss, t, ',');) f.push_back(t);
    if (f.size() != 21) throw Error(path, no, "expected 21 comma-separated fields, got " + std::to_string(f.size()));
    Pose T = Pose::Identity();
    try {
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) T.matrix()(r, c) = std::stod(f[std::size_t(9 + 4 * r + c)]);
      out[{f[0], std::stoi(f[2])}] = T;
    } catch (const std::exception&) {
      throw Error(path, no, "bad number");
    }
  }
  return out;
}

// Indices of the keyframes of `kind` listed in a pair's keyframes.csv whose folder exists under
// `dir` (LT-removert writes none with out.write_keyframes off), in index order.
std::vector<int> ListedKeyframes(const std::map<std::pair<std::string, int>, Pose>& rows, const std::string& kind,
                                 const std::string& dir) {
  std::vector<int> out;
  for (const auto& [key, T] : rows)
    if (key.first == kind && fs::is_directory(dir + "/" + io::layout::KeyframeDirName(key.second)))
      out.push_back(key.second);
  return out;
}

KeyframeDelta ReadDelta(const std::string& d, int index) {
  KeyframeDelta kd;
  kd.keyframe = index;
  kd.pd_strong = ReadIfExists(d + "pd_strong.pcd");
  kd.pd_weak = ReadIfExists(d + "pd_weak.pcd");
  kd.nd_strong = ReadIfExists(d + "nd_strong.pcd");
  kd.nd_weak = ReadIfExists(d + "nd_weak.pcd");
  return kd;
}

std::string PairDir(const PipelineDirs& dirs, const std::vector<std::string>& names, int c, int q) {
  const std::string a = dirs.changes + "/" + io::layout::PairDirName(c, q);
  if (fs::is_directory(a)) return a;
  const std::string b = dirs.changes + "/pair_" + names[std::size_t(c)] + "_" + names[std::size_t(q)];
  if (fs::is_directory(b)) return b;
  return "";
}

Pose ReadAnchor(const PipelineDirs& dirs, const std::string& name) {
  const std::string p = io::layout::AnchorFile(dirs.aligned, name);
  return fs::exists(p) ? io::ReadTransform(p) : Pose::Identity();
}

// What the store records of an aligned session: its name, anchor, the config text and its
// trajectory (LT-SLAM's world poses of every keyframe).
SessionMeta AlignedSessionMeta(const PipelineDirs& dirs, const std::string& name, const std::string& params) {
  return {name, ReadAnchor(dirs, name), params, io::ReadKittiPoses(io::layout::PosesWorldFile(dirs.aligned, name))};
}

// The input folder of a session: from the run manifest, else <dirs.sessions>/<name>, else "".
std::string SessionInputDir(const PipelineDirs& dirs, const std::string& name) {
  if (io::HasRunManifest(dirs.aligned))
    for (const auto& s : io::ReadRunManifest(dirs.aligned).sessions)
      if (s.name == name) return s.dir;
  if (!dirs.sessions.empty() && fs::is_directory(dirs.sessions + "/" + name)) return dirs.sessions + "/" + name;
  return "";
}

// Keyframe indices of a session in pose-file order: from the input session dir when known, else
// 0..n-1 (the simulator's and savers' numbering).
std::vector<int> KeyframeIndices(const PipelineDirs& dirs, const std::string& name, std::size_t n) {
  std::vector<int> idx(n);
  const std::string input = SessionInputDir(dirs, name);
  if (!input.empty()) {
    const Session s = io::LoadSession(input);
    if (s.keyframes.size() != n)
      throw Error(io::layout::PosesWorldFile(dirs.aligned, name) + ": " + std::to_string(n) +
                  " poses but the session has " + std::to_string(s.keyframes.size()) + " keyframes");
    for (std::size_t k = 0; k < n; ++k) idx[k] = s.keyframes[k].index;
  } else {
    for (std::size_t k = 0; k < n; ++k) idx[k] = int(k);
  }
  return idx;
}

}  // namespace

namespace {
// Without a run manifest (folders made by hand or by an older ltmapper): the folders holding
// world poses, sorted by name.
std::vector<std::string> ListedSessions(const PipelineDirs& dirs) {
  spdlog::warn("map: {} has no run manifest: taking the session order from the folder names", dirs.aligned);
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dirs.aligned))
    if (e.is_directory() && fs::exists(e.path() / "poses_world.txt")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}
}  // namespace

std::vector<std::string> AlignedSessions(const PipelineDirs& dirs, const std::string& central) {
  if (!fs::is_directory(dirs.aligned)) throw Error(dirs.aligned + ": LT-SLAM output directory not found");
  std::vector<std::string> names;
  if (io::HasRunManifest(dirs.aligned)) {
    for (const auto& s : io::ReadRunManifest(dirs.aligned).Aligned()) names.push_back(s.name);
  } else {
    names = ListedSessions(dirs);
  }
  if (names.empty()) throw Error(dirs.aligned + ": no <session>/poses_world.txt (LT-SLAM output)");
  if (!central.empty() && io::HasRunManifest(dirs.aligned) && central != names[0])
    throw Error(io::layout::ManifestFile(dirs.aligned) + ": the central session of this run is '" + names[0] +
                "', not '" + central + "' (LT-removert's pair folders are numbered in the run's order)");
  if (!central.empty()) {
    auto it = std::find(names.begin(), names.end(), central);
    if (it == names.end()) throw Error(dirs.aligned + ": no session named '" + central + "'");
    names.erase(it);
    names.insert(names.begin(), central);
  }
  return names;
}

IntegrationResult InitFromDirs(const std::string& store_path, const MapConfig& cfg, const PipelineDirs& dirs,
                               const std::string& central, int threads) {
  const auto names = AlignedSessions(dirs, central);
  const std::string& cname = names[0];
  if (fs::exists(store_path)) throw Error(store_path + ": map store already exists");
  // Central keyframes: poses and static clouds from the first pair directory; else the central
  // static map split by nearest keyframe.
  // Read chunk by chunk while the store encodes them (memory: a chunk, not the session).
  KeyframeSource src;
  std::vector<KeyframeInput> kfs;  // without a pair directory: split from the static map in memory
  std::string pair;
  for (std::size_t q = 1; q < names.size() && pair.empty(); ++q) pair = PairDir(dirs, names, 0, int(q));
  if (!pair.empty()) {
    const auto poses = ReadKeyframesCsv(pair + "/keyframes.csv");
    for (const auto& [key, T] : poses)  // (kind, index) order: the central keyframes by index
      if (key.first == "central") src.keyframes.push_back({key.second, T, 0});
    src.read = [&src, pair](std::size_t k) {
      return ReadIfExists(pair + "/keyframes/" + io::layout::KeyframeDirName(src.keyframes[k].index) + "/static.pcd");
    };
    spdlog::info("map init: {} central keyframes from {}", src.keyframes.size(), pair);
  } else {
    const std::string smap = io::layout::StaticMapFile(dirs.changes, cname);
    const auto poses = io::ReadKittiPoses(io::layout::PosesWorldFile(dirs.aligned, cname));
    const auto idx = KeyframeIndices(dirs, cname, poses.size());
    const PointCloud world = io::ReadPcd(smap);
    PointCloud positions;
    for (const auto& T : poses) positions.push_back(float(T.translation().x()), float(T.translation().y()), float(T.translation().z()));
    const geometry::KdTree tree(positions);
    std::vector<std::vector<std::uint32_t>> own(poses.size());
    for (std::size_t i = 0; i < world.size(); ++i) {
      std::uint32_t k;
      float d2;
      if (tree.Nearest(world.points[i].xyz(), &k, &d2)) own[k].push_back(std::uint32_t(i));
    }
    for (std::size_t k = 0; k < poses.size(); ++k)
      kfs.push_back({idx[k], poses[k], geometry::Transform(world.select(own[k]), poses[k].inverse())});
    spdlog::info("map init: no pair directory; {} keyframes from {}", kfs.size(), smap);
    src = InMemory(kfs);
  }
  RemoveStaleTemps(store_path);
  const std::string tmp = store_path + kTempInfix + std::to_string(::getpid());
  RemoveStoreFiles(tmp);
  IntegrationResult r;
  try {
    Store store = Store::Create(tmp, cfg, Store::Creation::kUnpublished);
    store.set_threads(threads);
    r = store.IntegrateBaseFrom(AlignedSessionMeta(dirs, cname, ConfigToString(cfg)), src);
    store.Close();
  } catch (...) {
    RemoveStoreFiles(tmp);
    throw;
  }
  // The store is closed (synced to disk): publish it with one rename.
  fs::rename(tmp, store_path);
  return r;
}

IntegrationResult IntegrateFromDirs(Store& store, const PipelineDirs& dirs, const std::string& query) {
  const auto sessions = store.Sessions();
  if (sessions.empty()) throw Error(store.path() + ": empty map store (run map init)");
  const auto names = AlignedSessions(dirs, sessions[0].name);
  const auto it = std::find(names.begin(), names.end(), query);
  if (it == names.end()) throw Error(dirs.aligned + ": no session named '" + query + "'");
  const int qi = int(it - names.begin());
  if (qi == 0) throw Error("session '" + query + "' is the central session");
  // Changes against the central session (LT-removert's default pairing), else against the
  // previous session (consecutive pairing; its keyframes must be map keyframes).
  int ci = 0;
  std::string pair = PairDir(dirs, names, 0, qi);
  if (pair.empty()) {
    ci = qi - 1;
    pair = PairDir(dirs, names, ci, qi);
  }
  if (pair.empty())
    throw Error(dirs.changes + ": no LT-removert pair directory for '" + names[0] + "' -> '" + query + "'");
  // The pair's keyframes.csv is its manifest: only the keyframe folders it lists are read.
  const auto poses = ReadKeyframesCsv(pair + "/keyframes.csv");
  const std::vector<int> kidx = ListedKeyframes(poses, "central", pair + "/keyframes");
  const std::vector<int> nidx = ListedKeyframes(poses, "new", pair + "/new_keyframes");
  // Read keyframe by keyframe while the store steps its chunks (memory: a chunk, not the session);
  // a new keyframe's point count comes from its PCD headers.
  DeltaSource deltas;
  deltas.keyframes = kidx;
  deltas.read = [&](std::size_t k) {
    return ReadDelta(pair + "/keyframes/" + io::layout::KeyframeDirName(kidx[k]) + "/", kidx[k]);
  };
  auto new_dir = [&](std::size_t k) { return pair + "/new_keyframes/" + io::layout::KeyframeDirName(nidx[k]) + "/"; };
  KeyframeSource fresh;
  fresh.keyframes.resize(nidx.size());
  ParallelFor(nidx.size(), store.threads(), [&](std::size_t k) {
    const std::string d = new_dir(k);
    fresh.keyframes[k] = {nidx[k], poses.at({"new", nidx[k]}),
                          PointsIfExists(d + "pd_strong.pcd") + PointsIfExists(d + "pd_weak.pcd")};
  });
  fresh.read = [&](std::size_t k) {
    const std::string d = new_dir(k);
    PointCloud cloud = WithClass(ReadIfExists(d + "pd_strong.pcd"), PointClass::kPDStrong);
    cloud.append(WithClass(ReadIfExists(d + "pd_weak.pcd"), PointClass::kPDWeak));
    return cloud;
  };
  spdlog::info("map integrate: {} from {} ({} reference keyframes, {} new-territory keyframes)", query, pair,
               kidx.size(), nidx.size());
  return store.IntegrateSessionFrom(AlignedSessionMeta(dirs, query, ConfigToString(store.config())),
                                    names[std::size_t(ci)], deltas, fresh);
}

}  // namespace ltm::map
