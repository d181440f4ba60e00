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
// With ld.covisible_only, a raw change the other session never had in view at all (no return
// in the window at its pixel from any keyframe in range: out of range, out of FOV) is
// "unobserved": a coverage difference, not a change. Unobserved ND stays static; unobserved PD
// is new territory (written apart, and added to the keyframe clouds as strong PD).
#include "ltmapper/removert/detail.hpp"

namespace ltm::removert::detail {

Visibility SeenThroughBy(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads) {
  Visibility out;
  out.seen.assign(points.size(), false);
  out.observed.assign(points.size(), false);
  if (points.empty() || keyframes.empty()) return out;
  const VisibilityVotes v =
      CountVisibility(points, keyframes, cfg.ld_resolutions_deg, cfg, threads, true);
  for (std::size_t i = 0; i < points.size(); ++i) {
    bool seen = false, observed = false;
    for (int l = 0; l < v.levels; ++l) {
      const double s = v.See(l, i), h = v.Hit(l, i);
      seen = seen || (s >= cfg.ld_min_votes && s >= cfg.ld_min_ratio * (s + h));
      observed = observed || s + h + v.occ[std::size_t(l) * v.points + i] > 0;
    }
    out.seen[i] = seen;
    out.observed[i] = observed;
  }
  return out;
}

}  // namespace ltm::removert::detail
