// Session directories (SC-LIO-SAM / SC-A-LOAM / FAST-LIO savers) and the KITTI odometry layout.
//
// Rule for matching poses to scans:
//  * g2o: a vertex id IS a scan index: VERTEX id k is the pose of Scans/k.pcd (any zero padding).
//    The set of vertex ids must equal the set of scan indices (SC-LIO-SAM numbers both 0..n-1).
//    An edge joining keyframes adjacent in index order is odometry, any other edge a loop (for
//    contiguous indices this is the usual |to - from| == 1).
//  * optimized_poses.txt: line i is the pose of the i-th scan in index order; counts must agree.
//    Odometry edges are derived from consecutive poses (has_information = false).
//  * KITTI: line i of the poses file is the pose of velodyne/i.bin (the file may be longer).
#include "ltmapper/io/files.hpp"
#include "ltmapper/io/session.hpp"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::io {
namespace {
// Keyframe times beside the scans (KITTI's name and rule: line i is the time of scan i).
constexpr const char* kTimesFile = "times.txt";

std::string BaseName(const std::string& dir) {
  fs::path p(dir);
  if (p.filename().empty()) p = p.parent_path();  // "a/b/" -> "b"
  return p.filename().string();
}

std::string IndexList(const std::vector<int>& ids, std::size_t max = 8) {
  std::ostringstream ss;
  for (std::size_t i = 0; i < ids.size() && i < max; ++i) ss << (i ? ", " : "") << ids[i];
  if (ids.size() > max) ss << ", ... (" << ids.size() << " in all)";
  return ss.str();
}

void DeriveOdometry(Session& s) {
  s.odometry.clear();
  for (std::size_t i = 1; i < s.keyframes.size(); ++i) {
    Edge e;
    e.from = s.keyframes[i - 1].index;
    e.to = s.keyframes[i].index;
    e.T_from_to = s.keyframes[i - 1].T_session_sensor.inverse() * s.keyframes[i].T_session_sensor;
    e.has_information = false;
    s.odometry.push_back(e);
  }
}

// Each keyframe's sweep motion from its times and poses: the constant velocity of the step to the
// next keyframe (the last keyframe: of the step before it), in the keyframe's sensor frame.
void SweepMotions(Session& s) {
  const std::size_t n = s.keyframes.size();
  if (n < 2) return;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t a = i + 1 < n ? i : i - 1;
    const Keyframe &ka = s.keyframes[a], &kb = s.keyframes[a + 1];
    const double dt = kb.time_s - ka.time_s;
    if (!(dt > 0.0))
      throw Error(s.dir + ": keyframe times must increase with the scan index (scan " + std::to_string(ka.index) +
                  " at " + std::to_string(ka.time_s) + " s, scan " + std::to_string(kb.index) + " at " +
                  std::to_string(kb.time_s) + " s)");
    const Pose d = ka.T_session_sensor.inverse() * kb.T_session_sensor;
    const Eigen::AngleAxisd aa(d.linear());
    SweepMotion& m = s.keyframes[i].sweep;
    m.known = true;
    m.v_mps = d.translation() / dt;
    m.w_radps = aa.angle() * aa.axis() / dt;
  }
}

// times.txt beside the scans (KITTI's rule: line i is the time of scan i), when there is one.
void ReadTimesFile(Session& s) {
  const fs::path file = fs::path(s.dir) / kTimesFile;
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return;
  const std::vector<double> t = ReadTimes(file.string());
  for (auto& kf : s.keyframes) {
    if (kf.index < 0 || std::size_t(kf.index) >= t.size())
      throw Error(file.string() + ": " + std::to_string(t.size()) + " times, but scan " + kf.cloud_path +
                  " needs line " + std::to_string(kf.index + 1));
    kf.time_s = t[std::size_t(kf.index)];
  }
  SweepMotions(s);
}

