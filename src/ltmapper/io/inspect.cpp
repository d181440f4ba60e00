// `ltmapper info`: what a session holds and what is wrong with it. Unlike LoadSession this goes
// on after a problem, so a user sees every problem at once.
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/session.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <limits>
#include <map>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::io {
namespace {

struct IndexedFile {
  int index = 0;
  std::string path;
};

std::string IdList(const std::vector<int>& ids, std::size_t max = 10) {
  std::ostringstream ss;
  for (std::size_t i = 0; i < ids.size() && i < max; ++i) ss << (i ? ", " : "") << ids[i];
  if (ids.size() > max) ss << ", ... (" << ids.size() << " in all)";
  return ss.str();
}

// Like ListIndexedFiles, but bad names and duplicate indices become problems (and a load error).
std::vector<IndexedFile> ListLenient(const std::string& dir, const std::string& ext, SessionInfo& info) {
  std::vector<IndexedFile> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file() || entry.path().extension().string() != ext) continue;
    try {
      files.push_back({FileIndex(entry.path().string()), entry.path().string()});
    } catch (const Error& e) {
      info.problems.push_back(e.what());
      if (info.load_error.empty()) info.load_error = e.what();
    }
  }
  std::sort(files.begin(), files.end(),
            [](const IndexedFile& a, const IndexedFile& b) { return a.index != b.index ? a.index < b.index : a.path < b.path; });
  std::vector<IndexedFile> unique;
  for (auto& f : files) {
    if (!unique.empty() && unique.back().index == f.index) {
      const std::string msg = dir + ": duplicate index " + std::to_string(f.index) + ": " +
                              fs::path(unique.back().path).filename().string() + " and " +
                              fs::path(f.path).filename().string();
      info.problems.push_back(msg);
      if (info.load_error.empty()) info.load_error = msg;
      continue;
    }
    unique.push_back(std::move(f));
  }
  return unique;
}

void PoseStats(const std::vector<Pose>& poses, SessionInfo& info) {
  if (poses.empty()) return;
  info.bbox_min = info.bbox_max = poses.front().translation();
  info.path_length_m = 0.0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Vector3d t = poses[i].translation();
    info.bbox_min = info.bbox_min.cwiseMin(t);
    info.bbox_max = info.bbox_max.cwiseMax(t);
    if (i > 0) info.path_length_m += (t - poses[i - 1].translation()).norm();
  }
}

// Reads every scan (in parallel): sizes, non-finite counts, empty and unreadable scans, raw sweeps
// (scans with per-point times).
void ScanStats(const std::vector<IndexedFile>& scans, SessionInfo& info) {
  struct Result {
    std::size_t points = 0, non_finite = 0;
    bool raw = false;
    std::string error;
  };
  std::vector<Result> results(scans.size());
  tbb::parallel_for(std::size_t(0), scans.size(), [&](std::size_t i) {
    try {
      CloudReadStats st;
      const PointCloud c = ReadCloud(scans[i].path, &st);
      results[i].points = c.size();
      results[i].raw = !c.time.empty();
      results[i].non_finite = st.non_finite_dropped;
    } catch (const std::exception& e) {
      results[i].error = e.what();
    }
  });
  info.points_min = std::numeric_limits<std::size_t>::max();
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const Result& r = results[i];
    if (!r.error.empty()) {
      info.problems.push_back("unreadable scan: " + r.error);
      if (info.load_error.empty()) info.load_error = r.error;
      continue;
    }
    ++info.scans_read;
    info.points_min = std::min(info.points_min, r.points);
    info.points_max = std::max(info.points_max, r.points);
    info.points_total += r.points;
    info.non_finite_points += r.non_finite;
    info.raw_sweeps += r.raw;
    if (r.points == 0)
      info.problems.push_back("empty scan: " + scans[i].path + " has 0 points" +
                              (r.non_finite ? " (after dropping " + std::to_string(r.non_finite) + " NaN/Inf points)" : ""));
  }
  if (info.scans_read == 0) info.points_min = 0;
}

