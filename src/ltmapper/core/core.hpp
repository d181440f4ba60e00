// ltmapper core: the types every module shares. Depends on Eigen only.
//
// Frames are named in code: a pose `T_a_b` maps points from frame b into frame a
// (p_a = T_a_b * p_b). A keyframe's pose in its own session's odometry frame is
// `T_session_sensor`; in the shared world frame it is `T_world_sensor = A * T_session_sensor`
// where A is the session's anchor (paper eq. 3).
#pragma once

#include <Eigen/Geometry>

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace ltm {

using Pose = Eigen::Isometry3d;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

// ---------------------------------------------------------------------------------------------
// Errors. Every bad input raises ltm::Error with the file (and line or point when known) named;
// the CLI turns it into a message and a non-zero exit code. Nothing calls exit() in a library.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
  // "file:line: what" (line omitted when 0).
  Error(const std::string& file, std::size_t line, const std::string& what);
};

// ---------------------------------------------------------------------------------------------
// Parallel loops: f(0) .. f(n-1) on `threads` workers (0 = all cores) in a task arena of the
// call's own (no process-wide thread limit), one index per task (each may be big). Every module
// uses these; results must not depend on the order the indices run in. ParallelForChunks calls
// f(begin, end) on ranges that cover [0, n), each at most `grain` long (small items, or a
// per-chunk set-up worth sharing).
void ParallelFor(std::size_t n, int threads, const std::function<void(std::size_t)>& f);
void ParallelForChunks(std::size_t n, int threads, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& f);

// ---------------------------------------------------------------------------------------------
// Point classes, stored per point when a cloud carries labels (PLY field "class").
enum class PointClass : std::uint8_t {
  kUnknown = 0,
  kStatic = 1,
  kHD = 2,        // high dynamic: moved during a session
  kPDStrong = 3,  // positive difference behind / beyond what the earlier session saw
  kPDWeak = 4,    // positive difference in space the earlier session observed as free
  kNDStrong = 5,  // negative difference the later session saw through
  kNDWeak = 6,    // negative difference never seen through (occluded): kept in the map
};
const char* ToString(PointClass c);

struct PointXYZI {
  float x = 0.f, y = 0.f, z = 0.f;
  float intensity = 0.f;
  Eigen::Vector3f xyz() const { return {x, y, z}; }
};

// Compact point cloud: 16 bytes per point plus optional per-point arrays, each either empty or
// exactly size() long (CheckConsistent() enforces it).
struct PointCloud {
  std::vector<PointXYZI> points;
  std::vector<PointClass> cls;         // optional class per point
  std::vector<std::uint16_t> session;  // optional session index per point
  std::vector<std::int32_t> object;    // optional object id per point (-1 = none)
  std::vector<float> time;             // optional time per point [s] after the scan's timestamp: a raw
                                       // sweep's (io deskews it on load with the keyframe's SweepMotion)

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  void reserve(std::size_t n) { points.reserve(n); }
  void clear();
  void push_back(float x, float y, float z, float intensity = 0.f) {
    points.push_back({x, y, z, intensity});
  }
  // Appends the points of `other` (and its optional arrays when both clouds have them, or when
  // this cloud is empty); appending an empty cloud changes nothing.
  void append(const PointCloud& other);
  // Keeps points whose mask entry is true (mask.size() == size()), all arrays together.
  PointCloud select(const std::vector<bool>& mask) const;
  PointCloud select(const std::vector<std::uint32_t>& indices) const;
  // Throws ltm::Error when an optional array has the wrong length.
  void CheckConsistent(const std::string& what) const;
};

// ---------------------------------------------------------------------------------------------
// Pose graph pieces, as in a session's g2o file.
struct Edge {
  int from = 0;  // keyframe index
  int to = 0;
  Pose T_from_to = Pose::Identity();
  Matrix6d information = Matrix6d::Identity();  // order: x y z rx ry rz (g2o convention)
  bool has_information = false;                 // false when the file gave none
};

// The sensor's motion while it swept one scan: constant linear and angular velocity in the sensor
// frame of the scan's timestamp, derived from the session's poses and keyframe times
// (io::LoadSession, times.txt). A raw sweep's point fired t seconds after the timestamp is moved
// into that frame as x' = R(t w) x + t v.
struct SweepMotion {
  bool known = false;                          // false: the session has no keyframe times
  Eigen::Vector3d v_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d w_radps = Eigen::Vector3d::Zero();
};