// Keyframe times serve only to deskew raw sweeps: times that do not fit the scans are ignored with
// a warning saying why (a raw sweep then fails naming its scan), never an error for a session
// whose scans need none.
void AttachTimes(Session& s, const std::function<void()>& attach) {
  try {
    attach();
  } catch (const Error& e) {
    spdlog::warn("{}: keyframe times ignored: {}", s.dir, e.what());
    for (Keyframe& kf : s.keyframes) {
      kf.time_s = std::numeric_limits<double>::quiet_NaN();
      kf.sweep = SweepMotion{};
    }
  }
}

void LoadClouds(Session& s) {
  std::atomic<std::size_t> non_finite{0};
  tbb::parallel_for(std::size_t(0), s.keyframes.size(), [&](std::size_t i) {
    auto& kf = s.keyframes[i];
    CloudReadStats st;
    kf.cloud = std::make_shared<const PointCloud>(ReadScan(kf.cloud_path, kf.sweep, &st));
    non_finite += st.non_finite_dropped;
  });
  for (const auto& kf : s.keyframes)
    if (kf.cloud->empty()) spdlog::warn("{}: empty scan (0 points); keyframe {} has no geometry", kf.cloud_path, kf.index);
  if (non_finite > 0)
    spdlog::warn("{}: dropped {} NaN/Inf points while reading the scans", s.dir, non_finite.load());
}

}  // namespace