// Whether the loaded session's raw sweeps can be deskewed (LoadSession read keyframe times); raw
// sweeps that cannot are a problem, and why the stages would fail on them.
void NoteRawSweeps(const Session* loaded, SessionInfo& info) {
  info.keyframe_times = loaded && !loaded->keyframes.empty() && loaded->keyframes.front().sweep.known;
  if (info.raw_sweeps > 0 && !info.keyframe_times) {
    const std::string p = std::to_string(info.raw_sweeps) +
                          " raw sweeps (per-point 'time' field) but no keyframe times to deskew them: put times.txt "
                          "beside the scans (one timestamp [s] per line, line i for scan i) or give TUM poses";
    info.problems.push_back(p);
    if (info.load_error.empty()) info.load_error = p;
  }
}

}  // namespace

// Layouts other than SC-LIO-SAM: what the loader reads, then the pose and scan statistics.
SessionInfo InspectLoaded(const std::string& dir, const SessionLayout& layout, bool read_scans) {
  SessionInfo info;
  info.dir = dir;
  info.layout = layout.name;
  info.pose_source = layout.poses.empty() ? "VIEWPOINT of each scan" : layout.poses;
  const auto scans = ListLenient(layout.scans_dir, layout.scan_ext, info);
  info.scans_found = scans.size();
  std::optional<Session> s;
  try {
    s = LoadSession(dir);
    std::vector<Pose> poses;
    for (const Keyframe& kf : s->keyframes) poses.push_back(kf.T_session_sensor);
    info.keyframes = poses.size();
    info.odometry_edges = s->odometry.size();
    info.loop_edges = s->loops.size();
    PoseStats(poses, info);
  } catch (const Error& e) {
    info.load_error = e.what();
    info.problems.push_back(e.what());
  }
  if (read_scans) ScanStats(scans, info);
  NoteRawSweeps(s ? &*s : nullptr, info);
  return info;
}

