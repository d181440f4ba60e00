// ltmapper slam: inter-session loops, the anchor-node pose graph, the LT-SLAM stage and the
// lifelong add (aligning one more session to a fixed reference).
#pragma once

#include "ltmapper/slam/config.hpp"

#include <string>
#include <vector>

namespace ltm::slam {

struct LoopRecord {
  NodeKey a, b;                   // a.session < b.session, or equal: a loop within one session
                                  // (OwnLoop); keyframe = position in the session
  std::string source = "sc";      // sc | radius | given
  double sc_distance = -1.0;      // -1 when not from Scan Context
  double yaw_deg = 0.0;           // Scan Context yaw (initial guess)
  Pose T_a_b = Pose::Identity();  // measurement z: p_a = T_a_b * p_b
  double fitness = -1.0;          // GICP fitness [m^2], -1 when not registered
  double overlap = -1.0;          // inlier ratio, -1 when not registered
  double inlier_rms_m = -1.0;     // RMS NN distance of the inliers, -1 when not registered
  double view = -1.0;             // radius candidates between sessions: ViewShare at the predicted
                                  // pose (could the scans overlap there); -1 when not measured
  bool verified = false;          // passed registration
  bool accepted = false;          // used in the final graph
  std::string status;             // accepted / why rejected
  double residual_t_m = -1.0, residual_r_deg = -1.0;  // final unweighted residual
  Matrix6d information = Matrix6d::Identity();        // order x y z rx ry rz
  // With registration.steps: the variance of the turn about the vertical that the registration's
  // Fisher information gives (HeadingVariance) [rad^2]; the graph scales it as the loops' cycles
  // show (LoopHeadingScale) and adds that information on the heading. 0: none.
  double heading_variance = 0.0;
  // With registration.steps: the covariance of the translation that the registration's Fisher
  // information gives (TranslationCovariance, source frame: keyframe b) [m^2]; the graph scales it as
  // the loops' cycles show (LoopTranslationScale) and adds that information on the horizontal
  // translation. Zero: none.
  Eigen::Matrix3d translation_covariance = Eigen::Matrix3d::Zero();
};

// A loop between two keyframes of one session (the radius search's, where its route came back):
// it bends that session's trajectory and says nothing of its placement among the others.
inline bool OwnLoop(const LoopRecord& l) { return l.a.session == l.b.session; }

struct SessionAlignment {
  std::string name;
  bool aligned = false;            // central: always true
  std::string reason;              // why not aligned
  Pose anchor = Pose::Identity();  // A = T_world_session (meaningful when aligned)
  std::vector<Pose> T_session_sensor;  // optimised, in the session's own frame
  std::vector<Pose> T_world_sensor;    // A * T_session_sensor; empty when not aligned
  int sc_candidates = 0, loops_verified = 0, loops_accepted = 0, radius_loops = 0;
  int own_loops = 0;  // accepted loops within the session (its route came back near itself)
  std::vector<Edge> registered;  // its keyframe steps registered (Session::registered), in joint.g2o
  // [deg] the RMS residual rotation of the accepted loops tying it to earlier sessions (the loops'
  // later side) after the optimisation: the rotation uncertainty of its poses against theirs, which
  // LD's tolerances follow (io::ManifestSession::rotation_sigma_deg); 0 without such a loop
  double rotation_sigma_deg = 0.0;
};

struct SlamResult {
  std::vector<SessionAlignment> sessions;
  std::vector<LoopRecord> loops;
  double time_descriptors_s = 0, time_retrieval_s = 0, time_registration_s = 0,
         time_optimisation_s = 0, time_total_s = 0;
  int registrations = 0;
  double refine_radius_m = 0;  // the radius search's radius (OverlapReach)
  double max_translation_m = 0;  // the registrations' derived translation gate (OverlapReach)
  bool solution_usable = true;
  double initial_cost = 0, final_cost = 0;
  int solver_iterations = 0;
  // The loops' heading (LoopHeadingScale): cycles measured, and how far the Fisher information
  // misstates the loops' heading variance (1 when no cycle measured it).
  int heading_cycles = 0;
  double loop_heading_scale = 1.0;
  // The same for the loops' horizontal translation (LoopTranslationScale).
  int translation_cycles = 0;
  double loop_translation_scale = 1.0;
  bool given_poses = false;  // placed by world poses from elsewhere (MeasureGivenPoses), not aligned
};

// Back end alone: anchor initialisation from `loops` (verified ones), consistency gating,
// Ceres optimisation with the robust loss, outlier pruning, aligned / not-aligned decision.
// Sessions need keyframe poses and edges only (no clouds). `loops` outcomes are filled in.
SlamResult OptimizeSessions(const std::vector<Session>& sessions, std::vector<LoopRecord>& loops,
                            const SlamConfig& cfg, int threads = 0);

// Whole LT-SLAM in memory: descriptors, retrieval, registration, graph, radius refinement.
// Session 0 is the central session. Throws ltm::Error on broken input (empty scans, edges to
// missing keyframes, no keyframes); sessions that cannot be aligned are reported, not thrown.
SlamResult AlignSessions(const std::vector<Session>& sessions, const SlamConfig& cfg,
                         int threads = 0);

// The stage from files: loads the session directories (first = central), aligns them and writes
// out_dir as described in docs/FORMATS.md ("LT-SLAM output").
SlamResult RunSlamStage(const SlamConfig& cfg, const std::vector<std::string>& session_dirs,
                        const std::string& out_dir, int threads = 0);
// The same output from world poses the user already has (GNSS / INS, another SLAM): one KITTI
// pose file per session (a pose per keyframe, keyframe order, the sessions' common world frame).
// ReadGivenPoses loads and checks them (ltm::Error naming the file whose pose count differs from
// its session's keyframes) before anything is written; WriteGivenPoses places every session as
// given, measured by MeasureGivenPoses, into out_dir.
struct GivenPoses {
  std::vector<std::string> session_dirs;
  std::vector<Session> sessions;
  SlamResult placed;  // every session aligned at its given poses
};
GivenPoses ReadGivenPoses(const std::vector<std::string>& session_dirs, const std::vector<std::string>& pose_files);
// One loaded session placed by the world poses of `file` (one per keyframe, keyframe order):
// aligned, its anchor the world pose of its first keyframe's odometry frame.
SessionAlignment GivenAlignment(const Session& s, const std::string& file);
SlamResult WriteGivenPoses(const SlamConfig& cfg, GivenPoses given, const std::string& out_dir, int threads = 0);
// Given world poses (`res`: every session aligned, T_world_sensor set) measured as LT-SLAM measures
// its own: radius loops between every two sessions at the given poses (within the keyframes'
// overlap reach), verified by GICP from the given relative pose. Each later session's
// rotation_sigma_deg is its verified loops' RMS rotation residual against the given poses: what
// LD's tolerances follow, so poses from elsewhere get margins as measured as LT-SLAM's (without a
// verified loop: 0, LD's prior). The loops go to res.loops (loops.csv).
void MeasureGivenPoses(const std::vector<Session>& sessions, SlamResult& res, const SlamConfig& cfg,
                       int threads = 0);

// ------------------------------------------------------------------------------ lifelong add
// A session already in the world frame, as the fixed reference that a new session is aligned
// to: its keyframes carry their world poses (`T_world_sensor`, keyframe order) and its odometry
// is rebuilt from them with an information far above any loop's, so the new session's loops
// cannot bend it (it moves by under a thousandth of a loop's pull); its own loops are dropped.
Session WorldReference(Session session, const std::vector<Pose>& T_world_sensor, const SlamConfig& cfg);
// Aligns `query` to `reference` (a WorldReference: its frame is the world) with the same
// retrieval, verification and graph as AlignSessions. Result sessions: {reference, query}; the
// query's T_world_sensor are world poses. The cost follows the two sessions' sizes only.
SlamResult AlignToReference(const Session& reference, const Session& query, const SlamConfig& cfg,
                            int threads = 0);
// aligned_dir/<folder>/: poses_world.txt, poses_world_tum.txt and anchor.txt when aligned, else
// NOT_ALIGNED.txt with the reason (docs/FORMATS.md, "LT-SLAM output"). The folder is the
// session's name, or its staging name.
void WriteSessionAlignment(const std::string& aligned_dir, const std::string& folder, const SessionAlignment& a);

}  // namespace ltm::slam
