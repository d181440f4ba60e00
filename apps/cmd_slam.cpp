// `ltmapper slam`: LT-SLAM from files. A central session and any number of query sessions ->
// aligned/ (docs/FORMATS.md, "LT-SLAM output").
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/slam.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace ltm::app {
namespace {

struct SlamArgs {
  CommonOptions common;
  std::string config;
  std::string central;
  std::vector<std::string> queries;
  std::vector<std::string> sessions;
  std::string out;
  bool strict = false;
};

void RunSlam(const SlamArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  slam::SlamConfig cfg;
  if (!a.config.empty()) io::LoadConfig(a.config, cfg);
  ValidateConfig(cfg, a.config.empty() ? "slam config" : a.config);
  spdlog::info("slam config:\n{}", ConfigToString(cfg));

  std::vector<std::string> dirs;
  if (!a.sessions.empty()) {
    if (!a.central.empty() || !a.queries.empty()) {
      throw Error("use either --sessions (first = central) or --central/--query, not both");
    }
    dirs = a.sessions;
  } else {
    if (a.central.empty()) throw Error("no central session: give --central DIR (or --sessions)");
    dirs.push_back(a.central);
    dirs.insert(dirs.end(), a.queries.begin(), a.queries.end());
  }
  if (dirs.size() < 2) throw Error("LT-SLAM needs a central session and at least one query");

  const slam::SlamResult res = slam::RunSlamStage(cfg, dirs, a.out, a.common.threads);
  int not_aligned = 0;
  for (const auto& s : res.sessions) not_aligned += s.aligned ? 0 : 1;
  spdlog::info("slam: wrote {} ({} of {} sessions aligned)", a.out,
               int(res.sessions.size()) - not_aligned, res.sessions.size());
  if (a.strict && not_aligned > 0) {
    throw Error(std::to_string(not_aligned) + " session(s) not aligned (see " + a.out +
                "/report.md)");
  }
}

LTM_COMMAND(20, [](CLI::App& parent) {
  auto a = std::make_shared<SlamArgs>();
  auto* cmd = parent.add_subcommand(
      "slam", "LT-SLAM: align sessions in one world frame (Scan Context + GICP + anchor graph)");
  cmd->add_option("--config", a->config, "Params file (config/params_ltslam.yaml)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--central", a->central, "Central session directory (the world frame)");
  cmd->add_option("--query", a->queries, "Query session directory (repeatable)");
  cmd->add_option("--sessions", a->sessions, "Session directories, the first is the central");
  cmd->add_option("--out", a->out, "Output directory (aligned/)")->required();
  cmd->add_flag("--strict", a->strict, "Exit with an error when a query is not aligned");
  AddCommonOptions(*cmd, a->common);
  cmd->callback([a] { RunSlam(*a); });
});

}  // namespace
}  // namespace ltm::app
