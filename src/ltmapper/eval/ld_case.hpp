// ltmapper eval: the inputs of an LD evaluation found from the command line's folders (what
// `ltmapper eval ld` scores): explicit truth / prediction folders, or the simulator's truth of a
// session pair placed in the method's world and LT-removert's pair folder (docs/FORMATS.md).
#pragma once

#include "ltmapper/eval/ld.hpp"
#include "ltmapper/eval/truth_mapping.hpp"

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ltm::eval {

// Truth and prediction in one frame, with what else the LD scores use.
struct LdCase {
  std::vector<std::pair<std::string, std::string>> inputs;  // what was scored (name, path), for the report
  ChangeClouds truth, pred;
  std::optional<ChangeClouds> truth_objects;   // the truth's points of changed objects, when it names them
  std::optional<ChangeClouds> truth_separable; // sim form: its points apart from the other session's surfaces
  std::optional<LdTrajectories> trajectories;  // sim form: keyframe positions of the pair (LD bands)
  std::string central_static;                  // sim form: changes/<central>/static_map.pcd, when present
};

// The truth's separable points (LdResult::pd_separable): PD farther than ld_match_dist_m from every
// point of `central_surfaces` (what the central sampled, in the truth's frame), ND from every
// point of `query_surfaces`.
ChangeClouds SeparableTruth(const ChangeClouds& truth, const PointCloud& central_surfaces,
                            const PointCloud& query_surfaces, const EvalConfig& cfg, int threads = 0);

// Explicit form: {pd,nd}_{strong,weak}.pcd of both folders (and the truth's objects_*.pcd when
// all four are there); `truth_transform` (a 3x4 / 4x4 file, may be empty) is applied to the truth.
LdCase LoadLdCase(const std::string& truth_dir, const std::string& pred_dir, const std::string& truth_transform);

// Sim form, pair `central`_`query` (sim session indices; truth_dir / pred_dir: FindPairDir of the
// sim's truth/ and of `changes`): the truth change clouds moved by `mapping` (PD by the query's
// keyframes, ND by the central's) or, with `from_scans`, rebuilt from the labelled scans placed
// with the method's poses (ChangesFromLabelledScans at ld_match_dist_m), and so the truth's points
// of changed objects (objects_*.pcd) when the pair folder has them, and its separable points
// (LdResult::pd_separable, from the sessions' static worlds placed alike); the sessions' sensor
// positions for the LD bands. With `find_central_static`, central_static is the central's HD-free
// map under `changes` when it exists (else a warning: weak-ND preservation is not scored).
LdCase LoadSimLdCase(const std::string& sim, const std::string& changes, const std::string& truth_dir,
                     const std::string& pred_dir, int central, int query, const TruthMapping& mapping,
                     bool from_scans, bool find_central_static, const EvalConfig& cfg, int threads = 0);

// The LD scores of a case. The kept map is `kept_map` (a cloud file) when given, else
// `central_static` minus the predicted strong ND (KeptMapFromChanges) when given, else none.
// With `errors_dir`, LdErrorClouds go to errors_dir/false_positives.ply and false_negatives.ply.
// Every file used is added to `inputs`.
LdResult ScoreLdCase(const LdCase& c, const std::string& kept_map, const std::string& central_static,
                     const std::string& errors_dir, const EvalConfig& cfg, int threads,
                     std::vector<std::pair<std::string, std::string>>* inputs);

// How the sim's truth is placed in the method's world for a stage output: with `aligned`, per
// keyframe (mapping "keyframe") or by the joint ATE alignment ("global"); without, the output is
// in the sim's true world (frame "world") or in the central session's frame ("central"). Logs it.
TruthMapping ResolveTruthMapping(const std::string& sim, const std::string& aligned, const std::string& frame,
                                 const std::string& mapping);

}  // namespace ltm::eval
