// ltmapper eval: live / meta map content (new and removed objects in each map).
#pragma once

#include "ltmapper/eval/truth_mapping.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

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

}  // namespace ltm::eval
