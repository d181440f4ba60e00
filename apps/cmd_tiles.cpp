// `ltmapper tiles`: HD removal of one session tile by tile (removert/tiles.hpp), memory bounded by
// the tile. plan -> run (each tile a job: here one after another, or on Dask through
// python/ltmapper_dask.py) -> merge: the maps of `ltmapper hd`, bit for bit. LD of a pair the
// same way over the two sessions' HD plans: ld-plan -> run -> merge (the stage's pair clouds).
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace ltm::app {
namespace {

struct TilesArgs {
  CommonOptions common;
  std::string session, poses, config, plan, out, central, query;
  std::vector<std::string> set;
  std::vector<std::size_t> tiles;
  bool force = false;
};

void Plan(const TilesArgs& a) {
  auto cfg = LoadParams<removert::RemovertConfig>(a.config, a.set);
  cfg.Validate(a.config.empty() ? "removert config" : a.config);
  const removert::TilePlan plan = removert::WriteTilePlan(a.out, a.session, a.poses, cfg, a.common.threads);
  std::size_t most = 0;
  for (const auto& t : plan.tiles) most = std::max(most, t.keyframes.size());
  spdlog::info("tiles: {} tiles of {:.1f} m (margin {:.2f} m, reach {:.1f} m) over {} keyframes, at most {} per tile, "
               "largest map ~{:.0f} points (tiles.max_map_points {}); plan {}",
               plan.tiles.size(), plan.EdgeM(), double(plan.margin_voxels) * plan.voxel_m, plan.reach_m,
               plan.session_keyframes, most, plan.largest_map_estimate, cfg.tiles_max_map_points, a.out);
}

void LdPlan(const TilesArgs& a) {
  const removert::LdTilePlan plan = removert::WriteLdTilePlan(a.out, a.central, a.query);
  spdlog::info("tiles: {} LD tiles of {:.1f} m (margin {:.2f} m), largest window {} points; plan {}", plan.tiles.size(),
               plan.EdgeM(), double(plan.margin_voxels) * plan.voxel_m, plan.largest_window, a.out);
}

void Run(const TilesArgs& a) {
  const bool ld = removert::IsLdTilePlan(a.plan);  // a.tiles empty: every tile, one after another
  const std::size_t ran = ld ? removert::RunLdTileJobs(a.plan, a.tiles, a.common.threads, a.force)
                             : removert::RunTileJobs(a.plan, a.tiles, a.common.threads, a.force);
  spdlog::info("tiles: ran {} tiles", ran);
}

void Merge(const TilesArgs& a) {
  if (removert::IsLdTilePlan(a.plan)) {
    const removert::LdStats st = removert::MergeLdTileJobs(a.plan, a.out);
    spdlog::info("tiles: LD: ND strong {} weak {} (unobserved {}), PD strong {} weak {} (unobserved {}), residues {} + "
                 "{}; clouds in {}", st.nd_strong, st.nd_weak, st.nd_unobserved, st.pd_strong, st.pd_weak,
                 st.pd_unobserved, st.nd_residue, st.pd_residue, a.out);
    return;
  }
  const removert::HdStats st = removert::MergeTileJobs(a.plan, a.out);
  spdlog::info("tiles: map {} points, removed {} + {} dilated, reverted {}; HD-free map {}", st.map_points, st.removed,
               st.dilated, st.reverted, io::layout::StaticMapIn(a.out));
}

void Setup(CLI::App& parent) {
  auto a = std::make_shared<TilesArgs>();
  auto* cmd = parent.add_subcommand("tiles", "HD removal of one session, or LD of a pair, tile by tile (memory bounded "
                                             "by the tile): plan, run the tiles (here or on Dask), merge");
  cmd->require_subcommand(1);
  auto* plan = cmd->add_subcommand("plan", "Split the session's world into tiles: PLAN_DIR/plan.json + config.yaml");
  AddCommonOptions(*plan, a->common);
  plan->add_option("session-dir", a->session, "Session directory (any layout `ltmapper info` names)")->required()
      ->check(CLI::ExistingDirectory);
  plan->add_option("--poses", a->poses, "KITTI world poses, one per keyframe (default: the session's own poses)")
      ->check(CLI::ExistingFile);
  plan->add_option("--config", a->config, "params_ltremovert.yaml (every key optional; tiles.edge_m)")
      ->check(CLI::ExistingFile);
  plan->add_option("--set", a->set, "Override a config key, e.g. --set tiles.edge_m=50 (repeatable)");
  plan->add_option("--out", a->out, "Plan directory (replaced whole when it holds a plan.json)")->required();
  plan->callback([a] { Plan(*a); });

  auto* ld_plan = cmd->add_subcommand("ld-plan", "Split a pair's LD into tiles over its sessions' HD tile plans (every "
                                                 "HD tile done): PLAN_DIR/plan.json + config.yaml");
  AddCommonOptions(*ld_plan, a->common);
  ld_plan->add_option("--central", a->central, "The central session's HD plan directory")->required()
      ->check(CLI::ExistingDirectory);
  ld_plan->add_option("--query", a->query, "The query session's HD plan directory (the same config)")->required()
      ->check(CLI::ExistingDirectory);
  ld_plan->add_option("--out", a->out, "LD plan directory (replaced whole when it holds a plan.json)")->required();
  ld_plan->callback([a] { LdPlan(*a); });

  auto* run = cmd->add_subcommand("run", "Run tile jobs: PLAN_DIR/parts/tile_NNNNNN/ (tiles already done are skipped)");
  AddCommonOptions(*run, a->common);
  run->add_option("plan-dir", a->plan, "Plan directory (`ltmapper tiles plan` or `ld-plan`)")->required()
      ->check(CLI::ExistingDirectory);
  run->add_option("--tile", a->tiles, "Tile number (repeatable; default: every tile, one after another)");
  run->add_flag("--force", a->force, "Run the tiles even when they are done");
  run->callback([a] { Run(*a); });

  auto* merge = cmd->add_subcommand("merge", "Merge the tiles' parts: OUT/static_map.pcd, hd_map.pcd, report.json (an "
                                             "LD plan: the pair's nd_*, pd_* clouds and report.json)");
  AddCommonOptions(*merge, a->common);
  merge->add_option("plan-dir", a->plan, "Plan directory (every tile done)")->required()->check(CLI::ExistingDirectory);
  merge->add_option("--out", a->out, "Output directory (replaced whole when it holds a report.json)")->required();
  merge->callback([a] { Merge(*a); });
  for (CLI::App* sub : {plan, ld_plan, run, merge})
    sub->parse_complete_callback([a] {
      if (a->common.quiet) spdlog::set_level(spdlog::level::warn);
    });
}

LTM_COMMAND(46, Setup);

}  // namespace
}  // namespace ltm::app
