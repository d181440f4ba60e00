// `ltmapper sim --config config/params_sim.yaml --out DIR [--seed N] [--threads N]`: writes
// simulated sessions (SC-LIO-SAM layout) plus point-wise ground truth (docs/FORMATS.md).
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/sim/sim.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace {

struct SimArgs {
  std::string config;
  std::string out;
  int seed = -1;
  ltm::app::CommonOptions common;
};

void RunSim(const SimArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  ltm::sim::SimConfig cfg;
  if (!a.config.empty()) ltm::io::LoadConfig(a.config, cfg);
  if (a.seed >= 0) cfg.seed = a.seed;
  ltm::sim::CheckConfig(cfg, a.config.empty() ? "sim defaults" : a.config);
  spdlog::info("sim config{}:\n{}", a.config.empty() ? " (defaults)" : " " + a.config, ltm::ConfigToString(cfg));
  const auto r = ltm::sim::Simulate(cfg, a.out, a.common.threads);
  spdlog::info("world: {} triangles, {} LD objects, {} HD actors", r.triangles, r.ld_objects, r.hd_actors);
  spdlog::info("{} sessions, {} keyframes, {} rays, {} points ({} HD, {} on LD objects)", r.sessions,
               r.keyframes, r.rays, r.points, r.hd_points, r.ld_points);
  spdlog::info("cast {:.2f} s ({:.2f} M rays/s, {:.1f} ms per keyframe), build {:.2f} s, write {:.2f} s, "
               "truth {:.2f} s, total {:.2f} s, {:.1f} MB written",
               r.seconds_cast, r.rays_per_s / 1e6, r.keyframes ? 1e3 * r.seconds_cast / double(r.keyframes) : 0.0,
               r.seconds_build, r.seconds_write, r.seconds_truth, r.seconds_total, double(r.bytes_written) / 1e6);
  for (const auto& p : r.pairs) {
    spdlog::info("pair 00-{:02d}: PD strong {} weak {}, ND strong {} weak {} (points, {} m voxels); LD objects "
                 "only: PD strong {} weak {}, ND strong {} weak {}; {} visibility rays", p.query, p.pd_strong,
                 p.pd_weak, p.nd_strong, p.nd_weak, cfg.truth_voxel_m, p.objects_pd_strong, p.objects_pd_weak,
                 p.objects_nd_strong, p.objects_nd_weak, p.rays);
  }
  spdlog::info("wrote {}/sessions and {}/truth", a.out, a.out);
}

LTM_COMMAND(5, [](CLI::App& parent) {
  auto args = std::make_shared<SimArgs>();
  auto* cmd = parent.add_subcommand("sim", "Simulate LiDAR sessions of a city block with point-wise ground truth");
  cmd->add_option("--config", args->config, "Params file (config/params_sim.yaml); defaults when omitted")
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", args->out, "Output directory (sessions/ and truth/)")->required();
  cmd->add_option("--seed", args->seed, "Override the config's seed")->check(CLI::Range(0, 2000000000));
  ltm::app::AddCommonOptions(*cmd, args->common);
  cmd->callback([args] { RunSim(*args); });
});

}  // namespace
