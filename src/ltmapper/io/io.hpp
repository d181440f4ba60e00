// ltmapper io: every file format users already have, read and written.
//
// All readers throw ltm::Error naming the file (and line where there is one). All writers write
// to a temporary name in the same directory and rename, so a crash never leaves a partial file.
// PCL and yaml-cpp are used only inside the .cpp files.
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

namespace ltm::io {

// ------------------------------------------------------------------------ atomic file writes
// Writes through a temporary file "<path>.tmp-<pid>-<n>" and renames it over `path` when
// `write` returns. On exception the temporary is removed and the exception is rethrown.
void WriteFileAtomic(const std::string& path, const std::function<void(std::ostream&)>& write);
// Same, for writers that need a path (e.g. PCL): `write(tmp_path)` must create tmp_path.
void WritePathAtomic(const std::string& path, const std::function<void(const std::string&)>& write);
// Creates a directory and its parents; throws on failure.
void MakeDirs(const std::string& dir);
// MakeDirs, then checks that files can be created in `dir` ("<dir>: output directory is not
// writable: <reason>"): the stages call it on their output before any work, so a read-only OUT
// fails in the first second, not after the stage ran.
void MakeWritableDir(const std::string& dir);

// ------------------------------------------------------------------------- stage folders
// A stage output folder is built whole in a fresh temporary folder "<dir>.tmp-<pid>-<n>" next to
// `dir`, and Publish() puts it in place of `dir` (the old folder is renamed aside, then removed),
// so no file of an earlier run (a session or pair folder of a longer session list, a keyframe of
// other parameters) can survive into this run's output. Destroyed unpublished, the temporary is
// removed. An existing `dir` is replaced only when it is empty or holds `identity_file` (a file
// the stage always writes, e.g. "report.json"): anything else is an error naming `dir`, so a
// mistyped --out never deletes a user's folder. Temporaries left by processes that no longer
// run are removed.
class StagingDir {
 public:
  StagingDir(std::string final_dir, std::string identity_file);
  ~StagingDir();
  StagingDir(const StagingDir&) = delete;
  StagingDir& operator=(const StagingDir&) = delete;
  const std::string& path() const { return tmp_; }  // write here
  void Publish();
 private:
  std::string final_, tmp_;
  bool published_ = false;
};

// ------------------------------------------------------------------ run layout and manifest
// One owner for the file names of a run's output (docs/FORMATS.md): the stages, eval and the
// pipeline build every path with these.
namespace layout {
std::string AlignedDir(const std::string& out_dir);   // OUT/aligned   (LT-SLAM)
std::string ChangesDir(const std::string& out_dir);   // OUT/changes   (LT-removert)
std::string ObjectsDir(const std::string& out_dir);   // OUT/objects   (LT-map export)
std::string ManifestFile(const std::string& aligned_dir);                            // manifest.yaml
std::string PosesWorldFile(const std::string& aligned_dir, const std::string& session);
std::string AnchorFile(const std::string& aligned_dir, const std::string& session);
std::string SessionChangesDir(const std::string& changes_dir, const std::string& session);
std::string StaticMapFile(const std::string& changes_dir, const std::string& session);  // HD-free map
// The files of one LT-removert session folder (changes/<session>/, or its staging copy).
std::string StaticMapIn(const std::string& session_changes_dir);  // static_map.pcd (HD-free)
std::string HdMapIn(const std::string& session_changes_dir);      // hd_map.pcd (removed points)
// Pair folder of LT-removert: "pair_<c>_<q>", c and q = positions (2 digits) of the sessions
// among the manifest's aligned sessions, in manifest order.
std::string PairDirName(int central, int query);
std::string KeyframeDirName(int index);  // "000123"
}  // namespace layout

// What LT-SLAM knows and every later stage needs, written once as aligned/manifest.yaml: the
// sessions in the run's order (central first), their names (= output folder names), input
// folders, whether they are aligned (and why not), and the resolved LT-SLAM params. LT-removert,
// LT-map and the pipeline read the session order and the aligned set from it instead of listing
// directories.
struct ManifestSession {
  std::string name;    // output folder name: aligned/<name>, changes/<name>
  std::string dir;     // input session folder (absolute)
  bool aligned = false;
  std::string reason;  // why not aligned ("" when aligned)
};
struct RunManifest {
  std::vector<ManifestSession> sessions;  // run order, central first
  std::string slam_config;                // resolved LT-SLAM params (YAML text)
  std::vector<ManifestSession> Aligned() const;  // aligned sessions, in run order
};
void WriteRunManifest(const std::string& aligned_dir, const RunManifest& manifest);
// Throws ltm::Error naming the file when it is missing or malformed.
RunManifest ReadRunManifest(const std::string& aligned_dir);
bool HasRunManifest(const std::string& aligned_dir);

// ----------------------------------------------------------------------------------- clouds
struct CloudReadStats {
  std::size_t points_in_file = 0;
  std::size_t non_finite_dropped = 0;  // NaN / Inf points removed (never propagated)
};
// PCD (ascii, binary, binary_compressed) through PCL's reader. Needs fields x y z; intensity
// optional (0 when absent). Truncated files and headers that disagree with the data are errors.
PointCloud ReadPcd(const std::string& path, CloudReadStats* stats = nullptr);
// The sensor pose of a PCD's VIEWPOINT header line (tx ty tz qw qx qy qz; identity when absent):
// the KTH DynamicMap benchmark stores each scan in the world frame with its sensor pose there.
Pose ReadPcdViewpoint(const std::string& path);
enum class PcdFormat { kAscii, kBinary, kBinaryCompressed };
void WritePcd(const std::string& path, const PointCloud& cloud,
              PcdFormat format = PcdFormat::kBinary);
// KITTI velodyne .bin: float32 x y z reflectance, little endian, 16 bytes per point.
PointCloud ReadKittiBin(const std::string& path, CloudReadStats* stats = nullptr);
void WriteKittiBin(const std::string& path, const PointCloud& cloud);
// Reads .pcd or .bin by extension.
PointCloud ReadCloud(const std::string& path, CloudReadStats* stats = nullptr);
// Binary little-endian PLY with float x y z intensity and, when present, uchar class,
// ushort session, int object (CloudCompare shows them as scalar fields).
void WritePly(const std::string& path, const PointCloud& cloud);
// One part of a labelled PLY: the points of `cloud` (those with keep[i] when `keep` is given),
// each with class `cls`, session `session` and object `object`.
struct PlyPart {
  const PointCloud* cloud = nullptr;
  PointClass cls = PointClass::kStatic;
  std::uint16_t session = 0;
  std::int32_t object = -1;
  const std::vector<bool>* keep = nullptr;
};
// The same file as WritePly of the parts' labelled concatenation (class, session and object
// fields), streamed from the parts without building that concatenation.
void WritePly(const std::string& path, const std::vector<PlyPart>& parts);
PointCloud ReadPly(const std::string& path);  // reads what WritePly writes

// -------------------------------------------------------------------------- scan context
// SCDs/NNNNNN.scd: `rows` lines of `cols` space-separated numbers (20 x 60 by default).
Eigen::MatrixXd ReadScd(const std::string& path, int rows = 20, int cols = 60);
void WriteScd(const std::string& path, const Eigen::MatrixXd& desc);

// ------------------------------------------------------------------------------------ poses
// KITTI: 12 numbers per line, row-major 3x4 [R|t].
std::vector<Pose> ReadKittiPoses(const std::string& path);
void WriteKittiPoses(const std::string& path, const std::vector<Pose>& poses);
// TUM: "timestamp tx ty tz qx qy qz qw" per line.
struct StampedPose {
  double stamp = 0.0;
  Pose pose = Pose::Identity();
};
std::vector<StampedPose> ReadTumPoses(const std::string& path);
void WriteTumPoses(const std::string& path, const std::vector<StampedPose>& poses);
// A 3x4 (12 numbers, row-major) or 4x4 (16 numbers) rigid transform from text; e.g. KITTI's
// `Tr` or `relative.txt`. A leading "Tr:" label is allowed.
Pose ReadTransform(const std::string& path);
Pose ParseTransform(const std::string& text, const std::string& where);

// -------------------------------------------------------------------------------------- g2o
struct G2oGraph {
  std::vector<std::pair<int, Pose>> vertices;  // (id, pose) in file order
  std::vector<Edge> edges;
};
// VERTEX_SE3:QUAT id x y z qx qy qz qw / EDGE_SE3:QUAT a b x y z qx qy qz qw [21 info values].
// Quaternions are normalised; a quaternion whose norm is far from 1 (|n-1| > 1e-3), an unknown
// tag, a duplicate vertex id or an edge to a missing vertex is an error naming file and line.
// FIX lines are accepted and ignored.
G2oGraph ReadG2o(const std::string& path);
void WriteG2o(const std::string& path, const G2oGraph& graph);

// ---------------------------------------------------------------------------------- sessions
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
// Writes a session in SC-LIO-SAM layout: Scans/NNNNNN.pcd (binary), singlesession_posegraph.g2o,
// optimized_poses.txt and, when `scds` is non-empty, SCDs/NNNNNN.scd. Clouds come from
// Keyframe::cloud (must be set).
void WriteSession(const std::string& dir, const Session& session,
                  const std::vector<Eigen::MatrixXd>& scds = {});
// Loads the cloud of a keyframe (from memory or its path).
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

// ------------------------------------------------------------------------------------- YAML
// Reads a YAML params file into any config with a Visit() (see core.hpp). Nested maps are
// flattened to dotted keys. Unknown keys, wrong types and out-of-range values are errors
// naming the file and key. Keys absent from the file keep their defaults. `section` selects a
// top-level map (other top-level keys are ignored; an absent section keeps every default). A file
// with any error changes nothing (values are applied only when the whole file is valid).
void LoadConfigFields(const std::string& path, const ConfigFields& fields,
                      const std::string& section = "");
template <class Config>
void LoadConfig(const std::string& path, Config& cfg, const std::string& section = "") {
  LoadConfigFields(path, FieldsOf(cfg), section);
  ValidateConfig(cfg, path);
}
// Writes the config as YAML (nested maps for dotted keys), e.g. to record the resolved params.
void SaveConfigFields(const std::string& path, const ConfigFields& fields);

// Numeric index of a scan file name ("000123.pcd" -> 123); throws when not a number.
int FileIndex(const std::string& filename);
// Regular files in `dir` with the extension `ext` (".pcd"), sorted by FileIndex.
std::vector<std::string> ListIndexedFiles(const std::string& dir, const std::string& ext);

}  // namespace ltm::io