struct Keyframe {
  int index = 0;                           // integer value of the scan file name
  Pose T_session_sensor = Pose::Identity();  // pose in the session's own odometry frame
  std::string cloud_path;                  // scan file, read on demand
  std::shared_ptr<const PointCloud> cloud; // set when loaded / generated in memory
  double time_s = std::numeric_limits<double>::quiet_NaN();  // timestamp [s] (times.txt), NaN when unknown
  SweepMotion sweep;                       // deskews the scan on load when it is a raw sweep
};

struct Session {
  std::string name;
  std::string dir;
  std::vector<Keyframe> keyframes;  // sorted by index
  std::vector<Edge> odometry;       // |to - from| == 1
  std::vector<Edge> loops;          // intra-session loops
  // Position in `keyframes` of the keyframe with this index, or -1.
  int Find(int index) const;
};

// ---------------------------------------------------------------------------------------------
// Config structs. Each module's config lists its fields once, in a Visit() method:
//
//   template <class V> void Visit(V& v) { v("voxel_m", voxel_m, "m", 0.01, 10.0); ... }
//
// and the same list drives YAML reading (io::LoadConfig: unknown keys are errors), range
// validation (ValidateConfig), and printing of the resolved config (ConfigToString).
// Nested sections are written as dotted keys ("lidar.beams") and as nested maps in YAML.
struct ConfigField {
  enum class Kind { kDouble, kInt, kBool, kString, kDoubleList };
  std::string key;
  Kind kind = Kind::kDouble;
  void* ptr = nullptr;
  std::string unit;
  double lo = 0.0, hi = 0.0;             // inclusive range for numbers and list entries
  std::vector<std::string> choices;      // allowed strings (empty = any non-empty string)
  bool allow_empty = false;              // lists: [] is a valid value (e.g. "no table given")
};

class ConfigFields {
 public:
  void operator()(const std::string& key, double& v, const std::string& unit, double lo, double hi);
  void operator()(const std::string& key, int& v, const std::string& unit, int lo, int hi);
  void operator()(const std::string& key, bool& v);
  void operator()(const std::string& key, std::string& v, std::vector<std::string> choices = {});
  void operator()(const std::string& key, std::vector<double>& v, const std::string& unit,
                  double lo, double hi, bool allow_empty = false);
  const std::vector<ConfigField>& fields() const { return fields_; }

 private:
  std::vector<ConfigField> fields_;
};

template <class Config>
ConfigFields FieldsOf(Config& c) {
  ConfigFields f;
  c.Visit(f);
  return f;
}

// Throws ltm::Error naming the first field out of range / not an allowed choice.
void ValidateFields(const ConfigFields& fields, const std::string& where);
// "key: value [unit]" lines, one per field.
std::string FieldsToString(const ConfigFields& fields);
// Applies one "key=value" override (command lines' --set): numbers, true|false, strings, and
// comma-separated lists. Unknown keys and unparsable values are errors naming the key; ranges
// are checked afterwards by ValidateConfig.
void SetField(const ConfigFields& fields, const std::string& key_value);

template <class Config>
void ValidateConfig(const Config& c, const std::string& where = "config") {
  ValidateFields(FieldsOf(const_cast<Config&>(c)), where);
}
template <class Config>
std::string ConfigToString(const Config& c) {
  return FieldsToString(FieldsOf(const_cast<Config&>(c)));
}

// ---------------------------------------------------------------------------------------------
// Progress for long loops: "label: done/total (rate/s, ETA)" on a terminal, throttled; silent
// when stderr is not a terminal (CI) unless forced. Thread-safe Tick().
class Progress {
 public:
  Progress(std::string label, std::size_t total, bool force = false);
  ~Progress();
  void Tick(std::size_t n = 1);
  void Done();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Session key for the pose graph: (session, keyframe position) without digit tricks, so any
// number of sessions works.
struct NodeKey {
  int session = 0;
  int keyframe = 0;
  bool operator<(const NodeKey& o) const {
    return session != o.session ? session < o.session : keyframe < o.keyframe;
  }
  bool operator==(const NodeKey& o) const { return session == o.session && keyframe == o.keyframe; }
};

// Peak resident set size of this process [bytes] (from /proc/self/status VmHWM), 0 if unknown.
std::size_t PeakRssBytes();

}  // namespace ltm
