// `ltmapper run`: LT-SLAM -> LT-removert -> LT-map in one go (resumable), and `ltmapper report`:
// evaluation Markdown + PNG renders gathered into report.md / report.html.
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/pipeline/pipeline.hpp"

#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

namespace {

struct RunArgs {
  ltm::app::CommonOptions common;
  std::string config;
  std::vector<std::string> sessions;
  std::string out;
  std::string slam_config, removert_config, map_config, from;
  std::vector<std::string> poses;  // world poses per session instead of LT-SLAM's alignment
};

// The run params from --config and the per-stage overrides (run and add share them).
ltm::pipeline::RunConfig LoadRunConfig(const RunArgs& a) {
  ltm::pipeline::RunConfig cfg;
  if (!a.config.empty()) ltm::io::LoadConfig(a.config, cfg);
  if (!a.slam_config.empty()) cfg.slam_config = a.slam_config;
  if (!a.removert_config.empty()) cfg.removert_config = a.removert_config;
  if (!a.map_config.empty()) cfg.map_config = a.map_config;
  if (!a.from.empty()) cfg.from_stage = a.from;
  ltm::ValidateConfig(cfg, a.config.empty() ? "run options" : a.config);
  spdlog::info("run config:\n{}", ltm::ConfigToString(cfg));
  return cfg;
}

void Run(const RunArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  const auto report = ltm::pipeline::RunPipeline(LoadRunConfig(a), a.sessions, a.out, a.common.threads, a.poses);
  std::cout << ltm::pipeline::FormatRunReport(report) << std::flush;
}

LTM_COMMAND(70, [](CLI::App& parent) {
  auto a = std::make_shared<RunArgs>();
  auto* cmd = parent.add_subcommand(
      "run", "LT-SLAM -> LT-removert -> LT-map on session directories (first = central); resumable");
  cmd->add_option("--sessions", a->sessions, "Session directories, central first")->required()->expected(2, -1);
  cmd->add_option("--out", a->out, "Output directory (aligned/, changes/, map.ltmap, live/meta maps)")->required();
  cmd->add_option("--config", a->config, "Run params YAML (config/params_run.yaml)");
  cmd->add_option("--slam-config", a->slam_config, "LT-SLAM params (overrides the run params)");
  cmd->add_option("--removert-config", a->removert_config, "LT-removert params");
  cmd->add_option("--map-config", a->map_config, "LT-map params");
  cmd->add_option("--from", a->from, "Rerun from this stage (default: resume after the last finished one)")
      ->check(CLI::IsMember({"auto", "slam", "removert", "map"}));
  cmd->add_option("--poses", a->poses,
                  "One KITTI world-pose file per session, in --sessions order: place the sessions by "
                  "these poses instead of aligning them (e.g. sim truth/session_XX/poses_world.txt)")
      ->check(CLI::ExistingFile);
  ltm::app::AddCommonOptions(*cmd, a->common);
  cmd->callback([a] { Run(*a); });
});

void Add(const RunArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  const auto cfg = LoadRunConfig(a);
  if (!a.poses.empty() && a.poses.size() != a.sessions.size())
    throw ltm::Error("add: " + std::to_string(a.sessions.size()) + " sessions but " + std::to_string(a.poses.size()) +
                     " pose files (--poses: one per session, in the same order)");
  for (std::size_t i = 0; i < a.sessions.size(); ++i) {  // one at a time, in the order given
    const auto report =
        ltm::pipeline::AddSession(cfg, a.out, a.sessions[i], a.common.threads, a.poses.empty() ? "" : a.poses[i]);
    std::cout << ltm::pipeline::FormatAddReport(report) << std::flush;
  }
}

LTM_COMMAND(75, [](CLI::App& parent) {
  auto a = std::make_shared<RunArgs>();
  auto* cmd = parent.add_subcommand(
      "add", "Add new drives to the map a run built in --map: align, HD removal and changes of the new drive only");
  cmd->add_option("--map", a->out, "The run's output directory (aligned/, changes/, map.ltmap)")->required();
  cmd->add_option("sessions", a->sessions, "New session directories, added one at a time in this order")
      ->required()->expected(1, -1);
  cmd->add_option("--config", a->config, "Run params YAML (config/params_run.yaml); use the run's own");
  cmd->add_option("--slam-config", a->slam_config, "LT-SLAM params (overrides the run params)");
  cmd->add_option("--removert-config", a->removert_config, "LT-removert params");
  cmd->add_option("--map-config", a->map_config, "LT-map params");
  cmd->add_option("--poses", a->poses,
                  "One KITTI world-pose file per new session, in the same order: place them by these poses "
                  "(the map's world frame) instead of aligning them")
      ->check(CLI::ExistingFile);
  ltm::app::AddCommonOptions(*cmd, a->common);
  cmd->callback([a] { Add(*a); });
});

struct ReportArgs {
  std::string out, title = "ltmapper report";
  std::vector<std::string> items;
};

LTM_COMMAND(90, [](CLI::App& parent) {
  auto a = std::make_shared<ReportArgs>();
  auto* cmd = parent.add_subcommand("report", "Gather Markdown results and PNG renders into report.md + report.html");
  cmd->add_option("--out", a->out, "Output path without extension (writes .md and .html)")->required();
  cmd->add_option("--title", a->title, "Report title");
  cmd->add_option("--item", a->items, "A .md file or a .png picture, in order; 'picture.png::caption' sets a caption")
      ->required();
  cmd->callback([a] {
    std::vector<ltm::pipeline::ReportItem> items;
    for (const auto& s : a->items) {
      const auto sep = s.find("::");
      items.push_back(sep == std::string::npos ? ltm::pipeline::ReportItem{s, ""}
                                               : ltm::pipeline::ReportItem{s.substr(0, sep), s.substr(sep + 2)});
    }
    ltm::pipeline::WriteReport(a->out, a->title, items);
    std::cout << "wrote " << a->out << ".md and " << a->out << ".html\n";
  });
});

}  // namespace
