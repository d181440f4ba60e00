// ltmapper eval: changed objects (LT-map's clusters against the simulator's LD objects).
#pragma once

#include "ltmapper/eval/truth_mapping.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

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
  // Share of all its change points in changes.ply (PD and ND of both strengths) that the other
  // session observed changed: PD in space the reference saw free (weak PD), ND the later session
  // saw through (strong ND). Under objects.min_observed_share (half), most of the change lies in
  // space one of the sessions never observed (a structure revealed behind a removed wall, a car
  // that left behind a hoarding): by the rule a coverage difference, not an object. NaN
  // without the file.
  double observed_share = kNaN;
  // A move's other end (truth/objects.csv's partner): the id of the same object at its other place
  // when that place is a changed object of this pair on the other side (a container gone from
  // one lot and new at another), else -1.
  int partner = -1;
};
struct ObjectCluster {
  std::string pair;       // step's "<reference>_<session>", 2 digits each
  int id = -1;            // cluster id (objects.csv of `ltmapper map objects`)
  PointCloud cloud;
  // "appeared" (PD cluster) or "disappeared" (ND cluster), from objects.csv's class column;
  // "" when unknown (the cluster then counts in the per-pair rows only).
  std::string change;
  bool moved = false;  // objects.csv's change column says "moved"
  int partner = -1;    // moved: the other end's cluster id (objects.csv's partner column)
  int track = -1;      // identity across steps (objects.csv's track column), -1 when absent
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
  bool moved = false;              // see ObjectCluster
  int partner = -1;
  int track = -1;
};
// Moves (ObjectTruth::partner) of one slice: the "moved objects reported as moved". A
// truth move (both ends scored) is found when both its ends are found (ObjectScore::found) by
// clusters reported as moved, and linked when those two clusters name each other as partners, or a
// row of each other's track (a later step's view of a move's end inherits the first view's partner;
// two identical containers that both moved may be paired the other way round). A cluster reported as
// moved is true when it is a true object whose best truth object is an end of a move. Precision =
// true reported / reported, recall = found / truth moves; NaN without any.
struct MovedPrf {
  std::string name;                // "all", "00_01", ...
  std::size_t truth_moves = 0, found = 0, linked = 0, reported = 0, true_reported = 0;
  double precision = kNaN, recall = kNaN;
};
// Identity across steps (the "the same object seen in several sessions keeps one id"),
// over pairs of true clusters of different steps: `same` find one truth object, `same_tracked` of
// those share a track; `tracked` share a track, `tracked_wrong` of those find two truth objects
// that are not one move's two ends.
struct IdentityScore {
  std::size_t same = 0, same_tracked = 0, tracked = 0, tracked_wrong = 0;
};
// Precision = true clusters / clusters, recall = found / scored truth objects, F1 their harmonic
// mean, for one slice (a pair, a change type or everything).
struct ObjectsPrf {
  std::string name;                // "00_01", "appeared", "disappeared", "class car", "all"
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
  double observed_share = kNaN;    // see ObjectTruth
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
  ObjectsPrf observable;                     // all clusters; the scored truth objects with observed_share >=
                                             // objects.min_observed_share
  std::vector<ObjectsPrf> per_pair, per_change;
  std::vector<ObjectsPrf> observable_per_pair;  // "00_01 observable": the pair's observable truth objects, its clusters
  std::vector<ObjectsPrf> per_class;         // "class car", ...: truth objects of the class, clusters overlapping them most
  std::vector<MovedPrf> moved;               // "all", then one per pair
  IdentityScore identity;
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
  int partner = -1;  // the optional partner column: the same object at its other place, else -1
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
// disappeared); moved, partner and track from the optional change, partner and track columns.
std::vector<ObjectCluster> ReadObjectClusters(const std::string& objects_dir);

}  // namespace ltm::eval
