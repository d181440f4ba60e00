// ltmapper io: session folders of every layout (detect, load, write, inspect).
#pragma once

#include "ltmapper/io/formats.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace ltm::io {

struct SessionLoadOptions {
  // Read every scan now (else Keyframe::cloud_path only). Scans are read with tbb::parallel_for
  // in the caller's task arena (wrap the call in a tbb::task_arena to bound the threads). Empty
  // scans load as empty clouds with a warning; NaN/Inf points are dropped with a warning.
  bool load_clouds = false;
  bool require_g2o = false;
};
// The layouts of session directories that users' tools write, detected from the files present
// (first match wins):
//   sc-lio-sam       Scans/NNNNNN.pcd, optional SCDs/NNNNNN.scd, singlesession_posegraph.g2o and/or
//                    optimized_poses.txt (SC-LIO-SAM / SC-A-LOAM / FAST-LIO savers)
//   scans+kitti-poses, scans+tum-poses
//                    scans/ (or Scans/) NNNNNN.pcd + poses_kitti.txt, poses_tum.txt or poses.txt: one
//                    pose per scan in index order (FAST-LIO-SAM, KISS-ICP results beside the scans)
//   kitti-odometry   velodyne/NNNNNN.bin + poses.txt (+ calib.txt: its Tr, camera poses)
//   kth-dynamicmap   pcd/NNNNNN.pcd, points in the world frame, sensor pose in each VIEWPOINT
//                    (KTH DynamicMap benchmark)
struct SessionLayout {
  std::string name;                 // one of the names above
  std::string scans_dir;            // the scan folder
  std::string scan_ext = ".pcd";
  std::string poses;                // pose file (empty for kth-dynamicmap)
  std::string poses_format = "kitti";  // kitti | tum | viewpoint (the g2o for sc-lio-sam)
  std::string calib;                // kitti-odometry: calib.txt when present
};
// ltm::Error naming the expected layouts when `dir` holds none of them.
SessionLayout DetectSessionLayout(const std::string& dir);
// Loads a session of any layout above. SC-LIO-SAM: poses come from the g2o vertices when present
// (else optimized_poses.txt), odometry edges from the g2o (else derived from consecutive poses).
// Scan files are sorted by the integer value of their names. Pose count != scan count, duplicate
// indices, a missing directory or missing files are errors. kth-dynamicmap scans are read now and
// moved into their sensor frames (Keyframe::cloud).
Session LoadSession(const std::string& dir, const SessionLoadOptions& opt = {});
// KITTI odometry layout: `dir/velodyne/NNNNNN.bin` + a poses file (12 numbers per line, one per
// scan index, maybe more lines than scans). When `T_cam_velo` is given (KITTI's `Tr`), the poses
// are camera poses and the LiDAR pose is T_w_velo = Tr^-1 * P * Tr.
Session LoadKittiSession(const std::string& dir, const std::string& poses_path,
                         const Pose* T_cam_velo = nullptr, const SessionLoadOptions& opt = {});
// Writes a session in SC-LIO-SAM layout: Scans/NNNNNN.pcd (binary; with `time` for raw sweeps),
// singlesession_posegraph.g2o, optimized_poses.txt, times.txt when every keyframe has a time and,
// when `scds` is non-empty, SCDs/NNNNNN.scd. Clouds come from
// Keyframe::cloud (must be set).
void WriteSession(const std::string& dir, const Session& session,
                  const std::vector<Eigen::MatrixXd>& scds = {});