namespace {
// SCDs/ against Scans/: descriptors missing (computed later) or without a scan.
void CheckScds(const fs::path& root, const std::set<int>& scan_ids, SessionInfo& info) {
  std::error_code ec;
  const std::string scd_dir = (root / "SCDs").string();
  if (!fs::is_directory(scd_dir, ec)) return;
  const auto scds = ListLenient(scd_dir, ".scd", info);
  info.scds_found = scds.size();
  std::set<int> scd_ids;
  for (const auto& s : scds) scd_ids.insert(s.index);
  std::vector<int> no_scd, no_scan;
  for (int id : scan_ids)
    if (!scd_ids.count(id)) no_scd.push_back(id);
  for (int id : scd_ids)
    if (!scan_ids.count(id)) no_scan.push_back(id);
  if (!no_scd.empty()) info.problems.push_back("SCDs/: no descriptor for scans " + IdList(no_scd) + " (they will be computed)");
  if (!no_scan.empty()) info.problems.push_back("SCDs/: descriptors without a scan: " + IdList(no_scan));
}

// The g2o's vertices (poses in id order) against the scans, its edges counted as odometry
// (neighbouring vertices) or loops; optimized_poses.txt beside it checked for the same count.
std::vector<Pose> G2oPoses(const std::string& g2o_path, const std::string& kitti_path, const std::set<int>& scan_ids,
                           std::size_t scans, SessionInfo& info) {
  std::vector<Pose> poses;
  info.pose_source = "singlesession_posegraph.g2o";
  try {
    const G2oGraph g = ReadG2o(g2o_path);
    std::map<int, Pose> by_id(g.vertices.begin(), g.vertices.end());
    std::map<int, int> position;
    for (const auto& [id, T] : by_id) {
      position[id] = int(poses.size());
      poses.push_back(T);
    }
    info.keyframes = by_id.size();
    std::vector<int> missing, extra;
    for (const auto& [id, T] : by_id)
      if (!scan_ids.count(id)) missing.push_back(id);
    for (int id : scan_ids)
      if (!by_id.count(id)) extra.push_back(id);
    if (!missing.empty()) info.problems.push_back("missing scans: g2o vertices without Scans/ file: " + IdList(missing));
    if (!extra.empty()) info.problems.push_back("extra scans without poses (no g2o vertex): " + IdList(extra));
    if (by_id.size() != scans)
      info.problems.push_back("count mismatch: " + std::to_string(by_id.size()) + " g2o vertices, " +
                              std::to_string(scans) + " scans");
    for (const auto& e : g.edges) (std::abs(position[e.from] - position[e.to]) == 1 ? info.odometry_edges : info.loop_edges)++;
  } catch (const Error& e) {
    info.problems.push_back(e.what());
  }
  std::error_code ec;
  if (!fs::exists(kitti_path, ec)) return poses;
  try {
    const auto kp = ReadKittiPoses(kitti_path);
    if (kp.size() != info.keyframes)
      info.problems.push_back("optimized_poses.txt has " + std::to_string(kp.size()) + " poses, the g2o " +
                              std::to_string(info.keyframes) + " vertices (the g2o is used)");
  } catch (const Error& e) {
    info.problems.push_back(std::string(e.what()) + " (not used: the g2o gives the poses)");
  }
  return poses;
}

std::vector<Pose> KittiPoses(const std::string& kitti_path, std::size_t scans, SessionInfo& info) {
  std::vector<Pose> poses;
  info.pose_source = "optimized_poses.txt";
  try {
    poses = ReadKittiPoses(kitti_path);
    info.keyframes = poses.size();
    if (poses.size() != scans)
      info.problems.push_back("count mismatch: pose count != scan count: " + std::to_string(poses.size()) +
                              " poses in optimized_poses.txt, " + std::to_string(scans) + " scans in Scans/");
    if (poses.size() > 1) info.odometry_edges = poses.size() - 1;
  } catch (const Error& e) {
    info.problems.push_back(e.what());
  }
  return poses;
}

// An SC-LIO-SAM folder: Scans/ (and SCDs/) with the g2o or optimized_poses.txt.
SessionInfo InspectScLioSam(const std::string& dir, bool read_scans) {
  std::error_code ec;
  const fs::path root(dir);
  const std::string scans_dir = (root / "Scans").string();
  if (!fs::is_directory(scans_dir, ec))
    throw Error(dir + ": missing Scans/ folder (expected Scans/NNNNNN.pcd keyframe scans)");
  SessionInfo info;
  info.dir = dir;
  info.layout = "sc-lio-sam";
  const auto scans = ListLenient(scans_dir, ".pcd", info);
  info.scans_found = scans.size();
  if (scans.empty()) info.problems.push_back(scans_dir + ": no .pcd scans");
  std::set<int> scan_ids;
  for (const auto& s : scans) scan_ids.insert(s.index);
  CheckScds(root, scan_ids, info);
  const std::string g2o_path = (root / "singlesession_posegraph.g2o").string();
  const std::string kitti_path = (root / "optimized_poses.txt").string();
  std::vector<Pose> poses;
  if (fs::exists(g2o_path, ec)) {
    poses = G2oPoses(g2o_path, kitti_path, scan_ids, scans.size(), info);
  } else if (fs::exists(kitti_path, ec)) {
    poses = KittiPoses(kitti_path, scans.size(), info);
  } else {
    info.pose_source = "none";
    info.problems.push_back("no poses: neither singlesession_posegraph.g2o nor optimized_poses.txt");
  }
  PoseStats(poses, info);
  if (read_scans) ScanStats(scans, info);
  std::optional<Session> s;
  try {
    s = LoadSession(dir);
  } catch (const Error& e) {
    info.load_error = e.what();
  }
  NoteRawSweeps(s ? &*s : nullptr, info);
  return info;
}
}  // namespace

