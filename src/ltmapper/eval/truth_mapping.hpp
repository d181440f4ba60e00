// ltmapper eval: placing the simulator's truth (true world) into the method's estimated world
// (globally or per keyframe), and truth rebuilt from the labelled scans.
#pragma once

#include "ltmapper/eval/trajectory.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

// Places the simulator's truth (true world frame) into the method's estimated world.
//
// Per keyframe: each truth point p of a session moves by the pose correction of the nearest (3D
// position) TRUE keyframe k of that session: p_est = T_est_k * T_true_k^-1 * p. The method's maps
// are built from scans placed with the estimated poses, so this puts every truth point where the
// method's map of that session puts the same surface, up to the relative drift between
// neighbouring keyframes. One rigid transform for everything (the joint ATE alignment) instead
// leaves the pose error (ATE ~0.25 m) in every point-wise score. true_poses / est_poses: the
// session's T_world_sensor per keyframe, same order; different counts or none: ltm::Error. The
// optional point arrays (cls, session, object) are kept.
PointCloud MapTruthByKeyframes(const PointCloud& truth_world, const std::vector<Pose>& true_poses,
                               const std::vector<Pose>& est_poses, int threads = 0);

struct TruthMapping {
  std::string mode = "global";          // global: T_est_truth for every point; keyframe: per keyframe
  std::string description;              // what was used, for the report inputs
  Pose T_est_truth = Pose::Identity();  // global mode
  std::vector<SessionTrajectory> sessions;  // keyframe mode, by sim session index; est empty when
                                            // the session was not aligned (mapping it is an error)
  // A truth cloud of sim session `session` (world frame) in the estimate frame.
  PointCloud Map(const PointCloud& truth_world, std::size_t session, int threads = 0) const;
  // Pose placing the sensor-frame scan of keyframe k of `session` (true pose T_world_sensor) in
  // the estimate frame: its estimated pose (keyframe mode: the exact per-keyframe correction of
  // every point the keyframe observed), or T_est_truth * T_world_sensor.
  Pose ScanPose(std::size_t session, std::size_t k, const Pose& T_world_sensor) const;
};
TruthMapping GlobalTruthMapping(const Pose& T_est_truth, const std::string& description);
// True poses DIR/truth/<s>/poses_world.txt and estimates aligned_dir/<s>/poses_world.txt of every
// sim session (counts must agree).
TruthMapping KeyframeTruthMapping(const std::string& sim_dir, const std::string& aligned_dir);

// Sensor positions of sim session `session` (truth/<name>/poses_world.txt) in the estimate frame,
// placed by `mapping.ScanPose`, one point per keyframe (LdTrajectories); ltm::Error naming the
// truth folder when there is no such session.
PointCloud SensorPositions(const std::string& sim_dir, std::size_t session, const TruthMapping& mapping);
// truth/<name>/static_world.pcd of sim session `session`: what its scans sampled of the surfaces
// it has (permanent structure and its LD objects), true world; ltm::Error as SensorPositions.
std::string StaticWorldFile(const std::string& sim_dir, std::size_t session);
// LD truth rebuilt the way the method builds its maps: the labelled scans of sim session
// `session` (truth/<name>/labels) placed with `mapping.ScanPose` (the estimated pose of each
// keyframe), keeping the static points whose true-world position has, as its nearest point of the
// session's truth/<name>/static_world.pcd, a point marked by one of `changes` (the session's
// change clouds, true world; each marks its nearest static-world point within voxel_m / 2), each
// labelled with that cloud's class, then voxelised at `voxel_m`. Far from the trajectory the per-keyframe
// mapping of MapTruthByKeyframes blurs by the sessions' relative rotation error times the
// viewing distance; this truth has exactly the method's blur. Returns one cloud per input (at most
// 8; the clouds may overlap: a point marked by several goes into each of them); with
// `sampled_surfaces` one more after them, every static point of the scans placed alike (what the
// session sampled of its surfaces, LdResult::pd_separable).
std::vector<PointCloud> ChangesFromLabelledScans(const std::string& sim_dir, std::size_t session,
                                                 const std::vector<const PointCloud*>& changes,
                                                 const TruthMapping& mapping, double voxel_m, int threads = 0,
                                                 bool sampled_surfaces = false);

}  // namespace ltm::eval
