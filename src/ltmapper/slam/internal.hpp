// Internal helpers shared by the slam .cpp files (not part of the public API).
#pragma once

#include "ltmapper/slam/slam.hpp"

#include <array>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ltm::geometry {
class KdTree;
}

namespace ltm::slam {

using Vector6d = Eigen::Matrix<double, 6, 1>;

// ------------------------------------------------------------------------------ GICP (gicp.cpp)
// A cloud prepared for GICP: its kd-tree and per-point local planes of the k nearest
// neighbours, each computed on first use (PlaneAt is not thread-safe: one registration per thread),
// or all at once by PrepareAllPlanes (then PlaneAt only reads: the cloud may take part in several
// registrations at once). A plane depends on the cloud alone, so either way gives the same.
class GicpCloud {
 public:
  struct Plane {
    Eigen::Matrix3d cov = Eigen::Matrix3d::Identity();  // GICP covariance: eigenvalues (eps, 1, 1)
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();   // zero when too few neighbours for a surface
    double spread = 0.0;  // [m^2] variance of the neighbours along the normal (the surface's roughness)
  };
  GicpCloud(const PointCloud& cloud, int covariance_neighbours);
  ~GicpCloud();
  GicpCloud(GicpCloud&&) noexcept;
  const PointCloud& cloud() const;
  const Plane& PlaneAt(std::size_t i) const;
  void PrepareAllPlanes();
  int neighbours() const { return k_; }  // k of the local planes
  std::unique_ptr<geometry::KdTree> tree;