namespace {

// SC-LIO-SAM / SC-A-LOAM: Scans/ + singlesession_posegraph.g2o and / or optimized_poses.txt.
Session LoadScLioSam(const std::string& dir, const SessionLoadOptions& opt) {
  std::error_code ec;
  const std::string scans_dir = (fs::path(dir) / "Scans").string();
  const std::vector<std::string> scans = ListIndexedFiles(scans_dir, ".pcd");
  if (scans.empty()) throw Error(scans_dir + ": no .pcd scans");

  Session s;
  s.dir = dir;
  s.name = BaseName(dir);
  s.keyframes.resize(scans.size());
  for (std::size_t i = 0; i < scans.size(); ++i) {
    s.keyframes[i].index = FileIndex(scans[i]);
    s.keyframes[i].cloud_path = scans[i];
  }

  const std::string g2o_path = (fs::path(dir) / "singlesession_posegraph.g2o").string();
  const std::string kitti_path = (fs::path(dir) / "optimized_poses.txt").string();
  if (fs::exists(g2o_path, ec)) {
    const G2oGraph g = ReadG2o(g2o_path);
    std::map<int, Pose> by_id;
    for (const auto& [id, T] : g.vertices) by_id[id] = T;
    std::vector<int> no_vertex, no_scan;
    std::set<int> scan_ids;
    for (const auto& kf : s.keyframes) {
      scan_ids.insert(kf.index);
      if (!by_id.count(kf.index)) no_vertex.push_back(kf.index);
    }
    for (const auto& [id, T] : by_id)
      if (!scan_ids.count(id)) no_scan.push_back(id);
    if (!no_vertex.empty() || !no_scan.empty()) {
      std::string msg = g2o_path + ": g2o vertex ids do not match the scan indices (" +
                        std::to_string(by_id.size()) + " vertices, " + std::to_string(scans.size()) +
                        " scans in Scans/)";
      if (!no_vertex.empty()) msg += "; scans without a vertex: " + IndexList(no_vertex);
      if (!no_scan.empty()) msg += "; vertices without a scan: " + IndexList(no_scan);
      throw Error(msg);
    }
    for (auto& kf : s.keyframes) kf.T_session_sensor = by_id[kf.index];
    for (const auto& e : g.edges) {
      const int a = s.Find(e.from), b = s.Find(e.to);
      (std::abs(a - b) == 1 ? s.odometry : s.loops).push_back(e);
    }
  } else if (opt.require_g2o) {
    throw Error(dir + ": missing singlesession_posegraph.g2o (required)");
  } else if (fs::exists(kitti_path, ec)) {
    const std::vector<Pose> poses = ReadKittiPoses(kitti_path);
    if (poses.size() != scans.size())
      throw Error(kitti_path + ": " + std::to_string(poses.size()) + " poses but Scans/ holds " +
                  std::to_string(scans.size()) + " scans (pose count != scan count)");
    for (std::size_t i = 0; i < poses.size(); ++i) s.keyframes[i].T_session_sensor = poses[i];
    DeriveOdometry(s);
  } else {
    throw Error(dir + ": no poses: neither singlesession_posegraph.g2o nor optimized_poses.txt");
  }
  AttachTimes(s, [&] { ReadTimesFile(s); });
  if (opt.load_clouds) LoadClouds(s);
  return s;
}

// A scan folder plus one pose per scan in index order (FAST-LIO-SAM: scans/ + poses_kitti.txt /
// poses_tum.txt; KISS-ICP results next to the scans).
Session LoadScansWithPoses(const std::string& dir, const SessionLayout& layout, const SessionLoadOptions& opt) {
  const std::vector<std::string> scans = ListIndexedFiles(layout.scans_dir, layout.scan_ext);
  if (scans.empty()) throw Error(layout.scans_dir + ": no " + layout.scan_ext + " scans");
  std::vector<Pose> poses;
  std::vector<double> stamps;
  if (layout.poses_format == "tum") {
    for (const StampedPose& p : ReadTumPoses(layout.poses)) {
      poses.push_back(p.pose);
      stamps.push_back(p.stamp);
    }
  } else {
    poses = ReadKittiPoses(layout.poses);
  }
  if (poses.size() != scans.size())
    throw Error(layout.poses + ": " + std::to_string(poses.size()) + " poses but " + layout.scans_dir + " holds " +
                std::to_string(scans.size()) + " scans (one pose per scan, in index order)");
  Session s;
  s.dir = dir;
  s.name = BaseName(dir);
  for (std::size_t i = 0; i < scans.size(); ++i) {
    Keyframe kf;
    kf.index = FileIndex(scans[i]);
    kf.cloud_path = scans[i];
    kf.T_session_sensor = poses[i];
    if (!stamps.empty()) kf.time_s = stamps[i];
    s.keyframes.push_back(std::move(kf));
  }
  DeriveOdometry(s);
  AttachTimes(s, [&] { stamps.empty() ? ReadTimesFile(s) : SweepMotions(s); });
  if (opt.load_clouds) LoadClouds(s);
  return s;
}

// KTH DynamicMap benchmark: pcd/NNNNNN.pcd in the world frame, the sensor pose in VIEWPOINT.
// The scans are moved into their sensor frames here (in memory), as every stage expects.
Session LoadKth(const std::string& dir, const SessionLayout& layout) {
  const std::vector<std::string> scans = ListIndexedFiles(layout.scans_dir, ".pcd");
  if (scans.empty()) throw Error(layout.scans_dir + ": no .pcd scans");
  Session s;
  s.dir = dir;
  s.name = BaseName(dir);
  s.keyframes.resize(scans.size());
  tbb::parallel_for(std::size_t(0), scans.size(), [&](std::size_t i) {
    Keyframe& kf = s.keyframes[i];
    kf.index = FileIndex(scans[i]);
    kf.cloud_path = scans[i];
    kf.T_session_sensor = ReadPcdViewpoint(scans[i]);
    PointCloud world = ReadPcd(scans[i]);
    const Eigen::Isometry3f T_sensor_world = kf.T_session_sensor.inverse().cast<float>();
    for (PointXYZI& p : world.points) {
      const Eigen::Vector3f q = T_sensor_world * p.xyz();
      p.x = q.x(), p.y = q.y(), p.z = q.z();
    }
    kf.cloud = std::make_shared<const PointCloud>(std::move(world));
  });
  DeriveOdometry(s);
  return s;
}

bool IsDir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}
bool IsFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

}  // namespace

