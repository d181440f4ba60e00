// ltmapper eval: scores every stage against ground truth (usually the simulator's truth/).
//
//   trajectories  ATE (after one rigid alignment), RPE, inter-session consistency
//   hd            point-wise SA / DA / AA of HD removal (KTH DynamicMap benchmark rule)
//   ld            precision / recall / F1 of PD and ND points, strong and weak
//   restore       the LT-mapper paper's Chamfer table over cubic patches
//   storage       bytes on disk, wall time and peak memory of a stage
//
// Every metric is a plain function returning a result struct; a Report gathers them and is
// written as JSON (machines) and Markdown (people). Undefined ratios (0/0) are NaN in the
// structs, `null` in JSON and "n/a" in Markdown. Depends on core; io, geometry and TBB are used
// only inside the .cpp files.
#pragma once

#include "ltmapper/core/core.hpp"

#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ltm::eval {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// ------------------------------------------------------------------------------------ config
struct EvalConfig {
  // Trajectories.
  std::string traj_align = "joint";        // joint: one SE(3) over all sessions; per_session; none
  std::string rpe_unit = "m";              // m: pairs `rpe_delta` metres of true path apart; frames
  double rpe_delta = 10.0;                 // [m or keyframes] RPE pair separation
  double consistency_max_dist_m = 10.0;    // [m] query keyframes farther than this from every
                                           // central keyframe (true positions) are skipped
  // HD removal.
  double hd_match_dist_m = 0.1;            // [m] truth point preserved if an output point is this close
  double hd_truth_max_range_m = 0.0;       // [m] drop truth points farther from their sensor (0 = keep all)
  int hd_keyframe_stride = 1;              // use every n-th labelled scan of a session (sim form)
  double hd_near_static_m = 0.1;           // [m] HD truth points this close to a static truth point are
                                           // also scored apart ("hd near static": a map that keeps the
                                           // static point keeps them at the match distance); 0 = off
  // LD changes.
  double ld_match_dist_m = 0.2;            // [m] predicted/truth change points closer than this match
  double ld_same_point_m = 0.001;          // [m] "same point" when removing predicted strong ND from
                                           // the central static map to derive the kept map
  std::vector<double> ld_bands_m = {20.0, 40.0, 60.0};  // [m] upper edges of the distance bands (from
                                           // the session that had to observe the place) for P / R per
                                           // band; a last band holds the rest; empty = no bands
  // Restoration (paper table).
  double patch_m = 5.0;                    // [m] edge of the cubic patches
  int patch_min_points = 25;               // a patch is valid when BOTH maps have >= this many points
  std::string chamfer = "mean";            // mean: (d(A->B) + d(B->A)) / 2 of mean NN distances [m];
                                           // fan_squared: sum of the two mean squared NN distances [m^2]
  std::vector<double> chamfer_thresholds = {1.0, 2.0, 3.0};  // count patches with CD > each
  double same_class_m = 0.3;               // [m] "same class" radius when both maps carry classes (one
                                           // LT-removert map voxel): share of each map's points with a
                                           // point of the other map of the same class this close; 0 = off
  // Changed objects (clusters of LT-map vs the simulator's LD objects).
  double obj_match_dist_m = 0.2;           // [m] a point matches when the other set has a point this close
  double obj_voxel_m = 0.1;                // [m] truth and cluster points voxel-downsampled to this
  double obj_min_iou = 0.5;                // an object is found when a cluster reaches this point IoU
  int obj_min_truth_points = 10;           // truth objects with fewer (voxelised) points: not scored
  int obj_keyframe_stride = 1;             // use every n-th labelled scan for the truth points
  int obj_min_change_points = 20;          // truth objects with fewer detectable change points
                                           // (pair changes.ply: PD, strong ND) are not scored
  // Live / meta map content (new and removed cars); points match at ld_match_dist_m.
  double livemeta_min_fraction = 0.5;      // an object is "in" a map when at least this fraction of
                                           // its truth points has a map point within ld_match_dist_m