 private:
  int k_ = 0;
  mutable std::vector<Plane> planes_;
  mutable std::vector<std::uint8_t> has_plane_;
};
struct GicpOptions {
  double max_correspondence_m = 1.0;  // pairs farther apart are not used
  int max_iterations = 30;            // Gauss-Newton steps at most
  std::size_t min_pairs = 6;          // fewer pairs than the pose's 6 unknowns: not solvable (not converged)
  // A step below both bounds ends the iterations: far below the verification's voxel-sized gates.
  double converged_rotation_rad = 1e-5;   // [rad]
  double converged_translation_m = 1e-5;  // [m]
};
struct GicpResult {
  Pose T = Pose::Identity();            // T_target_source
  bool converged = false;
  int iterations = 0;
};
// GICP of `source` onto `target` from `guess` (T_target_source).
GicpResult AlignGicp(const GicpCloud& target, const GicpCloud& source, const Pose& guess, const GicpOptions& opt);
// Whether a cloud of `points` points can take part in a registration: more than a local plane's
// neighbours (cfg.reg_covariance_neighbours).
bool Registrable(std::size_t points, const SlamConfig& cfg);
// The fine stage alone, on clouds prepared once for several registrations (GicpCloud, planes of
// cfg.reg_covariance_neighbours): the same result as RegisterGicp with the coarse stage off (an
// ltm::Error when cfg has it on: it needs the clouds, not their GICP preparation).
RegistrationResult RegisterGicp(const GicpCloud& target, const GicpCloud& source, const Pose& T_target_source_init,
                                const SlamConfig& cfg);
// The inlier ratio of `source` under T_target_source against `target` without registering: the
// share of source points with a target point within InlierRadius, as the verification counts it.
double OverlapRatio(const GicpCloud& target, const PointCloud& source, const Pose& T_target_source,
                    const SlamConfig& cfg);
// The share of `source` under T_target_source that lies where the target's sensor looked: in a
// direction (from the target's origin, 5 deg bins) in which the target has a return at least as
// far, less slack_m. Whether the two scans could overlap at that pose, whatever they hold.
double ViewShare(const PointCloud& target, const PointCloud& source, const Pose& T_target_source, double slack_m);

// The widest turn about the sensor's z axis [deg] in which `scan` holds no return (ViewShare's
// bins): 0-5 for a ring sensor, 290 for a 70 deg forward cone.
double WidestBlindArcDeg(const PointCloud& scan);
// The points of `cloud` (a downsampled scan in its sensor frame, `up` the vertical in that frame)
// off the ground: levelled, those more than a registration voxel above the lowest point of their
// column (cells of two voxels; a voxel's centroid lies within one voxel of the ground it samples).
// The ground says nothing of the turn about the vertical, and a ring sensor samples it in rings
// that travel with the sensor: they pull a registration of two of its scans toward standing still,
// along the route and, through the structures beside it, in heading (registration.cpp).
PointCloud OffTheGround(const PointCloud& cloud, const Eigen::Vector3d& up, const SlamConfig& cfg);
// Throws ltm::Error for sessions without keyframes, edges to missing keyframes, non-finite poses.
void ValidateSessionGraphs(const std::vector<Session>& sessions);
// Diagonal information of independent translation and rotation std-devs [m], [rad].
Matrix6d DiagInformation(double sigma_t, double sigma_r);
// The variance [rad^2] of the turn about the vertical (`up`, in the source keyframe's frame) that a
// registration's Fisher information implies (pose_graph.cpp).
double HeadingVariance(const Matrix6d& fisher, const Eigen::Vector3d& up, const SlamConfig& cfg);
// Information of a registered step or loop on that turn alone, of the given variance [rad^2].
Matrix6d HeadingInformation(double variance, const Eigen::Vector3d& up, const SlamConfig& cfg);
// The vertical in a keyframe's sensor frame: the z axis of its session's odometry frame (inertial
// odometry keeps that frame's z against gravity; the add's reference holds world poses).
Eigen::Vector3d Up(const Keyframe& kf);
// The turn about `up` of the rotation from `a` to `b` [rad] (its axis is the same in either frame).
double TurnAbout(const Pose& a, const Pose& b, const Eigen::Vector3d& up);
// The variance [rad^2] of a session edge's turn about `up` as the graph reads its information
// (EdgeInformation: the file's or the config's odometry sigmas; a registered step's own).
double TurnVariance(const Edge& e, const Eigen::Vector3d& up, const SlamConfig& cfg, bool own_information);
// The variance [m^2] per axis (the mean of the two) of an odometry edge's translation in the plane
// square to `up`, as the graph reads its information (EdgeInformation; `own_information`: a
// registered step's own).
double StatedHorizontalVariance(const Edge& e, const Eigen::Vector3d& up, const SlamConfig& cfg,
                                bool own_information = false);
// Calls f(a, e) for each edge e of `edges` (a session's odometry or registered steps) that is a
// step, from keyframe position a to a + 1; edges between other keyframes are skipped.
template <class F>
void ForEachStep(const Session& s, const std::vector<Edge>& edges, F&& f) {
  for (const Edge& e : edges) {
    const int a = s.Find(e.from), b = s.Find(e.to);
    if (a >= 0 && b == a + 1) f(std::size_t(a), e);
  }
}
// Whether n errors' sum of squares fits errors of the given variance: within what such errors
// exceed one time in a thousand (a chi-square's upper tail, Wilson-Hilferty's approximation).
bool SquaresWithin(double sum_sq, std::size_t n, double variance);
// What a session's registered steps say of their own heading, and of the odometry's:
//  - closures: each pair of verified steps k, k + 1 is closed by registering keyframe k + 2 onto k
//    directly. The two-step turn differs from the sum of the two steps' turns by the three
//    registrations' errors. A turn each registration of a scan pair makes of its own (a scene not
//    symmetric about the route: b, the same for a step and a two-step) survives in the closure as
//    b + b - b: the closures' mean is the steps' bias (bias; on seed 11's HDL-32E -0.0005 and
//    -0.0017 deg a step against the truth's -0.0006 and -0.0020). Their variance about it is three
//    steps' (step_var), and their squared ratios to the variances the Fisher information gives them
//    say how far it misstates those (scale, VarianceScale: off the ground it overstates a step's
//    heading variance about 16 times there);
//  - against the odometry: a step's turn, its bias taken off, minus the odometry's over the same
//    step holds both their errors, so the odometry's heading error (mean square: a gyro's bias
//    counts) is that mean square less the step's variance (odom_var). What the odometry states of
//    itself (its edges' information as the graph reads it, TurnVariance: stated_var, the mean
//    over the steps) bounds that: differences whose squares lie beyond what the step's and the
//    stated variances allow (SquaresWithin) say the steps err more than their closures show. A
//    forward cone's consecutive scans share their errors, which a closure cancels (the default
//    seed's rosette: closures 0.195 deg a step, against the odometry 0.38 deg, whose truth drifts
//    0.05 and states 0.2). Their mean is not tested: a gyro's bias, which an odometry's stated
//    information rarely covers, and the steps' leave the same mean (odom_mean, logged);
//  - admitted: finer than the odometry and explained by the two.
struct StepHeading {
  double bias = 0.0, step_var = 0.0, odom_var = 0.0, scale = 1.0;  // [rad], [rad^2], [rad^2], [-]
  double odom_mean = 0.0, stated_var = 0.0;                         // [rad], [rad^2]
  std::size_t closures = 0, compared = 0;
  bool finer = false, explained = false;
  std::vector<double> variance;  // per verified step, the Fisher information's (HeadingVariance) [rad^2]
};
StepHeading MeasureStepHeading(const std::vector<std::optional<RegistrationResult>>& steps,
                               const std::vector<std::optional<RegistrationResult>>& skips, const Session& session,
                               const SlamConfig& cfg);
// What a session's registered steps say of their translation in the horizontal plane (square to
// the vertical, Up), as MeasureStepHeading of the heading. Off the ground (OffTheGround) no ring of
// the ground pulls a step toward standing still; the structures beside the route hold it, the
// Fisher information says how well in each direction (a straight street's axis: hardly).
//  - closures: a two-step's horizontal translation (in keyframe k's frame) differs from the two
//    steps' composed by the three registrations' errors. A shift each registration makes of its
//    own (the registration voxels travel with the sensor) survives as b - b - b: minus the
//    closures' mean is the steps' bias (on the demo 1.0-1.6 mm a step along the route, against the
//    truth's 0.9-1.2). Per horizontal axis, the median of their squares over a chi-square's of one
//    degree, over three, is a step's variance (step_var); the squared closures whitened by the
//    three Fisher covariances say how far those misstate it (scale, VarianceScale). A share of the
//    step that each registration keeps of its guess (along a street's axis) cancels in a closure;
//  - against the odometry: a step's horizontal translation minus the odometry's over the same step
//    holds both their errors (an odometry's scale error and its noise a step), so the odometry's
//    variance per axis is the median square over a chi-square's median less the step's (odom_var);
//    what the odometry states (its edges' information as the graph reads it: stated_var, per axis)
//    bounds the differences as for the heading (SquaresWithin: explained);
//  - admitted (with the heading's): finer than the odometry and explained by the two.
struct StepTranslation {
  double step_var = 0.0, odom_var = 0.0, stated_var = 0.0, scale = 1.0;  // [m^2] per axis, [-]
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();  // [m] a step's own horizontal shift (keyframe k's frame)
  std::size_t closures = 0, compared = 0;
  bool finer = false, explained = false;
  std::vector<Eigen::Matrix3d> covariance;  // per verified step, the Fisher information's of its translation
                                            // (source frame, TranslationCovariance) [m^2]
};
StepTranslation MeasureStepTranslation(const std::vector<std::optional<RegistrationResult>>& steps,
                                       const std::vector<std::optional<RegistrationResult>>& skips,
                                       const Session& session, const SlamConfig& cfg);
// The covariance [m^2] of the translation (source frame) that a registration's Fisher information
// implies, with the same negligible prior as HeadingVariance (pose_graph.cpp).
Eigen::Matrix3d TranslationCovariance(const Matrix6d& fisher, const SlamConfig& cfg);
// Two unit vectors spanning the plane square to `up`.
Eigen::Matrix<double, 3, 2> Horizontal(const Eigen::Vector3d& up);
// Information of a registered step on its translation in the plane square to `up` alone (the
// 2 x 2 covariance `horizontal` in Horizontal(up)'s axes); height is left to the odometry.
Matrix6d HorizontalInformation(const Eigen::Matrix2d& horizontal, const Eigen::Vector3d& up);
// How far the variances a model gives understate (> 1) or overstate (< 1) the errors, from the
// ratios (squared error over the model's variance) of errors measured one degree of freedom each:
// their median over a chi-square's of one degree, which a few gross errors (a wrong loop, a step
// through a moving truck) do not move; 1 without ratios (pose_graph.cpp).
double VarianceScale(std::vector<double> ratio);
// The median of a chi-square of one degree of freedom.
constexpr double kChiSquare1Median = 0.45493642;
// How far the loops' heading variances (LoopRecord::heading_variance) misstate their errors,
// measured on the loops themselves (pose_graph.cpp): two verified loops between the same sessions,
// next to each other along the first session's route, close a cycle through each session's edges
// between their keyframes (of a registered step and the odometry edge, the finer in heading). Its turn
// about the vertical is the two loops' errors plus the edges'. Where the edges' variance (from
// their information) is below the two loops', the cycle measures the loops: the scale is the median
// over those cycles of (turn^2 - edges' variance) / (the two loops' variances), over the median of
// a chi-square of one degree (VarianceScale). Where that median is not positive the cycles do not
// measure the loops (cycles 0: no heading information).
struct LoopCycleScale {
  int cycles = 0;
  double scale = 1.0;
};
LoopCycleScale LoopHeadingScale(const std::vector<Session>& sessions, const std::vector<LoopRecord>& loops,
                                const SlamConfig& cfg);
// The same for the loops' horizontal translation (LoopRecord::translation_covariance): the two loops'
// translations and the edges' close the same cycle; per horizontal axis of keyframe a1, squared gap
// / (the two loops' variances), the whole gap laid on the loops (an upper bound of their error).
// Only cycles whose edges all hold the translation finer than the config's odometry count.
LoopCycleScale LoopTranslationScale(const std::vector<Session>& sessions, const std::vector<LoopRecord>& loops,
                                    const SlamConfig& cfg);
// Information of an inter-session loop: the paper's adaptive covariance from the registration
// fitness plus the registration's own (the inverse of its Fisher information; zero: none).
Matrix6d LoopInformation(double fitness, const Matrix6d& fisher, const SlamConfig& cfg);
// Cumulative path length [m] along a session's keyframe poses (drift-aware tolerances, loops
// within a session); of a session: along its odometry (the keyframes' session-frame poses).
std::vector<double> PathLength(const std::vector<Pose>& poses);
std::vector<double> PathLength(const Session& session);
// Rotation angle of R [deg].
double AngleDeg(const Eigen::Matrix3d& R);
// Whether two placements of one session (anchors T_world_session) implied by evidence
// `travelled_m` apart along the routes are one: within graph.consensus_t_m plus
// consensus_drift_ratio of that path, and graph.consensus_r_deg (the consensus's rule).
bool PlacementsAgree(const Pose& A, const Pose& B, double travelled_m, const SlamConfig& cfg);

// ------------------------------------------------------------------ placement checks (placements.cpp)
// What the checks of the placements read besides the loops and the result: each session's route
// (distance along its odometry, per keyframe), how far apart loops are one place (the median
// overlap reach), and two services of the alignment: a keyframe's look-alike candidates in its own
// drive, and their registration and verification.
struct PlacementEvidence {
  const std::vector<std::vector<double>>& routes;
  double place_m = 0.0;
  std::function<std::vector<LoopRecord>(const NodeKey&)> look_alikes;
  std::function<void(std::vector<LoopRecord>&)> verify;
};
// The placements a check drops, each with its reason (the session's loops between sessions are
// rejected in `loops`): those their predicted overlaps contradict (DropContradicted), then of the
// others those a single move to look-alike places would explain as well (DropAmbiguous).
std::vector<std::pair<std::size_t, std::string>> DroppedPlacements(const PlacementEvidence& e, std::vector<LoopRecord>& loops,
                                                                   const SlamResult& res, const SlamConfig& cfg);

// ------------------------------------------------------------------- global registration (global.cpp)
// An aligned session's map in the world frame with FPFH features, for placing submaps of a session
// Scan Context could not align (the fallback; its placements are loop candidates to verify).
// FPFH descriptors (Rusu et al. 2009, "Fast Point Feature Histograms") of every point of `cloud`
// with unit normals `normals` (a non-finite normal: none), from the neighbours within radius_m:
// per point, the histogram (11 bins each of the three Darboux-frame angles) of its pairs with
// its neighbours (SPFH); its FPFH is its neighbours' SPFHs weighted by 1 / squared distance, each
// of the three parts scaled to sum 100 (all zero without a neighbour's SPFH). PCL's
// FPFHEstimation computes the same numbers; this one saves loading pcl_features at every start.
using Fpfh = std::array<float, 33>;
std::vector<Fpfh> FpfhDescriptors(const PointCloud& cloud, const std::vector<Eigen::Vector3f>& normals,
                                  double radius_m);

class GlobalMap {
 public:
  GlobalMap(const PointCloud& world_map, const SlamConfig& cfg);
  ~GlobalMap();
  std::size_t size() const;  // points at the coarse voxel
  // T_world_submap of a submap (its own frame) by FPFH + RANSAC, or nothing when no placement
  // reaches the inlier fraction registration.min_overlap. Not thread-safe (std::rand).
  std::optional<Pose> Place(const PointCloud& submap) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class Stopwatch {
 public:
  Stopwatch() : t0_(std::chrono::steady_clock::now()) {}
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }

 private:
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace ltm::slam