SessionLayout DetectSessionLayout(const std::string& dir) {
  if (!IsDir(dir)) throw Error(dir + ": no such session directory");
  const fs::path root(dir);
  SessionLayout l;
  if (IsDir(root / "Scans") && (IsFile(root / "singlesession_posegraph.g2o") || IsFile(root / "optimized_poses.txt"))) {
    l.name = "sc-lio-sam";
    l.scans_dir = (root / "Scans").string();
    l.poses = IsFile(root / "singlesession_posegraph.g2o") ? (root / "singlesession_posegraph.g2o").string()
                                                            : (root / "optimized_poses.txt").string();
    return l;
  }
  for (const char* scans : {"Scans", "scans"}) {
    if (!IsDir(root / scans)) continue;
    l.scans_dir = (root / scans).string();
    for (const auto& [file, format] : {std::pair{"poses_kitti.txt", "kitti"}, {"poses_tum.txt", "tum"}, {"poses.txt", "kitti"}})
      if (IsFile(root / file)) {
        l.name = std::string("scans+") + format + "-poses";
        l.poses = (root / file).string();
        l.poses_format = format;
        return l;
      }
  }
  if (IsDir(root / "velodyne") && IsFile(root / "poses.txt")) {
    l.name = "kitti-odometry";
    l.scans_dir = (root / "velodyne").string();
    l.scan_ext = ".bin";
    l.poses = (root / "poses.txt").string();
    if (IsFile(root / "calib.txt")) l.calib = (root / "calib.txt").string();
    return l;
  }
  if (IsDir(root / "Scans") || IsDir(root / "scans"))
    throw Error(dir + ": no poses: neither singlesession_posegraph.g2o nor optimized_poses.txt (SC-LIO-SAM), nor "
                "poses_kitti.txt / poses_tum.txt / poses.txt beside the scans");
  if (IsDir(root / "pcd")) {
    l.name = "kth-dynamicmap";
    l.scans_dir = (root / "pcd").string();
    l.poses_format = "viewpoint";
    return l;
  }
  throw Error(dir + ": not a session directory; expected one of: Scans/NNNNNN.pcd + singlesession_posegraph.g2o or "
              "optimized_poses.txt (SC-LIO-SAM); scans/NNNNNN.pcd + poses_kitti.txt, poses_tum.txt or poses.txt "
              "(FAST-LIO-SAM, KISS-ICP); velodyne/NNNNNN.bin + poses.txt [+ calib.txt] (KITTI odometry); "
              "pcd/NNNNNN.pcd with VIEWPOINT poses (KTH DynamicMap benchmark)");
}

Session LoadSession(const std::string& dir, const SessionLoadOptions& opt) {
  const SessionLayout l = DetectSessionLayout(dir);
  if (opt.require_g2o && l.name != "sc-lio-sam")
    throw Error(dir + ": missing singlesession_posegraph.g2o (required)");
  if (l.name == "sc-lio-sam") return LoadScLioSam(dir, opt);
  if (l.name == "kitti-odometry") {
    std::unique_ptr<Pose> Tr;
    if (!l.calib.empty()) Tr = std::make_unique<Pose>(ReadTransform(l.calib));
    return LoadKittiSession(dir, l.poses, Tr.get(), opt);
  }
  if (l.name == "kth-dynamicmap") return LoadKth(dir, l);
  return LoadScansWithPoses(dir, l, opt);
}

