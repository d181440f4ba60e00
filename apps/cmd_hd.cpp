// `ltmapper hd <session-dir>`: HD removal (moving objects) of one drive with its own poses (or a
// KITTI pose file's, one per keyframe: --poses), any session layout (io::DetectSessionLayout). On a KTH DynamicMap benchmark folder the HD-free map
// goes to <dir>/ltmapper_output.pcd, where that benchmark's scorer looks for a method's output.
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace ltm::app {
namespace {

struct HdArgs {
  CommonOptions common;
  std::string dir, poses, config, out, hd_out;
  std::vector<std::string> set;
};

void RunHd(const HdArgs& a) {
  if (a.common.quiet) spdlog::set_level(spdlog::level::warn);
  const auto cfg = LoadParams<removert::RemovertConfig>(a.config, a.set);
  cfg.Validate(a.config.empty() ? "removert config" : a.config);
  const io::SessionLayout layout = io::DetectSessionLayout(a.dir);
  std::string out = a.out;
  if (out.empty() && layout.name == "kth-dynamicmap") out = a.dir + "/ltmapper_output.pcd";
  if (out.empty()) throw Error("--out is required for a " + layout.name + " session (only KTH folders have a default)");
  const std::vector<removert::WorldKeyframe> kfs = removert::LoadWorldKeyframes(a.dir, a.poses);
  spdlog::info("hd: {} ({} layout, {} keyframes{})", a.dir, layout.name, kfs.size(), a.poses.empty() ? "" : ", poses " + a.poses);
  const removert::HdResult res = removert::RemoveHd(kfs, cfg, a.common.threads);
  const removert::HdStats& st = res.stats;
  io::WritePcd(out, res.static_map);
  if (!a.hd_out.empty()) io::WritePcd(a.hd_out, res.hd_map);
  spdlog::info("hd: map {} points, removed {} + {} dilated ({:.2f} %), reverted {}; HD-free map {}", st.map_points,
               st.removed, st.dilated, st.map_points ? 100.0 * double(st.removed + st.dilated) / double(st.map_points) : 0.0,
               st.reverted, out);
}

LTM_COMMAND(45, [](CLI::App& parent) {
  auto a = std::make_shared<HdArgs>();
  auto* cmd = parent.add_subcommand("hd", "HD removal of one drive with its own poses (any layout; KTH DynamicMap "
                                          "folders get <dir>/ltmapper_output.pcd)");
  AddCommonOptions(*cmd, a->common);
  cmd->add_option("session-dir", a->dir, "Session directory (any layout `ltmapper info` names)")->required();
  cmd->add_option("--poses", a->poses, "KITTI pose file placing the keyframes (one per keyframe, in order; default: "
                                      "the session's own poses)")->check(CLI::ExistingFile);
  cmd->add_option("--config", a->config, "params_ltremovert.yaml (every key optional)")->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "HD-free map (PCD); default for KTH folders: <dir>/ltmapper_output.pcd");
  cmd->add_option("--hd-out", a->hd_out, "Also write the removed points (PCD)");
  cmd->add_option("--set", a->set, "Override a config key, e.g. --set hd.revert=false (repeatable)");
  cmd->callback([a] { RunHd(*a); });
});

}  // namespace
}  // namespace ltm::app
