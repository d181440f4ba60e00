// Finding eval inputs in the documented layouts (docs/FORMATS.md): the simulator's truth/,
// LT-SLAM's aligned/ and LT-removert's changes/.
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/io/json.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::eval {
namespace {

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (const char c : line) {
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      out.push_back(cur);
      cur.clear();
    } else if (c != '\r') {
      cur += c;
    }
  }
  out.push_back(cur);
  for (auto& s : out) {
    const auto b = s.find_first_not_of(" \t");
    const auto e = s.find_last_not_of(" \t");
    s = b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
  }
  return out;
}

// Integers appearing in a name, in order ("pair_session_00_session_01" -> 0, 1).
std::vector<long> Numbers(const std::string& s) {
  std::vector<long> out;
  for (std::size_t i = 0; i < s.size();) {
    if (std::isdigit(static_cast<unsigned char>(s[i]))) {
      std::size_t j = i;
      while (j < s.size() && std::isdigit(static_cast<unsigned char>(s[j]))) ++j;
      out.push_back(std::stol(s.substr(i, j - i)));
      i = j;
    } else {
      ++i;
    }
  }
  return out;
}

}  // namespace

std::vector<Pose> ReadPoses(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path, 0, "cannot open pose file");
  std::string line;
  std::size_t line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[line.find_first_not_of(" \t")] == '#')
      continue;
    std::istringstream ss(line);
    std::size_t n = 0;
    std::string tok;
    while (ss >> tok) ++n;
    if (n == 12) return io::ReadKittiPoses(path);
    if (n == 8) {
      std::vector<Pose> poses;
      for (const auto& sp : io::ReadTumPoses(path)) poses.push_back(sp.pose);
      return poses;
    }
    throw Error(path, line_no, "expected 12 numbers (KITTI) or 8 (TUM) per line, found " + std::to_string(n));
  }
  throw Error(path, 0, "pose file is empty");
}

std::vector<std::string> SimSessionNames(const std::string& sim_dir) {
  const std::string truth = Join(sim_dir, "truth");
  if (!fs::is_directory(truth)) throw Error(truth, 0, "not a simulator truth directory");
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(truth))
    if (e.is_directory() && e.path().filename().string().rfind("session_", 0) == 0)
      names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  if (names.empty()) throw Error(truth, 0, "no session_XX folders");
  return names;
}

std::vector<SessionTrajectory> LoadSimTrajectories(const std::string& sim_dir, const std::string& est_dir,
                                                   std::vector<std::string>* missing) {
  std::vector<SessionTrajectory> out;
  for (const auto& name : SimSessionNames(sim_dir)) {
    SessionTrajectory s;
    s.name = name;
    s.truth = ReadPoses(Join(Join(Join(sim_dir, "truth"), name), "poses_world.txt"));
    const std::string est = est_dir.empty()
                                ? Join(Join(Join(sim_dir, "sessions"), name), "optimized_poses.txt")
                                : io::layout::PosesWorldFile(est_dir, name);
    if (!fs::exists(est)) {
      if (missing) missing->push_back(name);
      continue;
    }
    s.est = ReadPoses(est);
    if (s.est.size() != s.truth.size())
      throw Error(est, 0, std::to_string(s.est.size()) + " poses but the truth has " +
                              std::to_string(s.truth.size()) + " keyframes");
    out.push_back(std::move(s));
  }
  if (out.empty())
    throw Error(est_dir.empty() ? sim_dir : est_dir, 0, "no session has estimated poses");
  return out;
}

std::map<int, std::string> ReadObjectClasses(const std::string& path) {
  std::map<int, std::string> out;
  std::ifstream in(path);
  if (!in) return out;
  std::string line;
  std::size_t line_no = 0, id_col = 0, class_col = 1;
  bool first = true;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    const auto f = SplitCsv(line);
    if (first) {
      first = false;
      if (!f.empty() && !f[0].empty() && !std::isdigit(static_cast<unsigned char>(f[0][0])) && f[0][0] != '-') {
        const auto id = std::find(f.begin(), f.end(), "id");
        const auto cls = std::find(f.begin(), f.end(), "class");
        if (id == f.end() || cls == f.end()) throw Error(path, line_no, "header needs columns 'id' and 'class'");
        id_col = std::size_t(id - f.begin());
        class_col = std::size_t(cls - f.begin());
        continue;
      }
    }
    if (f.size() <= std::max(id_col, class_col)) throw Error(path, line_no, "too few columns");
    try {
      out[std::stoi(f[id_col])] = f[class_col];
    } catch (const std::exception&) {
      throw Error(path, line_no, "object id '" + f[id_col] + "' is not an integer");
    }
  }
  return out;
}

