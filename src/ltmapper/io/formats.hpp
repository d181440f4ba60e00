// ltmapper io: the file formats (PCD, KITTI .bin, PLY, SCD, KITTI / TUM poses, g2o).
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ltm::io {

struct CloudReadStats {
  std::size_t points_in_file = 0;
  std::size_t non_finite_dropped = 0;  // NaN / Inf points removed (never propagated)
};
// PCD (ascii, binary, binary_compressed; ltmapper's own reader). Needs fields x y z; intensity
// optional (0 when absent); a float `time` field (a raw sweep's seconds after the scan's
// timestamp) fills PointCloud::time. Truncated files and headers that disagree with the data are errors.
PointCloud ReadPcd(const std::string& path, CloudReadStats* stats = nullptr);
// The point count a PCD's header declares (checked against the file's size), without reading the
// points. ReadPcd may return fewer: it drops non-finite points.
std::size_t ReadPcdPointCount(const std::string& path);
// The sensor pose of a PCD's VIEWPOINT header line (tx ty tz qw qx qy qz; identity when absent):
// the KTH DynamicMap benchmark stores each scan in the world frame with its sensor pose there.
Pose ReadPcdViewpoint(const std::string& path);
enum class PcdFormat { kAscii, kBinary, kBinaryCompressed };
// x y z intensity, and `time` when the cloud has per-point times (binary only).
void WritePcd(const std::string& path, const PointCloud& cloud,
              PcdFormat format = PcdFormat::kBinary);
// A binary PCD of `points` points written in pieces: `pieces(write)` calls write(cloud) for each
// piece in order; the file is WritePcd's bytes for their concatenation, never held whole. Atomic
// as WritePcd; ltm::Error naming the file (nothing written) when the pieces hold another count.
void WritePcdPieces(const std::string& path, std::size_t points,
                    const std::function<void(const std::function<void(const PointCloud&)>& write)>& pieces);
// KITTI velodyne .bin: float32 x y z reflectance, little endian, 16 bytes per point.
PointCloud ReadKittiBin(const std::string& path, CloudReadStats* stats = nullptr);
void WriteKittiBin(const std::string& path, const PointCloud& cloud);
// A binary PCD read a piece at a time (memory: one piece, not the file): Next(n, &cloud) replaces
// `cloud` with the next at most n points (ReadPcd's fields and checks, the header checked against
// the file's size first) and returns false once every point was read. Other DATA types are an
// ltm::Error naming the file (read those whole with ReadPcd).
class PcdPieceReader {
 public:
  explicit PcdPieceReader(const std::string& path);
  ~PcdPieceReader();
  PcdPieceReader(PcdPieceReader&&) noexcept;
  bool Next(std::size_t max_points, PointCloud* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
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
// times.txt (KITTI's): one timestamp [s] per line, line i the time of scan i; times must increase
// (ltm::Error naming the file and line otherwise).
std::vector<double> ReadTimes(const std::string& path);
void WriteTimes(const std::string& path, const std::vector<double>& times);
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

}  // namespace ltm::io