// Keyframe times and raw sweeps: a session's `times.txt` (line i = scan i, seconds; or the stamps
// of TUM poses) sets Keyframe::time_s and, with the poses, Keyframe::sweep (the velocity of the
// step to the next keyframe). A scan with a per-point `time` field is a raw sweep (each point in
// the sensor frame of its firing, `time` seconds after the scan's timestamp): ReadScan moves its
// points into the frame of the timestamp with that motion. Without times that is an error naming
// the scan. KITTI .bin scans carry no time field and are read as they are.
// Moves each point of a raw sweep into the frame of its scan's timestamp and drops `time`.
void Deskew(PointCloud& cloud, const SweepMotion& motion);
// The inverse of Deskew for a scan saved deskewed: each point moved back into the frame its column
// fired from (SweepTiming::TimeAt of its azimuth there, found in two fixed-point steps), with that
// `time`. Returns the scan unchanged when `motion` or `timing` is unknown or it already has times.
PointCloud Reskew(const PointCloud& deskewed, const SweepMotion& motion, const SweepTiming& timing);
// ReadCloud, then Deskew when the scan has per-point times (ltm::Error when `motion` is unknown).
PointCloud ReadScan(const std::string& path, const SweepMotion& motion, CloudReadStats* stats = nullptr);
// Loads the cloud of a keyframe (from memory or its path; a raw sweep is deskewed).
std::shared_ptr<const PointCloud> KeyframeCloud(const Keyframe& kf, CloudReadStats* stats = nullptr);
// The stages' one check on a keyframe's scan (LT-SLAM registration, LT-removert maps and
// visibility): a scan without finite points is an error "<where>: empty scan (no finite points)".
void RequireScanPoints(const PointCloud& scan, const std::string& where);

// What `ltmapper info` prints: counts, scan sizes, pose span, path length, edges, problems.
struct SessionInfo {
  std::string dir;
  std::size_t keyframes = 0;
  std::size_t scans_found = 0, scds_found = 0;
  std::size_t points_min = 0, points_max = 0, points_total = 0;
  std::size_t non_finite_points = 0;
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero(), bbox_max = Eigen::Vector3d::Zero();
  double path_length_m = 0.0;
  std::size_t odometry_edges = 0, loop_edges = 0;
  std::string layout;                  // DetectSessionLayout's name
  std::string pose_source;             // "g2o" or "optimized_poses.txt"
  std::vector<std::string> problems;   // missing / inconsistent files, one line each
  std::size_t scans_read = 0;          // scans read successfully (points_* are over these)
  std::size_t raw_sweeps = 0;          // scans read with per-point times (raw sweeps, deskewed on load)
  bool keyframe_times = false;         // times.txt or TUM stamps: raw sweeps can be deskewed
  std::string load_error;              // why LoadSession fails; empty when the session loads
};
// Never throws for problems inside the session (they go to `problems`, and `load_error` when
// LoadSession would fail or a scan is unreadable); throws ltm::Error when `dir` does not exist or
// has no Scans/ folder. Empty scans are problems (they load, but have no geometry).
SessionInfo InspectSession(const std::string& dir, bool read_scans = true);
// Same for a KITTI layout (velodyne/NNNNNN.bin + poses file, optional Tr as in LoadKittiSession).
SessionInfo InspectKittiSession(const std::string& dir, const std::string& poses_path,
                                const Pose* T_cam_velo = nullptr, bool read_scans = true);
std::string FormatSessionInfo(const SessionInfo& info);

// What `ltmapper info <cloud file>` prints for one .pcd / .bin / .ply: points, what the file
// carries besides x y z, the box, the range from the origin; ltm::Error naming the file when it
// cannot be read (the readers' own checks).
struct CloudInfo {
  std::string path;
  std::size_t points_in_file = 0, non_finite = 0, points = 0;
  bool labels = false, times = false;
  double time_min_s = 0.0, time_max_s = 0.0;
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero(), bbox_max = Eigen::Vector3d::Zero();
  double range_min_m = 0.0, range_median_m = 0.0, range_max_m = 0.0;
  bool viewpoint = false;  // a PCD VIEWPOINT other than the identity (KTH layout: world-frame points)
  Pose T_viewpoint = Pose::Identity();
};
CloudInfo InspectCloud(const std::string& path, PointCloud* cloud = nullptr);
std::string FormatCloudInfo(const CloudInfo& info);

}  // namespace ltm::io
