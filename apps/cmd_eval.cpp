// `ltmapper eval traj|hd|ld|restore|storage|objects|livemeta`: score a stage's output against ground truth.
// Each subcommand takes explicit files, or the simulator dir plus a stage output dir and finds
// the files by the layouts of docs/FORMATS.md. Prints the Markdown report; --json / --md write
// it to files (atomically).
#include "command.hpp"

#include "ltmapper/eval/eval.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

namespace fs = std::filesystem;

namespace ltm::app {
namespace {

struct EvalOptions {
  CommonOptions common;
  std::string config;
  std::vector<std::string> set;  // key=value overrides
  std::string json, md;
};

void AddEvalOptions(CLI::App& cmd, EvalOptions& o) {
  AddCommonOptions(cmd, o.common);
  cmd.add_option("--config", o.config, "params_eval.yaml (every key optional)");
  cmd.add_option("--set", o.set, "Override a config key, e.g. --set hd.match_dist_m=0.2 (repeatable)");
  cmd.add_option("--json", o.json, "Write the report as JSON to this file");
  cmd.add_option("--md", o.md, "Write the report as Markdown to this file");
}

eval::EvalConfig LoadEvalConfig(const EvalOptions& o) {
  if (o.common.quiet) spdlog::set_level(spdlog::level::warn);
  auto cfg = LoadParams<eval::EvalConfig>(o.config, o.set);
  cfg.Validate(o.config.empty() ? "eval config" : o.config);
  spdlog::info("eval config{}:\n{}", o.config.empty() ? " (defaults)" : " " + o.config, ConfigToString(cfg));
  return cfg;
}

void Finish(const eval::Report& report, const EvalOptions& o) {
  eval::WriteReport(report, o.json, o.md);
  std::cout << eval::ToMarkdown(report) << std::flush;
  if (!o.json.empty()) spdlog::info("wrote {}", o.json);
  if (!o.md.empty()) spdlog::info("wrote {}", o.md);
}

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

void Usage(const std::string& what) { throw CLI::ValidationError(what); }

// Where the stage output lives relative to the sim's true world: "central" (LT-SLAM's world =
// the central session's frame; with --aligned, by the joint ATE alignment) or "world" (the stage
// was run on the sim's true world poses, e.g. `removert --poses truth/*/poses_world.txt`).
void AddTruthFrame(CLI::App& cmd, std::string& frame) {
  cmd.add_option("--truth-frame", frame,
                 "Frame of the stage output: central (LT-SLAM world, default) or world (run on true world poses)")
      ->check(CLI::IsMember({"central", "world"}));
}
Pose TruthFrame(const std::string& sim, const std::string& aligned, const std::string& frame) {
  if (!aligned.empty()) return eval::TruthToEstimateFrame(sim, aligned);
  return frame == "world" ? Pose::Identity() : eval::TruthToEstimateFrame(sim, "");
}

// With --aligned, how the truth is placed in the estimated world: per keyframe (default) or by
// one rigid transform (joint ATE alignment).
void AddTruthMapping(CLI::App& cmd, std::string& mapping) {
  cmd.add_option("--truth-mapping", mapping,
                 "With --aligned: keyframe (default; each truth point moves by the pose correction of the nearest true "
                 "keyframe of the session that observed it) or global (one rigid transform, the joint ATE alignment)")
      ->check(CLI::IsMember({"keyframe", "global"}));
}
// Sim session index of a name ("session_02" -> its position among truth/session_XX).
std::size_t SessionIndex(const std::string& sim, const std::string& name) {
  const auto names = eval::SimSessionNames(sim);
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) throw Error(Join(sim, "truth"), 0, "no session '" + name + "'");
  return std::size_t(it - names.begin());
}

// ------------------------------------------------------------------------------------ traj
void SetupTraj(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::vector<std::string> truth, est, names;
    std::string sim, aligned;
    bool drifted = false;
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("traj", "ATE / RPE / inter-session consistency of world poses");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--truth-poses", o->truth, "True pose files (KITTI or TUM), one per session, central first");
  cmd->add_option("--est-poses", o->est, "Estimated pose files, same order and keyframes");
  cmd->add_option("--names", o->names, "Session names for the explicit files (default: parent folder names)");
  cmd->add_option("--sim", o->sim, "Simulator output dir (truth/<session>/poses_world.txt)");
  cmd->add_option("--aligned", o->aligned, "LT-SLAM output dir (<session>/poses_world.txt)");
  cmd->add_flag("--drifted", o->drifted, "With --sim: score the drifted input odometry (sessions/*/optimized_poses.txt)");
  cmd->callback([o] {
    const bool sim_form = !o->sim.empty();
    if (sim_form == (!o->truth.empty() || !o->est.empty()))
      Usage("eval traj: give --sim DIR with --aligned DIR or --drifted, or --truth-poses F... --est-poses F...");
    if (sim_form && (o->aligned.empty() == !o->drifted))
      Usage("eval traj: with --sim give exactly one of --aligned DIR and --drifted");
    if (!sim_form && o->truth.size() != o->est.size())
      Usage("eval traj: --truth-poses and --est-poses need the same number of files");
    if (!o->names.empty() && o->names.size() != o->truth.size())
      Usage("eval traj: --names needs one name per pose file");
    const auto cfg = LoadEvalConfig(*o);
    eval::Report report;
    std::vector<eval::SessionTrajectory> sessions;
    std::vector<std::string> missing;
    if (sim_form) {
      report.inputs = {{"sim", o->sim}, {"estimate", o->drifted ? "drifted session odometry" : o->aligned}};
      sessions = eval::LoadSimTrajectories(o->sim, o->drifted ? std::string() : o->aligned, &missing);
      for (const auto& m : missing) spdlog::warn("session {}: no estimated poses, not scored", m);
    } else {
      for (std::size_t i = 0; i < o->truth.size(); ++i) {
        eval::SessionTrajectory s;
        s.name = !o->names.empty() ? o->names[i] : fs::path(o->est[i]).parent_path().filename().string();
        if (s.name.empty()) s.name = "session_" + std::to_string(i);
        s.truth = eval::ReadPoses(o->truth[i]);
        s.est = eval::ReadPoses(o->est[i]);
        report.inputs.push_back({s.name + " truth", o->truth[i]});
        report.inputs.push_back({s.name + " estimate", o->est[i]});
        sessions.push_back(std::move(s));
      }
    }
    report.traj = eval::EvaluateTrajectories(sessions, cfg);
    report.traj->missing = missing;
    Finish(report, *o);
  });
}

// -------------------------------------------------------------------------------------- hd
void SetupHd(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::string truth_map, output, objects, sim, changes, session, aligned, poses;
    std::string truth_frame = "central";
    bool single_session = false;
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("hd", "HD removal: point-wise SA / DA / AA (KTH DynamicMap rule)");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--truth-map", o->truth_map, "Labelled raw map (PLY with 'class', 'object'), frame of the output");
  cmd->add_option("--output", o->output, "The method's HD-free map (PCD/PLY); default with --changes: <changes>/<session>/static_map.pcd "
                  "minus the residues of movers its pairs found (multi-session cleanup)");
  cmd->add_flag("--single-session", o->single_session, "With --changes: score <changes>/<session>/static_map.pcd as it is "
                "(the session's own HD removal, before the multi-session cleanup)");
  cmd->add_option("--objects", o->objects, "objects.csv for per-class rows (default with --sim: truth/objects.csv)");
  cmd->add_option("--sim", o->sim, "Simulator output dir: the raw map is built from truth/<session>/labels");
  cmd->add_option("--changes", o->changes, "LT-removert output dir");
  cmd->add_option("--session", o->session, "Session name (e.g. session_01)");
  cmd->add_option("--aligned", o->aligned, "Place the labelled scans with <aligned>/<session>/poses_world.txt (the poses the method used)");
  cmd->add_option("--poses", o->poses, "Place the labelled scans with this pose file (KITTI/TUM) instead");
  AddTruthFrame(*cmd, o->truth_frame);
  cmd->callback([o] {
    const bool sim_form = !o->sim.empty();
    if (sim_form == !o->truth_map.empty())
      Usage("eval hd: give --truth-map F --output F, or --sim DIR --session NAME with --changes DIR or --output F");
    if (!sim_form && o->output.empty()) Usage("eval hd: --output is required");
    if (sim_form && o->session.empty()) Usage("eval hd: --session is required with --sim");
    if (sim_form && o->output.empty() && o->changes.empty()) Usage("eval hd: give --changes DIR or --output F");
    if (!o->aligned.empty() && !o->poses.empty()) Usage("eval hd: give at most one of --aligned and --poses");
    if (o->single_session && (o->changes.empty() || !o->output.empty()))
      Usage("eval hd: --single-session goes with --changes DIR, without --output");
    const auto cfg = LoadEvalConfig(*o);
    std::string output = o->output;
    PointCloud out;
    if (!output.empty())
      out = io::ReadCloud(output);
    else if (o->single_session)
      out = io::ReadCloud(output = io::layout::StaticMapFile(o->changes, o->session));
    else
      out = eval::CleanedSessionMap(o->changes, o->session, cfg, o->common.threads, &output);
    const std::string objects = !o->objects.empty() ? o->objects : sim_form ? Join(Join(o->sim, "truth"), "objects.csv") : "";
    if (!o->objects.empty() && !fs::exists(o->objects)) throw Error(o->objects, 0, "no such file");
    eval::Report report;
    report.inputs.push_back({"output", output});
    spdlog::info("output map: {} points", out.size());
    eval::HdEvaluator ev(std::move(out), cfg, objects.empty() ? std::map<int, std::string>{} : eval::ReadObjectClasses(objects),
                         o->common.threads);
    if (!sim_form) {
      report.inputs.push_back({"truth map", o->truth_map});
      ev.Add(io::ReadPly(o->truth_map));
    } else {
      std::vector<Pose> poses;
      if (!o->aligned.empty() || !o->poses.empty()) {
        const std::string f = !o->poses.empty() ? o->poses : io::layout::PosesWorldFile(o->aligned, o->session);
        poses = eval::ReadPoses(f);
        report.inputs.push_back({"scan poses", f});
      } else {
        // True poses in the output's frame.
        const Pose T = TruthFrame(o->sim, "", o->truth_frame);
        for (const auto& p : eval::ReadPoses(Join(Join(Join(o->sim, "truth"), o->session), "poses_world.txt")))
          poses.push_back(T * p);
        report.inputs.push_back({"scan poses", "true poses, " + o->truth_frame + " frame"});
      }
      report.inputs.push_back({"truth", Join(Join(Join(o->sim, "truth"), o->session), "labels")});
      const std::size_t used = eval::AddSimSessionTruth(ev, o->sim, o->session, poses, cfg);
      spdlog::info("scored {} labelled scans", used);
    }
    report.hd = ev.Result();
    Finish(report, *o);
  });
}

// -------------------------------------------------------------------------------------- ld
void SetupLd(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::string truth_dir, pred_dir, kept_map, central_static, truth_transform;
    std::string sim, changes, pair, aligned;
    std::string truth_frame = "central", truth_mapping = "keyframe";
    std::string errors;
    bool from_scans = false, exact_ray = false;
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("ld", "LD changes: precision / recall / F1 of PD and ND, strong and weak");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--truth-dir", o->truth_dir, "Folder with truth {pd_strong,pd_weak,nd_strong,nd_weak}.pcd");
  cmd->add_option("--pred-dir", o->pred_dir, "Folder with predicted {pd_strong,pd_weak,nd_strong,nd_weak}.pcd");
  cmd->add_option("--truth-transform", o->truth_transform, "3x4/4x4 transform applied to the truth clouds");
  cmd->add_option("--kept-map", o->kept_map, "Map kept after the update (static / live map) for the weak-ND check");
  cmd->add_option("--central-static", o->central_static,
                  "Central HD-free map; kept map = it minus predicted strong ND (when no --kept-map)");
  cmd->add_option("--sim", o->sim, "Simulator output dir (truth/pair_00_XX)");
  cmd->add_option("--changes", o->changes, "LT-removert output dir (pair folder, <central>/static_map.pcd)");
  cmd->add_option("--pair", o->pair, "Session pair, e.g. 00_01");
  cmd->add_option("--aligned", o->aligned, "LT-SLAM output: map the truth into the estimated world (see --truth-mapping)");
  cmd->add_flag("--truth-from-scans", o->from_scans,
                "With --sim: rebuild the truth from the labelled scans placed with the method's poses "
                "(its maps' own blur far from the trajectory) instead of moving the truth clouds");
  cmd->add_flag("--exact-ray", o->exact_ray,
                "With --sim: score against the second truth (strong / weak by a ray cast straight at each "
                "point, truth/pair_*/exact_ray) instead of the beam truth (the scans' own rays)");
  cmd->add_option("--errors", o->errors,
                  "Write DIR/false_positives.ply and DIR/false_negatives.ply (class field: which PD/ND cloud)");
  AddTruthFrame(*cmd, o->truth_frame);
  AddTruthMapping(*cmd, o->truth_mapping);
  cmd->callback([o] {
    const bool sim_form = !o->sim.empty();
    if (sim_form && (o->changes.empty() || o->pair.empty()))
      Usage("eval ld: with --sim give --changes DIR and --pair 00_XX");
    if (!sim_form && o->exact_ray) Usage("eval ld: --exact-ray needs --sim");
    if (!sim_form && (o->truth_dir.empty() || o->pred_dir.empty()))
      Usage("eval ld: give --truth-dir D --pred-dir D, or --sim DIR --changes DIR --pair 00_XX");
    const auto cfg = LoadEvalConfig(*o);
    eval::LdCase ld;
    if (sim_form) {
      std::string tdir = eval::FindPairDir(Join(o->sim, "truth"), o->pair);
      if (o->exact_ray) {
        tdir = io::layout::ExactRayTruthDir(tdir);
        if (!std::filesystem::is_directory(tdir))
          throw Error(tdir + ": no exact-ray truth (simulated by an older ltmapper: run `ltmapper sim` again)");
      }
      const std::string pdir = eval::FindPairDir(o->changes, o->pair);
      int c = -1, q = -1;
      if (std::sscanf(o->pair.c_str(), "%d_%d", &c, &q) != 2 || c < 0 || q < 0)
        Usage("eval ld: --pair must be CC_QQ (sim session indices), got '" + o->pair + "'");
      const eval::TruthMapping m = eval::ResolveTruthMapping(o->sim, o->aligned, o->truth_frame, o->truth_mapping);
      ld = eval::LoadSimLdCase(o->sim, o->changes, tdir, pdir, c, q, m, o->from_scans,
                               o->central_static.empty() && o->kept_map.empty(), cfg, o->common.threads);
    } else {
      ld = eval::LoadLdCase(o->truth_dir, o->pred_dir, o->truth_transform);
    }
    eval::Report report;
    report.inputs = ld.inputs;
    const std::string central_static = o->central_static.empty() ? ld.central_static : o->central_static;
    report.ld = eval::ScoreLdCase(ld, o->kept_map, central_static, o->errors, cfg, o->common.threads, &report.inputs);
    Finish(report, *o);
  });
}

// --------------------------------------------------------------------------------- restore
void SetupRestore(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::string map_a, map_b, sim, session, aligned;
    std::string truth_frame = "central", truth_mapping = "keyframe";
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("restore", "Chamfer distance over cubic patches between two aligned maps (paper table)");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--map-a", o->map_a, "First map (e.g. the restored session), PCD/PLY")->required();
  cmd->add_option("--map-b", o->map_b, "Second map (e.g. the real session), same frame");
  cmd->add_option("--sim", o->sim, "Instead of --map-b: the simulator's truth/<session>/static_world.pcd");
  cmd->add_option("--session", o->session, "Session name for --sim");
  cmd->add_option("--aligned", o->aligned, "With --sim: map the truth into the estimated world (see --truth-mapping)");
  AddTruthFrame(*cmd, o->truth_frame);
  AddTruthMapping(*cmd, o->truth_mapping);
  cmd->callback([o] {
    if (o->map_b.empty() == o->sim.empty()) Usage("eval restore: give --map-b F, or --sim DIR --session NAME");
    if (!o->sim.empty() && o->session.empty()) Usage("eval restore: --session is required with --sim");
    const auto cfg = LoadEvalConfig(*o);
    eval::Report report;
    const PointCloud a = io::ReadCloud(o->map_a);
    PointCloud b;
    if (!o->map_b.empty()) {
      b = io::ReadCloud(o->map_b);
      report.inputs = {{"map A", o->map_a}, {"map B", o->map_b}};
    } else {
      const std::string f = Join(Join(Join(o->sim, "truth"), o->session), "static_world.pcd");
      const eval::TruthMapping m = eval::ResolveTruthMapping(o->sim, o->aligned, o->truth_frame, o->truth_mapping);
      b = m.Map(io::ReadCloud(f), SessionIndex(o->sim, o->session), o->common.threads);
      report.inputs = {{"map A", o->map_a}, {"map B", f}, {"truth mapping", m.description}};
    }
    report.restore = eval::EvaluateRestore(a, b, cfg, o->common.threads);
    Finish(report, *o);
  });
}

// --------------------------------------------------------------------------------- storage
void SetupStorage(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::vector<std::string> paths, reports;
    double wall_s = -1.0, peak_mb = -1.0;
    std::string label = "given";
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("storage", "Bytes on disk (ratios to the first path), wall time and peak memory");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--path", o->paths, "Files or directories to measure (the first is the ratio reference)");
  cmd->add_option("--report", o->reports, "Stage report.json files to read wall time / peak memory from");
  cmd->add_option("--wall-s", o->wall_s, "Wall time of a run [s], reported under --label")->check(CLI::NonNegativeNumber);
  cmd->add_option("--peak-mb", o->peak_mb, "Peak memory of a run [MiB], reported under --label")->check(CLI::NonNegativeNumber);
  cmd->add_option("--label", o->label, "Label for --wall-s / --peak-mb");
  cmd->callback([o] {
    if (o->paths.empty() && o->reports.empty() && o->wall_s < 0 && o->peak_mb < 0)
      Usage("eval storage: give --path P..., --report F... or --wall-s / --peak-mb");
    const auto cfg = LoadEvalConfig(*o);
    (void)cfg;
    eval::Report report;
    eval::StorageResult s = eval::EvaluateStorage(o->paths);
    for (const auto& r : o->reports) s.costs.push_back(eval::ReadCostReport(r));
    if (o->wall_s >= 0 || o->peak_mb >= 0) {
      eval::CostItem c;
      c.label = o->label;
      if (o->wall_s >= 0) c.wall_s = o->wall_s;
      if (o->peak_mb >= 0) c.peak_bytes = o->peak_mb * 1048576.0;
      s.costs.push_back(c);
    }
    report.storage = std::move(s);
    Finish(report, *o);
  });
}

// --------------------------------------------------------------------------------- objects
void SetupObjects(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::string sim, objects, aligned;
    std::vector<std::string> pairs;
    std::string truth_frame = "central", truth_mapping = "keyframe";
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand("objects", "Changed objects: LT-map clusters vs the simulator's LD objects (point IoU)");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--sim", o->sim, "Simulator output dir (truth/objects.csv, truth/<session>/labels)")->required();
  cmd->add_option("--objects", o->objects, "Output of `ltmapper map objects` (objects.csv, objects.ply)")->required();
  cmd->add_option("--aligned", o->aligned, "LT-SLAM output: map the truth into the estimated world (see --truth-mapping)");
  cmd->add_option("--pair", o->pairs, "Session pair(s), e.g. 00_01 (default: 00 with every other session)");
  AddTruthFrame(*cmd, o->truth_frame);
  AddTruthMapping(*cmd, o->truth_mapping);
  cmd->callback([o] {
    const auto cfg = LoadEvalConfig(*o);
    std::vector<std::string> pairs = o->pairs;
    if (pairs.empty()) {
      const auto names = eval::SimSessionNames(o->sim);
      for (std::size_t q = 1; q < names.size(); ++q) {
        char buf[32];
        std::snprintf(buf, sizeof(buf), "00_%02zu", q);
        pairs.push_back(buf);
      }
    }
    const eval::TruthMapping m = eval::ResolveTruthMapping(o->sim, o->aligned, o->truth_frame, o->truth_mapping);
    std::vector<eval::ObjectTruth> truth;
    for (const auto& p : pairs) {
      auto t = eval::LoadSimObjectTruth(o->sim, p, m, cfg, o->common.threads);
      spdlog::info("pair {}: {} changed truth objects", p, t.size());
      for (auto& x : t) truth.push_back(std::move(x));
    }
    const auto clusters = eval::ReadObjectClusters(o->objects);
    spdlog::info("{} clusters read from {}", clusters.size(), o->objects);
    eval::Report report;
    report.inputs = {{"sim", o->sim}, {"objects", o->objects}};
    if (!o->aligned.empty()) report.inputs.push_back({"aligned", o->aligned});
    report.inputs.push_back({"truth mapping", m.description});
    report.objects = eval::EvaluateObjects(truth, clusters, cfg, o->common.threads);
    Finish(report, *o);
  });
}

// -------------------------------------------------------------------------------- livemeta
void SetupLiveMeta(CLI::App& parent) {
  struct Opt : EvalOptions {
    std::string sim, aligned, live, meta;
    std::vector<std::string> classes = {"car"};
    std::string truth_frame = "central", truth_mapping = "keyframe";
  };
  auto o = std::make_shared<Opt>();
  auto* cmd = parent.add_subcommand(
      "livemeta", "Live map has the objects new since session 0 and the meta map not; removed objects in neither");
  AddEvalOptions(*cmd, *o);
  cmd->add_option("--sim", o->sim, "Simulator output dir (truth/objects.csv, truth/<session>/static_world.ply)")->required();
  cmd->add_option("--live", o->live, "Live map (PCD/PLY), estimated world")->required();
  cmd->add_option("--meta", o->meta, "Meta map (PCD/PLY), estimated world")->required();
  cmd->add_option("--aligned", o->aligned, "LT-SLAM output: map the truth into the estimated world (see --truth-mapping)");
  cmd->add_option("--class", o->classes, "Object classes scored (truth/objects.csv 'class'; repeatable; 'all' = every class)");
  AddTruthFrame(*cmd, o->truth_frame);
  AddTruthMapping(*cmd, o->truth_mapping);
  cmd->callback([o] {
    const auto cfg = LoadEvalConfig(*o);
    const eval::TruthMapping m = eval::ResolveTruthMapping(o->sim, o->aligned, o->truth_frame, o->truth_mapping);
    std::vector<std::string> classes = o->classes;
    std::string class_list;
    for (const auto& c : classes) class_list += (class_list.empty() ? "" : ", ") + c;
    if (std::find(classes.begin(), classes.end(), "all") != classes.end()) classes.clear(), class_list = "all";
    const auto truth = eval::LoadSimLiveMetaTruth(o->sim, classes, m, o->common.threads);
    spdlog::info("{} objects ({}) changed between session 0 and the last session", truth.size(), class_list);
    const PointCloud live = io::ReadCloud(o->live), meta = io::ReadCloud(o->meta);
    eval::Report report;
    report.inputs = {{"sim", o->sim}, {"live map", o->live}, {"meta map", o->meta}, {"classes", class_list},
                     {"truth mapping", m.description}};
    report.livemeta = eval::EvaluateLiveMeta(truth, live, meta, cfg, o->common.threads);
    Finish(report, *o);
  });
}

}  // namespace

LTM_COMMAND(80, [](CLI::App& app) {
  auto* eval = app.add_subcommand("eval", "Score a stage against ground truth: traj, hd, ld, restore, storage, objects, livemeta");
  eval->require_subcommand(1);
  SetupTraj(*eval);
  SetupHd(*eval);
  SetupLd(*eval);
  SetupRestore(*eval);
  SetupStorage(*eval);
  SetupObjects(*eval);
  SetupLiveMeta(*eval);
});

}  // namespace ltm::app
