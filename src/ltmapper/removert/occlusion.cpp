// Occlusion-aware split of LD changes (paper: "Weak ND Preservation", "Strong PD").
//
// The paper's modified Removert: instead of removing map points that a scan sees through, it
// keeps (reverts to the static map) the raw ND points that the other session could not see
// through. Here one rule serves both directions: a point is "seen through" by a set of keyframes
// when, at any of the LD resolutions, at least ld_min_votes keyframes see through it and those
// are at least ld_min_ratio of the keyframes with evidence about it. Out of range, out of the
// FOV, occluded (scan range shorter) and no-return pixels give no see-through vote.
//   ND seen through by the query  -> strong ND (removed);  else weak ND (kept).
//   PD seen through by the central -> weak PD (was free);  else strong PD.
#include "ltmapper/removert/detail.hpp"

namespace ltm::removert::detail {

std::vector<bool> SeenThroughBy(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                                const RemovertConfig& cfg, int threads) {
  std::vector<bool> out(points.size(), false);
  if (points.empty() || keyframes.empty()) return out;
  const VisibilityVotes v = CountVisibility(points, keyframes, cfg.ld_resolutions_deg, cfg, threads);
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int l = 0; l < v.levels && !out[i]; ++l) {
      const double s = v.See(l, i), h = v.Hit(l, i);
      out[i] = s >= cfg.ld_min_votes && s >= cfg.ld_min_ratio * (s + h);
    }
  }
  return out;
}

}  // namespace ltm::removert::detail
