// ltmapper eval: EvalConfig (params_eval.yaml) and kNaN, the value of every undefined ratio.
#pragma once

#include "ltmapper/core/core.hpp"

#include <limits>
#include <string>
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
  double obj_min_observed_share = 0.5;     // "observable" objects: at least this share of their change
                                           // points observed changed by the other session (weak PD, strong ND)
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
    v("objects.min_observed_share", obj_min_observed_share, "", 0.0, 1.0);
    v("livemeta.min_fraction", livemeta_min_fraction, "", 0.0, 1.0);
  }
  // Range checks plus the cross-field rules (ld.bands_m strictly increasing); ltm::Error naming `where`.
  void Validate(const std::string& where = "eval config") const;
};

}  // namespace ltm::eval
