// ltmapper eval: trajectory scores (ATE, RPE, inter-session consistency) and the rigid
// alignment they use.
#pragma once

#include "ltmapper/eval/config.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

struct ErrorStats {
  std::size_t n = 0;
  double rmse = kNaN, mean = kNaN, median = kNaN, max = kNaN;
};
ErrorStats Stats(std::vector<double> values);

struct PoseErrors {
  ErrorStats trans_m;   // [m]
  ErrorStats rot_deg;   // [deg]
};

// One session's keyframe poses T_world_sensor: truth (sim world) and estimate (any frame; the
// ATE alignment removes the frame difference), same keyframes in the same order. Session 0 is
// the central session.
struct SessionTrajectory {
  std::string name;
  std::vector<Pose> truth;
  std::vector<Pose> est;
};

struct TrajSessionResult {
  std::string name;
  std::size_t poses = 0;
  PoseErrors ate, rpe;
  Pose T_truth_est = Pose::Identity();  // alignment applied to this session's estimate
};
struct ConsistencySessionResult {
  std::string name;                     // query session
  std::size_t pairs = 0, skipped = 0;   // skipped: no central keyframe within the max distance
  PoseErrors error;
};
struct TrajResult {
  std::string align;
  std::string rpe_unit;
  double rpe_delta = 0.0;
  PoseErrors ate, rpe;                  // over all sessions' poses / pairs
  std::vector<TrajSessionResult> sessions;
  PoseErrors consistency;               // over all query sessions
  std::vector<ConsistencySessionResult> consistency_sessions;
  std::vector<std::string> missing;     // sessions without an estimate (filled by loaders)
};

// Rigid transform T (no scale) minimising sum |T * src_i - dst_i|^2 (Horn / Umeyama: SVD of the
// cross-covariance, reflection fixed). Needs >= 1 point; with < 3 non-collinear points the
// rotation is the least-squares one SVD gives (identity for a single point).
Pose AlignRigid(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst);

// ATE: per pose |t_truth - t_aligned| and the angle of R_truth^T R_aligned.
// RPE: for each i, j = first later keyframe whose true path distance from i is >= rpe_delta
// (or i + rpe_delta frames); error of (T_i^-1 T_j)_est against (T_i^-1 T_j)_truth.
// Consistency: for each query keyframe q, its nearest central keyframe c by true position
// (within consistency_max_dist_m); error of (T_c^-1 T_q)_est against the truth. Independent of
// the world frame, so it measures how well sessions agree with each other.
TrajResult EvaluateTrajectories(const std::vector<SessionTrajectory>& sessions,
                                const EvalConfig& cfg);

}  // namespace ltm::eval