std::vector<std::string> LabelledScanPaths(const std::string& session_truth_dir, std::size_t keyframes) {
  const std::string dir = Join(session_truth_dir, "labels");
  if (!fs::is_directory(dir)) throw Error(dir, 0, "no labelled scans");
  auto files = io::ListIndexedFiles(dir, ".ply");
  if (files.size() != keyframes)
    throw Error(dir, 0, std::to_string(files.size()) + " labelled scans but " + std::to_string(keyframes) + " poses");
  for (auto& f : files)
    if (f.find('/') == std::string::npos) f = Join(dir, f);
  return files;
}

PointCloud ReadLabelledScan(const std::string& path) {
  PointCloud scan = io::ReadPly(path);
  if (scan.cls.size() != scan.size()) throw Error(path, 0, "labelled scan has no 'class' field");
  return scan;
}

std::size_t AddSimSessionTruth(HdEvaluator& ev, const std::string& sim_dir, const std::string& session,
                               const std::vector<Pose>& T_frame_sensor, const EvalConfig& cfg) {
  const auto files = LabelledScanPaths(Join(Join(sim_dir, "truth"), session), T_frame_sensor.size());
  const std::size_t stride = std::size_t(cfg.hd_keyframe_stride);
  if (cfg.hd_near_static_m > 0.0) {
    // Static truth of the whole session (voxel near_static / 2) for the "hd near static" split.
    PointCloud ref;
    for (std::size_t k = 0; k < files.size(); k += stride) {
      const PointCloud scan = ReadLabelledScan(files[k]);
      std::vector<bool> is_static(scan.size());
      for (std::size_t i = 0; i < scan.size(); ++i) is_static[i] = scan.cls[i] == PointClass::kStatic;
      PointCloud st = scan.select(is_static);
      st.cls.clear();
      st.session.clear();
      st.object.clear();
      geometry::TransformInPlace(st, T_frame_sensor[k]);
      ref.append(geometry::VoxelDownsample(st, 0.5 * cfg.hd_near_static_m, 1));
    }
    ev.SetStaticReference(geometry::VoxelDownsample(ref, 0.5 * cfg.hd_near_static_m));
  }
  Progress progress("eval hd: labelled scans", (files.size() + cfg.hd_keyframe_stride - 1) / cfg.hd_keyframe_stride);
  std::size_t used = 0;
  for (std::size_t k = 0; k < files.size(); k += std::size_t(cfg.hd_keyframe_stride)) {
    PointCloud scan = ReadLabelledScan(files[k]);
    geometry::TransformInPlace(scan, T_frame_sensor[k]);
    ev.Add(scan, T_frame_sensor[k].translation());
    ++used;
    progress.Tick();
  }
  progress.Done();
  return used;
}

Pose TruthToEstimateFrame(const std::string& sim_dir, const std::string& aligned_dir) {
  if (!aligned_dir.empty()) {
    const auto sessions = LoadSimTrajectories(sim_dir, aligned_dir, nullptr);
    std::vector<Eigen::Vector3d> est, truth;
    for (const auto& s : sessions)
      for (std::size_t i = 0; i < s.truth.size(); ++i) {
        est.push_back(s.est[i].translation());
        truth.push_back(s.truth[i].translation());
      }
    return AlignRigid(est, truth).inverse();  // AlignRigid gives T_truth_est
  }
  const auto names = SimSessionNames(sim_dir);
  return io::ReadTransform(Join(Join(Join(sim_dir, "truth"), names.front()), "origin.txt")).inverse();
}