SessionInfo InspectSession(const std::string& dir, bool read_scans) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir + ": no such session directory");
  const fs::path root(dir);
  // Scans/ without a pose file is an SC-LIO-SAM session with a problem, listed then.
  if (!fs::is_directory(root / "Scans", ec) || (!fs::exists(root / "singlesession_posegraph.g2o", ec) &&
                                                !fs::exists(root / "optimized_poses.txt", ec))) {
    try {
      const SessionLayout layout = DetectSessionLayout(dir);
      return InspectLoaded(dir, layout, read_scans);
    } catch (const Error&) {
      if (!fs::is_directory(root / "Scans", ec)) throw;
    }
  }
  return InspectScLioSam(dir, read_scans);
}

SessionInfo InspectKittiSession(const std::string& dir, const std::string& poses_path,
                                const Pose* T_cam_velo, bool read_scans) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir + ": no such KITTI sequence directory");
  const std::string velo_dir = (fs::path(dir) / "velodyne").string();
  if (!fs::is_directory(velo_dir, ec))
    throw Error(dir + ": missing velodyne/ folder (expected velodyne/NNNNNN.bin)");
  SessionInfo info;
  info.dir = dir;
  info.layout = "kitti-odometry";
  info.pose_source = poses_path + (T_cam_velo ? " (camera poses, with Tr)" : "");
  const auto scans = ListLenient(velo_dir, ".bin", info);
  info.scans_found = scans.size();
  if (scans.empty()) info.problems.push_back(velo_dir + ": no .bin scans");
  std::vector<Pose> poses;
  try {
    const auto all = ReadKittiPoses(poses_path);
    const Pose Tr = T_cam_velo ? *T_cam_velo : Pose::Identity();
    std::vector<int> no_pose;
    for (const auto& s : scans) {
      if (s.index >= 0 && std::size_t(s.index) < all.size())
        poses.push_back(Tr.inverse() * all[std::size_t(s.index)] * Tr);
      else
        no_pose.push_back(s.index);
    }
    if (!no_pose.empty())
      info.problems.push_back("extra scans without poses (" + std::to_string(all.size()) +
                              " lines in the poses file): " + IdList(no_pose));
  } catch (const Error& e) {
    info.problems.push_back(e.what());
  }
  info.keyframes = poses.size();
  if (poses.size() > 1) info.odometry_edges = poses.size() - 1;
  PoseStats(poses, info);
  if (read_scans) ScanStats(scans, info);
  std::optional<Session> s;
  if (info.load_error.empty()) {
    try {
      s = LoadKittiSession(dir, poses_path, T_cam_velo);
    } catch (const Error& e) {
      info.load_error = e.what();
    }
  }
  NoteRawSweeps(s ? &*s : nullptr, info);
  return info;
}

namespace {
// "x [..]  y [..]  z [..] m" of a box, tiny values as 0 (no "-0.00").
std::string BoxText(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  auto c = [](double v) { return std::abs(v) < 0.005 ? 0.0 : v; };
  char buf[160];
  std::snprintf(buf, sizeof(buf), "x [%.2f, %.2f]  y [%.2f, %.2f]  z [%.2f, %.2f] m", c(lo.x()), c(hi.x()), c(lo.y()),
                c(hi.y()), c(lo.z()), c(hi.z()));
  return buf;
}
}  // namespace