Session LoadKittiSession(const std::string& dir, const std::string& poses_path,
                         const Pose* T_cam_velo, const SessionLoadOptions& opt) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir + ": no such KITTI sequence directory");
  const std::string velo_dir = (fs::path(dir) / "velodyne").string();
  if (!fs::is_directory(velo_dir, ec))
    throw Error(dir + ": missing velodyne/ folder (expected velodyne/NNNNNN.bin)");
  const std::vector<std::string> scans = ListIndexedFiles(velo_dir, ".bin");
  if (scans.empty()) throw Error(velo_dir + ": no .bin scans");
  const std::vector<Pose> poses = ReadKittiPoses(poses_path);
  Session s;
  s.dir = dir;
  s.name = BaseName(dir);
  const Pose Tr = T_cam_velo ? *T_cam_velo : Pose::Identity();
  const Pose Tr_inv = Tr.inverse();
  for (const auto& path : scans) {
    Keyframe kf;
    kf.index = FileIndex(path);
    if (kf.index < 0 || std::size_t(kf.index) >= poses.size())
      throw Error(poses_path + ": " + std::to_string(poses.size()) + " poses, but scan " + path +
                  " needs pose line " + std::to_string(kf.index + 1));
    // Camera poses P: T_w_velo = Tr^-1 * P * Tr, where Tr = T_cam_velo and the world is the
    // LiDAR frame of scan 0 (rotated like the camera's first frame).
    kf.T_session_sensor = Tr_inv * poses[std::size_t(kf.index)] * Tr;
    kf.cloud_path = path;
    s.keyframes.push_back(std::move(kf));
  }
  DeriveOdometry(s);
  AttachTimes(s, [&] { ReadTimesFile(s); });
  if (opt.load_clouds) LoadClouds(s);
  return s;
}

namespace {
// times.txt when every keyframe has a time (line i = scan i: the indices must be 0 .. n-1).
void WriteTimesOf(const std::string& dir, const Session& session) {
  std::vector<double> times;
  for (std::size_t i = 0; i < session.keyframes.size(); ++i) {
    const Keyframe& kf = session.keyframes[i];
    if (!std::isfinite(kf.time_s)) return;
    if (kf.index != int(i))
      throw Error(dir + ": keyframe times need scan indices 0 .. n-1 (times.txt line i is scan i), not " +
                  std::to_string(kf.index) + " at position " + std::to_string(i));
    times.push_back(kf.time_s);
  }
  if (!times.empty()) WriteTimes((fs::path(dir) / kTimesFile).string(), times);
}
}  // namespace

void WriteSession(const std::string& dir, const Session& session,
                  const std::vector<Eigen::MatrixXd>& scds) {
  if (!scds.empty() && scds.size() != session.keyframes.size())
    throw Error(dir + ": " + std::to_string(scds.size()) + " Scan Context descriptors for " +
                std::to_string(session.keyframes.size()) + " keyframes");
  std::set<int> indices;
  for (const auto& kf : session.keyframes) {
    if (!kf.cloud) throw Error(dir + ": keyframe " + std::to_string(kf.index) + " has no cloud in memory");
    if (kf.index < 0) throw Error(dir + ": negative keyframe index " + std::to_string(kf.index));
    if (!indices.insert(kf.index).second)
      throw Error(dir + ": duplicate keyframe index " + std::to_string(kf.index));
  }
  auto name = [](int index, const char* ext) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%06d%s", index, ext);
    return std::string(buf);
  };
  const fs::path root(dir);
  MakeDirs((root / "Scans").string());
  // Refuse to mix with scans of another session left in the folder: loading would mismatch.
  for (const auto& path : ListIndexedFiles((root / "Scans").string(), ".pcd"))
    if (!indices.count(FileIndex(path)))
      throw Error(path + ": a scan not in the session being written is already in " + dir +
                  "/Scans (write into an empty directory)");
  tbb::parallel_for(std::size_t(0), session.keyframes.size(), [&](std::size_t i) {
    const auto& kf = session.keyframes[i];
    WritePcd((root / "Scans" / name(kf.index, ".pcd")).string(), *kf.cloud, PcdFormat::kBinary);
  });
  if (!scds.empty()) {
    MakeDirs((root / "SCDs").string());
    for (std::size_t i = 0; i < scds.size(); ++i)
      WriteScd((root / "SCDs" / name(session.keyframes[i].index, ".scd")).string(), scds[i]);
  }
  G2oGraph g;
  std::vector<Pose> poses;
  for (const auto& kf : session.keyframes) {
    g.vertices.emplace_back(kf.index, kf.T_session_sensor);
    poses.push_back(kf.T_session_sensor);
  }
  g.edges = session.odometry;
  g.edges.insert(g.edges.end(), session.loops.begin(), session.loops.end());
  WriteG2o((root / "singlesession_posegraph.g2o").string(), g);
  WriteKittiPoses((root / "optimized_poses.txt").string(), poses);
  WriteTimesOf(dir, session);
}