namespace {
// The four change clouds' files of a pair folder, `prefix` + {pd,nd}_{strong,weak}.pcd.
std::array<std::string, 4> ChangeFiles(const std::string& dir, const std::string& prefix) {
  return {Join(dir, prefix + "pd_strong.pcd"), Join(dir, prefix + "pd_weak.pcd"), Join(dir, prefix + "nd_strong.pcd"),
          Join(dir, prefix + "nd_weak.pcd")};
}
ChangeClouds ReadChangeFiles(const std::array<std::string, 4>& f) {
  return {io::ReadPcd(f[0]), io::ReadPcd(f[1]), io::ReadPcd(f[2]), io::ReadPcd(f[3])};
}
}  // namespace

ChangeClouds ReadChangeClouds(const std::string& dir) {
  if (!fs::is_directory(dir)) throw Error(dir, 0, "no such change directory");
  return ReadChangeFiles(ChangeFiles(dir, ""));
}

std::optional<ChangeClouds> ReadObjectChangeClouds(const std::string& dir) {
  const auto files = ChangeFiles(dir, "objects_");
  for (const std::string& f : files)
    if (!fs::exists(f)) return std::nullopt;
  return ReadChangeFiles(files);
}

ChangeClouds TransformChanges(const ChangeClouds& c, const Pose& T) {
  return {geometry::Transform(c.pd_strong, T), geometry::Transform(c.pd_weak, T),
          geometry::Transform(c.nd_strong, T), geometry::Transform(c.nd_weak, T)};
}

namespace {
// The residue clouds of `session` in the pairs listed by the stage's report.json (none without one).
std::vector<std::string> ResidueFiles(const std::string& changes, const std::string& session) {
  const std::string report = Join(changes, "report.json");
  if (!fs::exists(report)) return {};
  const io::json::Value doc = io::json::ParseFile(report);
  const io::json::Value* sessions = doc.Find("sessions");
  const io::json::Value* pairs = doc.Find("pairs");
  if (!sessions || !pairs) throw Error(report, 0, "no 'sessions' or 'pairs' (not an LT-removert report)");
  long position = -1;
  for (std::size_t i = 0; i < sessions->arr.size(); ++i) {
    const io::json::Value* name = sessions->arr[i].Find("name");
    if (name && name->str == session) position = long(i);
  }
  if (position < 0) throw Error(report, 0, "no session '" + session + "' among the stage's sessions");
  std::vector<std::string> files;
  for (const auto& p : pairs->arr) {
    const io::json::Value *c = p.Find("central"), *q = p.Find("query"), *dir = p.Find("dir");
    if (!c || !q || !dir) throw Error(report, 0, "a pair without 'central', 'query' or 'dir'");
    if (long(c->num) == position) files.push_back(Join(Join(changes, dir->str), "nd_residue.pcd"));
    if (long(q->num) == position) files.push_back(Join(Join(changes, dir->str), "pd_residue.pcd"));
  }
  return files;
}
}  // namespace

PointCloud CleanedSessionMap(const std::string& changes, const std::string& session, const EvalConfig& cfg,
                             int threads, std::string* note) {
  const std::string file = io::layout::StaticMapFile(changes, session);
  const PointCloud map = io::ReadCloud(file);
  PointCloud residues;
  for (const auto& f : ResidueFiles(changes, session)) residues.append(io::ReadPcd(f));
  PointCloud cleaned = WithoutPoints(map, residues, cfg, threads);
  if (note)
    *note = file + (residues.empty() ? "" : " minus " + std::to_string(map.size() - cleaned.size()) +
                                                " residues of movers the other sessions saw through");
  return cleaned;
}

std::string FindPairDir(const std::string& root, const std::string& pair) {
  if (!fs::is_directory(root)) throw Error(root, 0, "no such directory");
  const std::string direct = Join(root, "pair_" + pair);
  if (fs::is_directory(direct)) return direct;
  const auto want = Numbers(pair);
  std::vector<std::string> seen;
  if (want.size() == 2) {
    for (const auto& e : fs::directory_iterator(root)) {
      const std::string name = e.path().filename().string();
      if (!e.is_directory() || name.rfind("pair_", 0) != 0) continue;
      seen.push_back(name);
      const auto got = Numbers(name);
      if (got.size() >= 2 && got[got.size() - 2] == want[0] && got.back() == want[1]) return e.path().string();
    }
  }
  std::string list;
  for (const auto& s : seen) list += " " + s;
  throw Error(root, 0, "no pair folder for '" + pair + "' (found:" + (list.empty() ? " none" : list) + ")");
}

}  // namespace ltm::eval
