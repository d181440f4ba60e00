// ltmapper sim: the simulation (Simulate), its report, the ray caster (Simulator) and odometry drift.
#pragma once

#include "ltmapper/sim/config.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace ltm::sim {

// An LD object: exists only in the sessions of `present_in`.
struct LdObjectInfo {
  int id = 0;
  std::string cls;                 // car, truck, tree, fence, container, structure, wall, hoarding
  std::vector<int> present_in;     // sorted session indices
  std::string placement;           // open | occluded | revealed
  int partner = -1;                // the same object at its other place (a moved container), else -1
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // world frame [m]
  Eigen::Vector3d box_min = Eigen::Vector3d::Zero(), box_max = Eigen::Vector3d::Zero();
};

// An HD actor: moves along its session's route during that session only.
struct HdActorInfo {
  int id = 0;          // unique over all sessions, after the LD object ids
  int session = 0;
  std::string cls;     // car | pedestrian
  double speed_mps = 0.0;
};

// Counts of the point-wise change truth of one pair (central 0, query k), in points after
// voxel downsampling (truth.voxel_m): every changed surface, and the LD-object-only part.
struct PairTruthCounts {
  int query = 0;
  std::size_t pd_strong = 0, pd_weak = 0, nd_strong = 0, nd_weak = 0;
  std::size_t objects_pd_strong = 0, objects_pd_weak = 0, objects_nd_strong = 0, objects_nd_weak = 0;
  std::size_t rays = 0;  // visibility rays cast for this pair
};

struct SimReport {
  int sessions = 0;
  std::size_t keyframes = 0;
  std::size_t triangles = 0;
  std::size_t ld_objects = 0, hd_actors = 0;
  std::size_t rays = 0, points = 0, hd_points = 0, ld_points = 0;
  double rays_per_s = 0.0;          // casting only
  double seconds_build = 0.0;       // scenario + Embree scenes
  double seconds_cast = 0.0;        // ray casting
  double seconds_write = 0.0;       // sessions, labels
  double seconds_truth = 0.0;       // static worlds, change truth with visibility
  double seconds_total = 0.0;
  std::size_t bytes_written = 0;
  std::vector<PairTruthCounts> pairs;
};

// Runs the whole simulation and writes DIR/sessions/session_XX and DIR/truth (FORMATS.md).
// `threads` = 0 uses all cores. Output bytes do not depend on `threads`.
SimReport Simulate(const SimConfig& cfg, const std::string& out_dir, int threads = 0);

// Result of one ray.
struct RayHit {
  bool hit = false;
  float range = 0.f;                         // [m] noise-free distance to the first hit
  PointClass cls = PointClass::kUnknown;     // kStatic (also LD objects) or kHD
  int object = -1;                           // LD object id, HD actor id, -1 permanent static
  float cos_incidence = 1.f;                 // |cos| of the angle between ray and surface normal
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // unit surface normal at the hit (world; either side)
};

// The scenario and its Embree scenes in memory (for tests and benchmarks; Simulate uses it).
// Not thread-safe across calls: CastScan/CastRay first put the HD actors of (session, keyframe)
// in place. Each call runs its rays in parallel itself.
class Simulator {
 public:
  explicit Simulator(const SimConfig& cfg, int threads = 0);
  ~Simulator();
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;

  const SimConfig& config() const;
  int sessions() const;
  int keyframes(int session) const;
  std::size_t triangles() const;
  std::size_t hd_actors() const;
  const std::vector<LdObjectInfo>& ld_objects() const;
  std::vector<HdActorInfo> hd_actor_info() const;
  // HD actor ids are unique over all sessions and never collide with LD object ids.
  bool IsPresent(int ld_object, int session) const;

  Pose T_world_session(int session) const;                      // the true unknown origin
  const std::vector<Pose>& T_world_sensor(int session) const;   // true keyframe poses
  std::vector<Pose> T_session_sensor_true(int session) const;   // true poses, session frame
  const std::vector<Pose>& T_session_sensor_drifted(int session) const;  // written odometry

  // One keyframe scan in the sensor frame with per-point cls (kStatic / kHD), session and
  // object filled (and `time` for a distorted sweep: each point in the frame of its firing, that
  // many seconds after the keyframe); noise and dropout applied (deterministic per ray). Points ordered beam by
  // beam (top beam first), column by column within a beam.
  PointCloud CastScan(int session, int keyframe);
  // The world pose each column of a keyframe's scan is fired from (lidar.sweep: all the keyframe
  // pose when instant, else moving on towards the next keyframe during sweep_s).
  std::vector<Pose> SweepPoses(int session, int keyframe) const;
  // The keyframe's timestamp [s] from the session's start (the moment of its first column).
  double KeyframeTime(int session, int keyframe) const;
  // A raw sweep (lidar.sweep: distorted, whose points carry `time`) moved into the keyframe frame
  // by the true sweep poses, `time` dropped: the truth every stage should see after deskewing.
  // A scan without times is returned as it is.
  PointCloud TrueDeskewed(int session, int keyframe, const PointCloud& scan) const;
  // Rays from `origin_world` along unit `dirs_world` in the world of `session` with the HD
  // actors at `keyframe` (noise free, up to max_range). Runs in parallel.
  std::vector<RayHit> CastRays(int session, int keyframe, const Eigen::Vector3d& origin_world,
                               const std::vector<Eigen::Vector3f>& dirs_world);
  // The same with one origin per ray.
  std::vector<RayHit> CastRays(int session, int keyframe, const std::vector<Eigen::Vector3f>& origins_world,
                               const std::vector<Eigen::Vector3f>& dirs_world);
  // The rays CastScan fires for a keyframe, before casting: ray i = beam * columns + column (the
  // beam x column table, or this scan's rosette), from its column's sweep pose (SweepPoses):
  // world origins and unit world directions.
  void FiredRays(int session, int keyframe, std::vector<Eigen::Vector3f>* origins_world,
                 std::vector<Eigen::Vector3f>* dirs_world) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Odometry drift: a copy of the true session-frame poses whose consecutive increments carry a
// per-session scale error, x/y noise, a yaw and a z random walk (see SimConfig drift.*). The
// first pose is kept.
std::vector<Pose> DriftPoses(const std::vector<Pose>& T_session_sensor_true, const SimConfig& cfg,
                             std::uint64_t seed);

}  // namespace ltm::sim
