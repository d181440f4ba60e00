// The inputs of `ltmapper eval ld` found from its folders, and their scores (ld_case.hpp).
#include "ltmapper/eval/ld_case.hpp"
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace ltm::eval {
namespace {

std::string Join(const std::string& a, const std::string& b) { return (std::filesystem::path(a) / b).string(); }

// The pair's truth in the estimate frame: its change sets (true world, PD from the query's static
// world, ND from the central's: the pair's clouds, and their changed objects' part when the truth
// names it) and what each session sampled of its surfaces (its static world). From the scans,
// each session's labelled scans are read once for all of them.
struct PlacedTruth {
  std::vector<ChangeClouds> sets;
  PointCloud central_surfaces, query_surfaces;
};
PlacedTruth SimTruth(const std::string& sim, const std::vector<const ChangeClouds*>& sets, std::size_t c,
                     std::size_t q, const TruthMapping& m, bool from_scans, const EvalConfig& cfg, int threads) {
  PlacedTruth out;
  if (!from_scans) {
    for (const ChangeClouds* w : sets)
      out.sets.push_back({m.Map(w->pd_strong, q, threads), m.Map(w->pd_weak, q, threads),
                          m.Map(w->nd_strong, c, threads), m.Map(w->nd_weak, c, threads)});
    out.central_surfaces = m.Map(io::ReadCloud(StaticWorldFile(sim, c)), c, threads);
    out.query_surfaces = m.Map(io::ReadCloud(StaticWorldFile(sim, q)), q, threads);
    return out;
  }
  std::vector<const PointCloud*> pd_in, nd_in;
  for (const ChangeClouds* w : sets) {
    pd_in.insert(pd_in.end(), {&w->pd_strong, &w->pd_weak});
    nd_in.insert(nd_in.end(), {&w->nd_strong, &w->nd_weak});
  }
  constexpr bool kSampledSurfaces = true;  // one more cloud after the sets: what the session sampled
  auto pd = ChangesFromLabelledScans(sim, q, pd_in, m, cfg.ld_match_dist_m, threads, kSampledSurfaces);
  auto nd = ChangesFromLabelledScans(sim, c, nd_in, m, cfg.ld_match_dist_m, threads, kSampledSurfaces);
  for (std::size_t k = 0; k < sets.size(); ++k)
    out.sets.push_back(
        {std::move(pd[2 * k]), std::move(pd[2 * k + 1]), std::move(nd[2 * k]), std::move(nd[2 * k + 1])});
  out.query_surfaces = std::move(pd.back());
  out.central_surfaces = std::move(nd.back());
  return out;
}

}  // namespace

ChangeClouds SeparableTruth(const ChangeClouds& truth, const PointCloud& central_surfaces,
                            const PointCloud& query_surfaces, const EvalConfig& cfg, int threads) {
  const auto apart = [&](const PointCloud& c, const PointCloud& other) {
    std::vector<bool> keep = geometry::WithinRadius(c, other, cfg.ld_match_dist_m, threads);
    keep.flip();
    return c.select(keep);
  };
  return {apart(truth.pd_strong, central_surfaces), apart(truth.pd_weak, central_surfaces),
          apart(truth.nd_strong, query_surfaces), apart(truth.nd_weak, query_surfaces)};
}

LdCase LoadLdCase(const std::string& truth_dir, const std::string& pred_dir, const std::string& truth_transform) {
  LdCase out;
  out.inputs = {{"truth", truth_dir}, {"prediction", pred_dir}};
  out.truth = ReadChangeClouds(truth_dir);
  out.truth_objects = ReadObjectChangeClouds(truth_dir);
  if (!truth_transform.empty()) {
    const Pose T = io::ReadTransform(truth_transform);
    out.truth = TransformChanges(out.truth, T);
    if (out.truth_objects) out.truth_objects = TransformChanges(*out.truth_objects, T);
  }
  out.pred = ReadChangeClouds(pred_dir);
  return out;
}

LdCase LoadSimLdCase(const std::string& sim, const std::string& changes, const std::string& truth_dir,
                     const std::string& pred_dir, int central, int query, const TruthMapping& mapping,
                     bool from_scans, bool find_central_static, const EvalConfig& cfg, int threads) {
  const std::size_t c = std::size_t(central), q = std::size_t(query);
  LdCase out;
  out.inputs = {{"truth", truth_dir}, {"prediction", pred_dir}, {"truth mapping", mapping.description}};
  // Where each session's sensor was, in the output frame (LD distance bands).
  out.trajectories = LdTrajectories{SensorPositions(sim, c, mapping), SensorPositions(sim, q, mapping)};
  const ChangeClouds changes_world = ReadChangeClouds(truth_dir);
  const std::optional<ChangeClouds> objects_world = ReadObjectChangeClouds(truth_dir);
  std::vector<const ChangeClouds*> sets = {&changes_world};
  if (objects_world) sets.push_back(&*objects_world);
  PlacedTruth placed = SimTruth(sim, sets, c, q, mapping, from_scans, cfg, threads);
  out.truth = std::move(placed.sets[0]);
  if (objects_world) out.truth_objects = std::move(placed.sets[1]);
  out.truth_separable = SeparableTruth(out.truth, placed.central_surfaces, placed.query_surfaces, cfg, threads);
  if (from_scans)
    out.inputs.push_back({"truth built from", fmt::format("labelled scans placed with the method's poses, voxel {} m",
                                                          cfg.ld_match_dist_m)});
  out.pred = ReadChangeClouds(pred_dir);
  if (find_central_static) {
    // The central session is the pair's first number, indexing the sim's sessions.
    const auto names = SimSessionNames(sim);
    if (c < names.size()) {
      const std::string f = io::layout::StaticMapFile(changes, names[c]);
      if (std::filesystem::exists(f)) out.central_static = f;
      else spdlog::warn("{} not found: weak-ND preservation not scored", f);
    }
  }
  return out;
}

LdResult ScoreLdCase(const LdCase& c, const std::string& kept_map, const std::string& central_static,
                     const std::string& errors_dir, const EvalConfig& cfg, int threads,
                     std::vector<std::pair<std::string, std::string>>* inputs) {
  std::optional<PointCloud> kept;
  if (!kept_map.empty()) {
    kept = io::ReadCloud(kept_map);
    inputs->push_back({"kept map", kept_map});
  } else if (!central_static.empty()) {
    kept = KeptMapFromChanges(io::ReadCloud(central_static), c.pred.nd_strong, cfg, threads);
    inputs->push_back({"kept map", central_static + " minus predicted strong ND"});
  }
  const LdResult r = EvaluateLd(c.truth, c.pred, kept ? &*kept : nullptr, cfg, threads,
                                c.trajectories ? &*c.trajectories : nullptr,
                                c.truth_objects ? &*c.truth_objects : nullptr,
                                c.truth_separable ? &*c.truth_separable : nullptr);
  if (!errors_dir.empty()) {
    const LdErrors e = LdErrorClouds(c.truth, c.pred, cfg, threads);
    io::MakeDirs(errors_dir);
    io::WritePly(Join(errors_dir, "false_positives.ply"), e.false_positives);
    io::WritePly(Join(errors_dir, "false_negatives.ply"), e.false_negatives);
    inputs->push_back({"error clouds", errors_dir});
  }
  return r;
}

TruthMapping ResolveTruthMapping(const std::string& sim, const std::string& aligned, const std::string& frame,
                                 const std::string& mapping) {
  TruthMapping m;
  if (!aligned.empty() && mapping == "keyframe") m = KeyframeTruthMapping(sim, aligned);
  else if (!aligned.empty()) m = GlobalTruthMapping(TruthToEstimateFrame(sim, aligned), "global: joint ATE alignment (" + aligned + ")");
  else if (frame == "world") m = GlobalTruthMapping(Pose::Identity(), "none: the output is in the sim's true world frame");
  else m = GlobalTruthMapping(TruthToEstimateFrame(sim, ""), "global: inverse of the central session's true origin");
  spdlog::info("truth mapping: {}", m.description);
  return m;
}

}  // namespace ltm::eval