namespace {
// A raw sweep (per-point times) deskewed with `motion`; `where` names it in the error when the
// motion is unknown. A scan without times is left as it is.
void DeskewRaw(PointCloud& cloud, const SweepMotion& motion, const std::string& where) {
  if (cloud.time.empty()) return;
  if (!motion.known)
    throw Error(where + ": a raw sweep (per-point 'time' field) in a session without keyframe times to deskew it: "
                "put times.txt beside the scans (one timestamp [s] per line, line i for scan i) or give TUM poses");
  Deskew(cloud, motion);
}
}  // namespace

std::shared_ptr<const PointCloud> KeyframeCloud(const Keyframe& kf, CloudReadStats* stats) {
  if (kf.cloud) {
    if (stats) *stats = CloudReadStats{kf.cloud->size(), 0};
    if (kf.cloud->time.empty()) return kf.cloud;
    auto copy = std::make_shared<PointCloud>(*kf.cloud);
    DeskewRaw(*copy, kf.sweep, "keyframe " + std::to_string(kf.index));
    return copy;
  }
  if (kf.cloud_path.empty())
    throw Error("keyframe " + std::to_string(kf.index) + ": neither a cloud nor a cloud path");
  return std::make_shared<const PointCloud>(ReadScan(kf.cloud_path, kf.sweep, stats));
}

void Deskew(PointCloud& cloud, const SweepMotion& motion) {
  float last_t = std::numeric_limits<float>::quiet_NaN();
  Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
  Eigen::Vector3f d = Eigen::Vector3f::Zero();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float t = cloud.time[i];
    if (t != last_t) {  // a column's points share their time
      R = motion.RotationAt(t).cast<float>();
      d = (double(t) * motion.v_mps).cast<float>();
      last_t = t;
    }
    PointXYZI& p = cloud.points[i];
    const Eigen::Vector3f q = R * p.xyz() + d;
    p.x = q.x(), p.y = q.y(), p.z = q.z();
  }
  cloud.time.clear();
}

PointCloud Reskew(const PointCloud& deskewed, const SweepMotion& motion, const SweepTiming& timing) {
  if (!motion.known || !timing.known || !deskewed.time.empty()) return deskewed;
  PointCloud out = deskewed;
  out.time.resize(out.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    PointXYZI& p = out.points[i];
    const Eigen::Vector3d q(p.x, p.y, p.z);
    Eigen::Vector3d fired = q;
    double t = 0.0;
    for (int step = 0; step < 2; ++step) {  // q = R(t) p + t v with t the time of p's own column
      t = timing.TimeAt(std::atan2(fired.y(), fired.x()));
      fired = motion.RotationAt(t).transpose() * (q - t * motion.v_mps);
    }
    p.x = float(fired.x()), p.y = float(fired.y()), p.z = float(fired.z());
    out.time[i] = float(t);
  }
  return out;
}

PointCloud ReadScan(const std::string& path, const SweepMotion& motion, CloudReadStats* stats) {
  PointCloud cloud = ReadCloud(path, stats);
  DeskewRaw(cloud, motion, path);
  return cloud;
}

void RequireScanPoints(const PointCloud& scan, const std::string& where) {
  if (scan.empty()) throw Error(where + ": empty scan (no finite points)");
}

}  // namespace ltm::io