  template <class V>
  void Visit(V& v) {
    v("traj.align", traj_align, {"joint", "per_session", "none"});
    v("traj.rpe_unit", rpe_unit, {"m", "frames"});
    v("traj.rpe_delta", rpe_delta, "m|frames", 1e-3, 1e6);
    v("traj.consistency_max_dist_m", consistency_max_dist_m, "m", 0.0, 1e6);
    v("hd.match_dist_m", hd_match_dist_m, "m", 1e-4, 10.0);
    v("hd.truth_max_range_m", hd_truth_max_range_m, "m", 0.0, 1e4);
    v("hd.keyframe_stride", hd_keyframe_stride, "", 1, 1000000);
    v("hd.near_static_m", hd_near_static_m, "m", 0.0, 10.0);
    v("ld.match_dist_m", ld_match_dist_m, "m", 1e-4, 10.0);
    v("ld.same_point_m", ld_same_point_m, "m", 0.0, 1.0);
    v("ld.bands_m", ld_bands_m, "m", 0.0, 1e6);
    v("restore.patch_m", patch_m, "m", 0.01, 1e4);
    v("restore.min_points", patch_min_points, "", 1, 100000000);
    v("restore.chamfer", chamfer, {"mean", "fan_squared"});
    v("restore.thresholds", chamfer_thresholds, "m|m^2", 0.0, 1e6);
    v("restore.same_class_m", same_class_m, "m", 0.0, 100.0);
    v("objects.match_dist_m", obj_match_dist_m, "m", 1e-4, 10.0);
    v("objects.voxel_m", obj_voxel_m, "m", 0.0, 10.0);
    v("objects.min_iou", obj_min_iou, "", 0.0, 1.0);
    v("objects.min_truth_points", obj_min_truth_points, "", 0, 100000000);
    v("objects.keyframe_stride", obj_keyframe_stride, "", 1, 1000000);
    v("objects.min_change_points", obj_min_change_points, "", 0, 100000000);
    v("livemeta.min_fraction", livemeta_min_fraction, "", 0.0, 1.0);
  }
  // Range checks plus the cross-field rules (ld.bands_m strictly increasing); ltm::Error naming `where`.
  void Validate(const std::string& where = "eval config") const;
};

// ----------------------------------------------------------------------------- trajectories
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

// ---------------------------------------------------------------------------------- HD removal
struct ClassCount {
  std::string name;         // "static", "hd", "ld:<object class>", "unknown"
  std::size_t total = 0;
  std::size_t preserved = 0;
};
struct HdResult {
  double match_dist_m = 0.0;
  std::size_t output_points = 0;
  std::size_t static_total = 0, static_preserved = 0;
  std::size_t dynamic_total = 0, dynamic_removed = 0;
  // HD points farther than hd_near_static_m from every static truth point (when a static
  // reference was given): DA over those alone.
  bool separable_given = false;
  std::size_t separable_total = 0, separable_removed = 0;
  double da_separable = kNaN;
  std::size_t ignored = 0;  // truth points of class unknown or beyond hd_truth_max_range_m
  double sa = kNaN, da = kNaN, aa = kNaN;  // SA = preserved static / static, DA = removed HD / HD
  std::vector<ClassCount> classes;         // sorted: static, ld:*, hd, unknown
};