std::string FormatSessionInfo(const SessionInfo& info) {
  std::ostringstream os;
  char buf[256];
  os << "session " << info.dir << "\n";
  os << "  layout:          " << info.layout << "\n";
  os << "  keyframes:       " << info.keyframes << " (poses from " << info.pose_source << ")\n";
  os << "  scans:           " << info.scans_found << " found, " << info.scds_found << " SCDs"
     << (info.scds_found == 0 ? " (Scan Context computed when needed)" : "") << "\n";
  if (info.scans_read > 0) {
    std::snprintf(buf, sizeof(buf), "min %zu / mean %.0f / max %zu (%zu points in %zu scans read)",
                  info.points_min, double(info.points_total) / double(info.scans_read), info.points_max,
                  info.points_total, info.scans_read);
    os << "  points per scan: " << buf << "\n";
    os << "  non-finite:      " << info.non_finite_points << " NaN/Inf points dropped\n";
    if (info.raw_sweeps > 0)
      os << "  sweeps:          " << info.raw_sweeps << " raw (per-point time), "
         << (info.keyframe_times ? "deskewed on load with the keyframe times" : "NOT deskewable: no keyframe times")
         << "\n";
  } else {
    os << "  points per scan: not read\n";
  }
  if (info.keyframes > 0) {
    const Eigen::Vector3d e = info.bbox_max - info.bbox_min;
    std::snprintf(buf, sizeof(buf), " (extent %.2f x %.2f x %.2f m)", e.x(), e.y(), e.z());
    os << "  pose bbox:       " << BoxText(info.bbox_min, info.bbox_max) << buf << "\n";
    std::snprintf(buf, sizeof(buf), "%.2f m", info.path_length_m);
    os << "  path length:     " << buf << "\n";
  }
  os << "  edges:           " << info.odometry_edges << " odometry, " << info.loop_edges << " loops\n";
  if (info.problems.empty()) {
    os << "  problems:        none\n";
  } else {
    os << "  PROBLEMS (" << info.problems.size() << "):\n";
    for (const auto& p : info.problems) os << "    - " << p << "\n";
  }
  if (!info.load_error.empty()) os << "  CANNOT LOAD:     " << info.load_error << "\n";
  return os.str();
}

CloudInfo InspectCloud(const std::string& path, PointCloud* out) {
  CloudInfo info;
  info.path = path;
  CloudReadStats st;
  PointCloud c = ReadCloud(path, &st);
  info.points_in_file = st.points_in_file;
  info.non_finite = st.non_finite_dropped;
  info.points = c.size();
  info.labels = !c.cls.empty() || !c.session.empty() || !c.object.empty();
  info.times = !c.time.empty();
  if (info.times) {
    const auto [lo, hi] = std::minmax_element(c.time.begin(), c.time.end());
    info.time_min_s = *lo, info.time_max_s = *hi;
  }
  std::vector<double> range;
  range.reserve(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3d p = c.points[i].xyz().cast<double>();
    info.bbox_min = i == 0 ? p : info.bbox_min.cwiseMin(p);
    info.bbox_max = i == 0 ? p : info.bbox_max.cwiseMax(p);
    range.push_back(p.norm());
  }
  if (!range.empty()) {
    info.range_median_m = UpperMedian(range);
    info.range_min_m = *std::min_element(range.begin(), range.end());
    info.range_max_m = *std::max_element(range.begin(), range.end());
  }
  if (fs::path(path).extension() == ".pcd") {
    info.T_viewpoint = ReadPcdViewpoint(path);
    info.viewpoint = !info.T_viewpoint.isApprox(Pose::Identity());
  }
  if (out) *out = std::move(c);
  return info;
}

std::string FormatCloudInfo(const CloudInfo& info) {
  std::ostringstream os;
  char buf[256];
  os << "cloud " << info.path << "\n";
  std::snprintf(buf, sizeof(buf), "%zu (%zu in the file, %zu NaN/Inf dropped)", info.points, info.points_in_file,
                info.non_finite);
  os << "  points:          " << buf << "\n";
  os << "  fields:          x y z intensity" << (info.labels ? " class session object" : "");
  if (info.times) {
    std::snprintf(buf, sizeof(buf), " time (%.4f .. %.4f s: a raw sweep)", info.time_min_s, info.time_max_s);
    os << buf;
  }
  os << "\n";
  if (info.points > 0) {
    os << "  bbox:            " << BoxText(info.bbox_min, info.bbox_max) << "\n";
    std::snprintf(buf, sizeof(buf), "min %.2f / median %.2f / max %.2f m from the origin", info.range_min_m,
                  info.range_median_m, info.range_max_m);
    os << "  range:           " << buf << "\n";
  }
  if (info.viewpoint) {
    const Eigen::Vector3d t = info.T_viewpoint.translation();
    std::snprintf(buf, sizeof(buf), "sensor at (%.2f, %.2f, %.2f): points in the world frame (KTH layout)", t.x(),
                  t.y(), t.z());
    os << "  viewpoint:       " << buf << "\n";
  }
  return os.str();
}

}  // namespace ltm::io
