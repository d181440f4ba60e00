// `ltmapper removert`: LT-removert from files. Sessions + world poses (LT-SLAM's aligned/ dir or
// one KITTI pose file per session) -> changes/ (docs/FORMATS.md, "LT-removert output").
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <memory>
#include <sstream>

namespace ltm::app {
namespace {

struct RemovertArgs {
  CommonOptions common;
  std::string config;
  std::vector<std::string> sessions;
  std::string aligned;
  std::vector<std::string> poses;
  std::string out;
  std::vector<std::string> set;
};

void Report(const removert::StageReport& rep, const std::string& out);

void RunRemovert(const RemovertArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  const auto cfg = LoadParams<removert::RemovertConfig>(a.config, a.set);
  cfg.Validate(a.config.empty() ? "removert config" : a.config);
  spdlog::info("removert config:\n{}", ConfigToString(cfg));

  if (!a.aligned.empty() && a.sessions.empty()) {  // the sessions and their order from the run manifest
    Report(removert::RunRemovertStageOnRun(cfg, a.aligned, a.out, a.common.threads), a.out);
    return;
  }
  std::vector<std::string> poses = a.poses;
  removert::RemovertConfig run_cfg = cfg;
  if (!a.aligned.empty()) {
    std::vector<std::string> names;
    for (const auto& s : a.sessions) {
      const std::string name = std::filesystem::path(s).lexically_normal().filename().string();
      names.push_back(name.empty() ? std::filesystem::path(s).parent_path().filename().string() : name);
      poses.push_back(io::layout::PosesWorldFile(a.aligned, names.back()));
    }
    // LT-SLAM's rotation measures of these sessions, as a run of all of them reads them (an
    // aligned folder without a manifest measures nothing: pose_sigma_deg).
    if (io::HasRunManifest(a.aligned)) run_cfg = removert::WithAlignment(cfg, io::ReadRunManifest(a.aligned), names);
  }
  if (poses.size() != a.sessions.size())
    throw Error("need one pose file per session: " + std::to_string(a.sessions.size()) +
                " sessions, " + std::to_string(poses.size()) + " pose files");
  Report(removert::RunRemovertStage(run_cfg, a.sessions, poses, a.out, a.common.threads), a.out);
}

void Report(const removert::StageReport& rep, const std::string& out) {
  for (std::size_t s = 0; s < rep.sessions.size(); ++s) {
    const auto& h = rep.hd[s];
    spdlog::info("{}: {} map points, {} removed as HD + {} dilated ({:.2f} %), {} reverted", rep.sessions[s],
                 h.map_points, h.removed, h.dilated,
                 h.map_points ? 100.0 * double(h.removed + h.dilated) / double(h.map_points) : 0.0, h.reverted);
  }
  for (std::size_t p = 0; p < rep.pairs.size(); ++p) {
    const auto& l = rep.ld[p];
    spdlog::info("pair {}-{}: ND strong {} weak {}, PD strong {} weak {}, {} new keyframes",
                 rep.pairs[p].first, rep.pairs[p].second, l.nd_strong, l.nd_weak, l.pd_strong,
                 l.pd_weak, rep.new_keyframes[p].size());
  }
  spdlog::info("removert: {:.1f} s, peak memory {:.0f} MB, output {}", rep.seconds,
               double(rep.peak_rss_bytes) / 1e6, out);
}

LTM_COMMAND(40, [](CLI::App& parent) {
  auto a = std::make_shared<RemovertArgs>();
  auto* cmd = parent.add_subcommand(
      "removert", "LT-removert: HD removal (remove-then-revert) and LD changes (PD/ND, strong/weak)");
  AddCommonOptions(*cmd, a->common);
  cmd->add_option("--config", a->config, "params_ltremovert.yaml (every key optional)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--sessions", a->sessions,
                  "Session directories; the first is the central session (default with --aligned: the aligned "
                  "sessions of its manifest.yaml, in run order)");
  auto* al = cmd->add_option("--aligned", a->aligned,
                             "LT-SLAM output dir: world poses from <dir>/<session>/poses_world.txt")
                 ->check(CLI::ExistingDirectory);
  auto* po = cmd->add_option("--poses", a->poses,
                             "One KITTI world-pose file per session (e.g. sim truth/session_XX/poses_world.txt); "
                             "LD then takes the rotation prior pose_sigma_deg (`ltmapper run --poses` measures the "
                             "poses' rotation error instead)");
  al->excludes(po);
  po->excludes(al);
  cmd->add_option("--out", a->out, "Output directory (changes/)")->required();
  cmd->add_option("--set", a->set, "Override a config key, e.g. --set ld.weak_nd=false (repeatable)");
  cmd->callback([a] {
    if (a->aligned.empty() && a->poses.empty()) throw Error("removert: give --aligned DIR or --poses FILE...");
    if (a->aligned.empty() && a->sessions.empty()) throw Error("removert: give --sessions DIR... with --poses");
    RunRemovert(*a);
  });
});

}  // namespace
}  // namespace ltm::app