// KTH DynamicMap benchmark rule: every truth point (PointCloud::cls: kStatic or kHD, world frame
// of the output) is matched to the nearest output point; within hd_match_dist_m it is preserved,
// else removed. The output map is usually voxel-downsampled: with voxel v a truth point of an
// occupied voxel lies within v*sqrt(3) of the voxel's centroid and typically within ~v/2, so
// choose hd_match_dist_m around v (a larger distance lets HD points next to kept static points
// count as preserved, lowering DA). Feeding truth in pieces (Add) gives the same counts as one
// big cloud, so the raw map of a long session never has to be held in memory.
class HdEvaluator {
 public:
  // object_classes: LD object id -> class name, for the per-class rows (optional).
  HdEvaluator(PointCloud output, const EvalConfig& cfg,
              std::map<int, std::string> object_classes = {}, int threads = 0);
  ~HdEvaluator();
  HdEvaluator(const HdEvaluator&) = delete;
  HdEvaluator& operator=(const HdEvaluator&) = delete;
  // Truth points with labels (cls required; object optional: -1 / absent = permanent static).
  // `sensor` is where the points were observed from (for hd_truth_max_range_m).
  void Add(const PointCloud& truth, const Eigen::Vector3d& sensor = Eigen::Vector3d::Zero());
  // Static truth points (world frame of the output) for the "hd near static" split; call before Add.
  void SetStaticReference(PointCloud static_truth);
  HdResult Result() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
HdResult EvaluateHd(const PointCloud& truth, const PointCloud& output, const EvalConfig& cfg,
                    const std::map<int, std::string>& object_classes = {}, int threads = 0);

// ---------------------------------------------------------------------------------------- LD
struct ChangeClouds {
  PointCloud pd_strong, pd_weak, nd_strong, nd_weak;
};
struct PrfStats {
  std::size_t predicted = 0, predicted_matched = 0;  // predicted points within d of truth
  std::size_t truth = 0, truth_matched = 0;          // truth points within d of a prediction
  double precision = kNaN, recall = kNaN, f1 = kNaN;
};
// Pooled PD and ND by distance band: a PD point's distance to the nearest central keyframe (the
// session that would have had to observe its place), an ND point's to the nearest query keyframe;
// precision over the predicted points of the band, recall over its truth points, each matched
// against all points of the other set.
struct LdBand {
  double min_m = 0.0, max_m = 0.0;  // distances in [min_m, max_m); max_m = +inf for the last band
  PrfStats pd, nd;
};
struct LdResult {
  double match_dist_m = 0.0;
  PrfStats pd_strong, pd_weak, pd, nd_strong, nd_weak, nd;  // pd / nd: strong and weak pooled
  std::vector<LdBand> bands;  // empty without keyframe positions (LdTrajectories) or ld.bands_m
  // Weak ND (static in central, never seen through by the query) must stay in the map.
  bool kept_map_given = false;
  std::size_t weak_nd_truth = 0, weak_nd_kept = 0;
  double weak_nd_preserved = kNaN;
  // Strength correctness: among predicted PD (ND) points within d of a truth PD (ND) point of
  // either strength, the fraction whose nearest such truth point has the predicted strength.
  std::size_t pd_matched = 0, pd_strength_correct = 0;
  double pd_strength_accuracy = kNaN;
  std::size_t nd_matched = 0, nd_strength_correct = 0;
  double nd_strength_accuracy = kNaN;
};
// Keyframe positions of the pair's sessions, in the frame of the change clouds (for LdBand).
struct LdTrajectories {
  PointCloud central, query;
};
// Truth and prediction in the same frame. `kept_map` (may be null) is the map the method keeps
// after the update (static / live map): weak-ND truth points within d of it count as kept.
// With `trajectories` (may be null) the result holds the distance bands of cfg.ld_bands_m
// (strictly increasing, else ltm::Error).
LdResult EvaluateLd(const ChangeClouds& truth, const ChangeClouds& predicted,
                    const PointCloud* kept_map, const EvalConfig& cfg, int threads = 0,
                    const LdTrajectories* trajectories = nullptr);
// Where the LD prediction is wrong, pooled per kind (PD vs PD, ND vs ND) at ld_match_dist_m:
// predicted points with no truth point of their kind within d (false positives) and truth
// points with no predicted point within d (false negatives). `cls` keeps each point's own class
// (kPDStrong ... kNDWeak), so a PLY of either shows which output or truth cloud it came from.
struct LdErrors {
  PointCloud false_positives, false_negatives;
};
LdErrors LdErrorClouds(const ChangeClouds& truth, const ChangeClouds& predicted, const EvalConfig& cfg,
                       int threads = 0);
// Kept map derived from a removert output: the central static map minus the points that have a
// predicted strong-ND point within ld_same_point_m (strong ND is removed, weak ND kept).
PointCloud KeptMapFromChanges(const PointCloud& central_static, const PointCloud& nd_strong,
                              const EvalConfig& cfg, int threads = 0);

// ------------------------------------------------------------------------------ restoration
struct RestoreResult {
  double patch_m = 0.0;
  int min_points = 0;
  std::string chamfer;
  std::size_t points_a = 0, points_b = 0;
  std::size_t patches_a = 0, patches_b = 0, patches_both = 0;  // occupied patches
  std::size_t np_valid = 0;                // patches where both maps have >= min_points
  double max = kNaN, mean = kNaN, variance = kNaN;  // over valid patches (population variance)
  std::vector<double> thresholds;
  std::vector<std::size_t> np_above;       // valid patches with CD > thresholds[k]
  // Class agreement (both maps labelled, same_class_m > 0; else NaN): the share of A's points with
  // a B point of the same class within same_class_m, and the reverse.
  double same_class_m = 0.0;
  double same_class_a = kNaN, same_class_b = kNaN;
};
// Both maps in the same frame. Patches are the cells floor(p / patch_m) of one grid anchored at
// the origin. In a valid patch, d(A->B) is the mean over A's points of the distance to the
// nearest B point OF THE SAME PATCH, and CD = (d(A->B) + d(B->A)) / 2 [m] ("mean"), or the sum
// of the two directed means of squared distances [m^2] ("fan_squared", Fan et al. 2017).
RestoreResult EvaluateRestore(const PointCloud& a, const PointCloud& b, const EvalConfig& cfg,
                              int threads = 0);
// Share of `want`'s points with a point of `got` of the same class within radius_m (0 when want
// is empty). Both clouds must carry classes (cls), else ltm::Error.
double SameClassFraction(const PointCloud& want, const PointCloud& got, double radius_m, int threads = 0);

// ---------------------------------------------------------------------------- truth mapping
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
// LD truth rebuilt the way the method builds its maps: the labelled scans of sim session
// `session` (truth/<name>/labels) placed with `mapping.ScanPose` (the estimated pose of each
// keyframe), keeping the static points whose true-world position has, as its nearest point of the
// session's truth/<name>/static_world.pcd, a point marked by one of `changes` (the session's
// change clouds, true world; each marks its nearest static-world point within voxel_m / 2), each
// labelled with that cloud's class, then voxelised at `voxel_m`. Far from the trajectory the per-keyframe
// mapping of MapTruthByKeyframes blurs by the sessions' relative rotation error times the
// viewing distance; this truth has exactly the method's blur. Returns one cloud per input.
std::vector<PointCloud> ChangesFromLabelledScans(const std::string& sim_dir, std::size_t session,
                                                 const std::vector<const PointCloud*>& changes,
                                                 const TruthMapping& mapping, double voxel_m, int threads = 0);


// ----------------------------------------------------------------------------- live / meta map
// The criterion "the live map contains new parked cars; the meta map does not": truth objects of
// some classes (cars) that are new since session 0 (present in the last session, absent from 0)
// or removed since (present in 0, absent from the last). Each session where the object exists
// gives a view: its points in that session's static_world, mapped with that session's keyframes
// (the map may hold the object as any of those sessions placed it, e.g. added at an earlier
// step). An object is in a map when, in its best view, >= livemeta_min_fraction of the points
// have a map point within ld_match_dist_m. Wanted: new objects in live and not in meta, removed
// objects in neither. Objects whose largest view has < obj_min_truth_points points: not scored.
struct LiveMetaObject {
  int id = -1;
  std::string cls, placement;
  bool added = true;              // true: new since session 0; false: removed since session 0
  std::vector<PointCloud> views;  // truth points per session where it exists, estimate frame
};
struct LiveMetaScore {
  int id = -1;
  std::string cls, placement;
  bool added = true;
  std::size_t points = 0;          // largest view
  double live_fraction = kNaN, meta_fraction = kNaN;  // best view for each map
  bool scored = false, in_live = false, in_meta = false;
};
struct LiveMetaResult {
  double match_dist_m = 0.0, min_fraction = 0.0;
  std::size_t live_points = 0, meta_points = 0;
  std::size_t added = 0, added_in_live = 0, added_in_meta = 0;        // scored objects only
  std::size_t removed = 0, removed_in_live = 0, removed_in_meta = 0;
  std::vector<LiveMetaScore> objects;
};
LiveMetaResult EvaluateLiveMeta(const std::vector<LiveMetaObject>& truth, const PointCloud& live,
                                const PointCloud& meta, const EvalConfig& cfg, int threads = 0);
// Objects of the given classes (empty = every class) from DIR/truth/objects.csv, points from the
// `object` field of truth/<session>/static_world.ply, mapped into the estimate frame by `mapping`.
std::vector<LiveMetaObject> LoadSimLiveMetaTruth(const std::string& sim_dir, const std::vector<std::string>& classes,
                                                 const TruthMapping& mapping, int threads = 0);

// ----------------------------------------------------------------------------------- objects
// Changed objects of a session pair: truth = LD objects present in exactly one of the two
// sessions (points in the estimate frame), prediction = LT-map's clusters of that step.
struct ObjectTruth {
  std::string pair;       // "00_01"
  int id = -1;            // LD object id (truth/objects.csv)
  std::string cls, placement;
  int session = 0;        // sim session index where the object exists (its points come from there)
  PointCloud cloud;
  // Pairs whose clusters may hold the object (empty = {pair}). LT-map's step k stores the change
  // of the map state, so an object that session j (00 < j < k) already lacked (removal) or had
  // (addition) was applied at step j: clusters of those pairs (00, j) are eligible too.
  std::vector<std::string> match_pairs;
  // Truth change points of the object in truth/pair_*/changes.ply that the clustering can see
  // (PD strong / weak, ND strong); -1 when the file is absent. Objects with fewer than
  // obj_min_change_points (e.g. occluded: weak ND only, or never seen by the other session)
  // are not scored.
  long change_points = -1;
};
struct ObjectCluster {
  std::string pair;       // step's "<reference>_<session>", 2 digits each
  int id = -1;            // cluster id (objects.csv of `ltmapper map objects`)
  PointCloud cloud;
  // "appeared" (PD cluster) or "disappeared" (ND cluster), from objects.csv's class column;
  // "" when unknown (the cluster then counts in the per-pair rows only).
  std::string change;
};
// A cluster against the truth objects of its pair: it is a true object when some truth object
// eligible for its pair (ObjectTruth::match_pairs) reaches IoU >= obj_min_iou, else a false one.
struct ClusterScore {
  std::string pair, change;
  int id = -1;
  std::size_t points = 0;          // after voxelisation
  int best_truth = -1;             // truth object id with the highest IoU (-1: none overlaps)
  double best_iou = 0.0;
  bool true_object = false;
};
// Precision = true clusters / clusters, recall = found / scored truth objects, F1 their harmonic
// mean, for one slice (a pair, a change type or everything).
struct ObjectsPrf {
  std::string name;                // "00_01", "appeared", "disappeared", "all"
  std::size_t truth_objects = 0, found = 0, clusters = 0, true_clusters = 0;
  double precision = kNaN, recall = kNaN, f1 = kNaN;
};
struct ObjectScore {
  std::string pair;
  int id = -1;
  std::string cls, placement;
  int session = 0;
  std::size_t points = 0;          // truth points after voxelisation
  int best_cluster = -1;           // cluster with the highest IoU (-1: none overlaps)
  std::size_t cluster_points = 0;  // its points after voxelisation
  double best_iou = 0.0;
  long change_points = -1;         // see ObjectTruth
  bool scored = true;              // false: too few truth points or change points
  bool found = false;              // scored and best_iou >= obj_min_iou
};
struct ObjectsResult {
  double match_dist_m = 0.0, voxel_m = 0.0, min_iou = 0.0;
  std::size_t clusters = 0;        // clusters of the scored pairs
  std::size_t truth_objects = 0;   // scored truth objects
  std::size_t found = 0;
  double found_fraction = kNaN;
  std::vector<ObjectScore> objects;
  std::vector<ClusterScore> cluster_scores;  // clusters of the scored pairs
  ObjectsPrf all;                            // every scored pair and change type
  std::vector<ObjectsPrf> per_pair, per_change;
};
// Point IoU of two point sets after voxel-downsampling both to obj_voxel_m (same density, so
// counts are comparable): a point of A matches when B has a point within obj_match_dist_m and
// vice versa; inter = (matched A + matched B) / 2, IoU = inter / (|A| + |B| - inter). Equals the
// set IoU when the matched points pair up one to one. 0 when either set is empty.
double PointIoU(const PointCloud& a, const PointCloud& b, const EvalConfig& cfg);
// Every truth object against the clusters of its pair (boxes grown by the match distance must
// overlap); one cluster per object: the one with the highest IoU. Every cluster against the truth
// objects of its pair, the same way (ClusterScore), for precision / recall / F1 per pair and per
// change type (truth: appeared when the object exists in the pair's second session).
ObjectsResult EvaluateObjects(const std::vector<ObjectTruth>& truth, const std::vector<ObjectCluster>& clusters,
                              const EvalConfig& cfg, int threads = 0);
// truth/objects.csv rows (id, class, present_in, placement; sessions as sim indices).
struct SimObject {
  int id = -1;
  std::string cls, placement;
  std::vector<int> present_in;
};
std::vector<SimObject> ReadSimObjects(const std::string& objects_csv);
// Truth changed objects of pair "CC_QQ" (sim session indices): labelled scan points (class
// static, object = id) of the session where each object exists (removed objects: central, added:
// query), each scan placed by mapping.ScanPose, voxel-downsampled to obj_voxel_m.
std::vector<ObjectTruth> LoadSimObjectTruth(const std::string& sim_dir, const std::string& pair,
                                            const TruthMapping& mapping, const EvalConfig& cfg, int threads = 0);
// The clusters written by `ltmapper map objects` (objects.csv + objects.ply with object ids);
// pair = reference and session columns (store session orders, = sim indices when the sessions
// were integrated in sim order); change from the optional class column (pd_* appeared, nd_*
// disappeared).
std::vector<ObjectCluster> ReadObjectClusters(const std::string& objects_dir);

// ----------------------------------------------------------------------------------- storage
struct StorageItem {
  std::string path;
  std::uint64_t bytes = 0;      // apparent size: sum of regular files' sizes (recursively)
  std::size_t files = 0;
  double ratio_to_first = kNaN; // bytes / bytes of the first item
};
struct CostItem {
  std::string label;            // e.g. the report's path
  double wall_s = kNaN;         // [s]
  double peak_bytes = kNaN;     // [bytes]
};
struct StorageResult {
  std::vector<StorageItem> items;
  std::vector<CostItem> costs;
};
// Throws when `path` does not exist. Symlinks are not followed.
StorageItem MeasureStorage(const std::string& path);
StorageResult EvaluateStorage(const std::vector<std::string>& paths);
// Wall time and peak memory from a stage's report.json: the shallowest numeric field (then
// document order) named wall_time_s / wall_s / seconds_total / elapsed_s / time_s / seconds, and
// peak_rss_bytes / peak_memory_bytes / peak_bytes (bytes) or peak_rss_mb / peak_memory_mb /
// peak_mb (MiB). Absent fields stay NaN; malformed JSON is an error.
CostItem ReadCostReport(const std::string& report_json_path);

// ------------------------------------------------------------------------------------ report
struct Report {
  std::vector<std::pair<std::string, std::string>> inputs;  // what was scored (name, path)
  std::optional<TrajResult> traj;
  std::optional<HdResult> hd;
  std::optional<LdResult> ld;
  std::optional<RestoreResult> restore;
  std::optional<StorageResult> storage;
  std::optional<ObjectsResult> objects;
  std::optional<LiveMetaResult> livemeta;
};
std::string ToJson(const Report& report);
std::string ToMarkdown(const Report& report);
// Writes either or both (empty path = skip), atomically.
void WriteReport(const Report& report, const std::string& json_path, const std::string& md_path);
// The number at a dotted path ("hd.sa", "traj.sessions.0.ate.trans_m.rmse") of a JSON text;
// nullopt when absent or not a number (null). Malformed JSON throws ltm::Error.
std::optional<double> JsonNumber(const std::string& json_text, const std::string& dotted_path);

// ---------------------------------------------------------------------- stage file layouts
// (docs/FORMATS.md) Helpers the CLI uses to find inputs in a sim dir and stage outputs.

// KITTI (12 numbers per line) or TUM (8) pose file, detected from the first data line.
std::vector<Pose> ReadPoses(const std::string& path);
// Session names under DIR/truth (session_XX folders), sorted.
std::vector<std::string> SimSessionNames(const std::string& sim_dir);
// Truth poses DIR/truth/<s>/poses_world.txt with estimates from `est_dir/<s>/poses_world.txt`
// (an aligned/ dir) or, when est_dir is empty, the drifted session poses
// DIR/sessions/<s>/optimized_poses.txt. Sessions without an estimate are listed in *missing.
std::vector<SessionTrajectory> LoadSimTrajectories(const std::string& sim_dir,
                                                   const std::string& est_dir,
                                                   std::vector<std::string>* missing);
// DIR/truth/objects.csv -> id -> class (empty map when the file is absent).
std::map<int, std::string> ReadObjectClasses(const std::string& objects_csv);
// Paths of the labelled scans <session_truth_dir>/labels/*.ply in keyframe order; ltm::Error
// naming the folder when it is missing or holds other than `keyframes` scans.
std::vector<std::string> LabelledScanPaths(const std::string& session_truth_dir, std::size_t keyframes);
// One labelled scan (PLY with a per-point 'class' field, else ltm::Error naming the file).
PointCloud ReadLabelledScan(const std::string& path);
// Feeds a session's labelled scans (truth/<session>/labels/*.ply) placed with
// T_frame_sensor[k] (one per keyframe, keyframe order) into `ev`; returns scans used.
std::size_t AddSimSessionTruth(HdEvaluator& ev, const std::string& sim_dir,
                               const std::string& session, const std::vector<Pose>& T_frame_sensor,
                               const EvalConfig& cfg);
// Transform taking the sim's true world frame into the estimated world frame: the inverse of
// the joint ATE alignment when `aligned_dir` is given, else the inverse of the central
// session's true origin (world = central session frame, as LT-SLAM defines it).
Pose TruthToEstimateFrame(const std::string& sim_dir, const std::string& aligned_dir);
// The four change clouds {pd_strong,pd_weak,nd_strong,nd_weak}.pcd of a pair folder.
ChangeClouds ReadChangeClouds(const std::string& dir);
ChangeClouds TransformChanges(const ChangeClouds& c, const Pose& T);
// `root/pair_<pair>`; pair "00_01" also finds pair_session_00_session_01 and any pair_*
// folder whose two trailing numbers are 00 and 01. Throws listing what exists when none.
std::string FindPairDir(const std::string& root, const std::string& pair);

}  // namespace ltm::eval
