// ltmapper eval: LD change scores (precision / recall / F1 of PD and ND, distance bands,
// error clouds, the kept map).
#pragma once

#include "ltmapper/eval/config.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

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
  // Recall over the truth points of changed objects alone (where the truth names them:
  // objects_*.pcd beside its clouds), matched against every predicted PD (ND) point; the rest of
  // the truth is coverage (surfaces both sessions have that one of them never observed).
  bool objects_given = false;
  PrfStats pd_objects, nd_objects;  // truth, truth_matched, recall (nothing predicted: precision NaN)
  // Recall over the separable truth points alone (where given: the sim form, SeparableTruth): those
  // farther than the match distance from every surface the other session sampled. Nearer, a change
  // cannot be told from that surface at the match distance (a new hoarding's foot on the ground the
  // central saw), as HD's "hd near static".
  bool separable_given = false;
  PrfStats pd_separable, nd_separable;
};
// Keyframe positions of the pair's sessions, in the frame of the change clouds (for LdBand).
struct LdTrajectories {
  PointCloud central, query;
};
// Truth and prediction in the same frame. `kept_map` (may be null) is the map the method keeps
// after the update (static / live map): weak-ND truth points within d of it count as kept.
// With `trajectories` (may be null) the result holds the distance bands of cfg.ld_bands_m
// (strictly increasing, else ltm::Error). With `truth_objects` (may be null: the truth's points
// of changed objects, a subset of `truth`) the result holds pd_objects / nd_objects; likewise
// `truth_separable` (may be null: its separable points) and pd_separable / nd_separable.
LdResult EvaluateLd(const ChangeClouds& truth, const ChangeClouds& predicted,
                    const PointCloud* kept_map, const EvalConfig& cfg, int threads = 0,
                    const LdTrajectories* trajectories = nullptr, const ChangeClouds* truth_objects = nullptr,
                    const ChangeClouds* truth_separable = nullptr);
// Where the LD prediction is wrong, pooled per kind (PD vs PD, ND vs ND) at ld_match_dist_m:
// predicted points with no truth point of their kind within d (false positives) and truth
// points with no predicted point within d (false negatives). `cls` keeps each point's own class
// (kPDStrong ... kNDWeak), so a PLY of either shows which output or truth cloud it came from.
struct LdErrors {
  PointCloud false_positives, false_negatives;
};
LdErrors LdErrorClouds(const ChangeClouds& truth, const ChangeClouds& predicted, const EvalConfig& cfg,
                       int threads = 0);
// `cloud` minus its points that have a point of `taken` within ld_same_point_m (`taken` holds
// copies of some of its points: strong ND, residues of movers).
PointCloud WithoutPoints(const PointCloud& cloud, const PointCloud& taken, const EvalConfig& cfg, int threads = 0);
// Kept map derived from a removert output: the central static map minus the predicted strong ND
// (WithoutPoints: strong ND is removed, weak ND kept).
PointCloud KeptMapFromChanges(const PointCloud& central_static, const PointCloud& nd_strong,
                              const EvalConfig& cfg, int threads = 0);

}  // namespace ltm::eval
