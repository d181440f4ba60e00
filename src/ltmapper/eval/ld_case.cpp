// The inputs of `ltmapper eval ld` found from its folders, and their scores (ld_case.hpp).
#include "ltmapper/eval/ld_case.hpp"
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace ltm::eval {
namespace {

std::string Join(const std::string& a, const std::string& b) { return (std::filesystem::path(a) / b).string(); }

// The pair's truth clouds `w` (true world, PD from the query's static world, ND from the
// central's) in the estimate frame.
ChangeClouds SimTruth(const std::string& sim, const ChangeClouds& w, std::size_t c, std::size_t q,
                      const TruthMapping& m, bool from_scans, const EvalConfig& cfg, int threads) {
  if (!from_scans)
    return {m.Map(w.pd_strong, q, threads), m.Map(w.pd_weak, q, threads), m.Map(w.nd_strong, c, threads),
            m.Map(w.nd_weak, c, threads)};
  const double v = cfg.ld_match_dist_m;
  auto pd = ChangesFromLabelledScans(sim, q, {&w.pd_strong, &w.pd_weak}, m, v, threads);
  auto nd = ChangesFromLabelledScans(sim, c, {&w.nd_strong, &w.nd_weak}, m, v, threads);
  return {std::move(pd[0]), std::move(pd[1]), std::move(nd[0]), std::move(nd[1])};
}

}  // namespace

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
  out.truth = SimTruth(sim, ReadChangeClouds(truth_dir), c, q, mapping, from_scans, cfg, threads);
  if (from_scans)
    out.inputs.push_back({"truth built from", fmt::format("labelled scans placed with the method's poses, voxel {} m",
                                                          cfg.ld_match_dist_m)});
  if (const auto objects = ReadObjectChangeClouds(truth_dir))
    out.truth_objects = SimTruth(sim, *objects, c, q, mapping, from_scans, cfg, threads);
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
                                c.truth_objects ? &*c.truth_objects : nullptr);
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
