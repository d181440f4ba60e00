// `ltmapper view --store map.ltmap`: the evolving map in 3D in the browser (ltm::view). Serves the
// page and the store's clouds on 127.0.0.1 until stopped (Ctrl-C).
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/view/view.hpp"

#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <thread>

namespace ltm::app {
namespace {

struct ViewOptions {
  CommonOptions common;
  view::ViewConfig cfg;
  std::string host = "127.0.0.1";
  int port = 8080;
  std::string map_config;
  std::vector<std::string> set;  // view config overrides
};

void RunView(ViewOptions& o) {
  if (o.common.quiet) spdlog::set_level(spdlog::level::warn);
  if (!o.map_config.empty()) io::LoadConfig(o.map_config, o.cfg.map);
  ValidateConfig(o.cfg.map, o.map_config.empty() ? "map config" : o.map_config);
  for (const auto& kv : o.set) SetField(FieldsOf(o.cfg), kv);
  ValidateConfig(o.cfg, "view config");
  if (!o.common.quiet) spdlog::info("view config:\n{}", ConfigToString(o.cfg));
  o.cfg.threads = o.common.threads;
  const view::Viewer viewer(o.cfg);
  std::thread warm;
  struct Join {
    std::thread& t;
    ~Join() { if (t.joinable()) t.join(); }
  } join{warm};
  view::Serve(viewer, o.host, o.port, [&](int port) {
    // The page opens on the latest session: its tiles and their level 0 are ready before the
    // address is printed; the other sessions and the meta map follow in the background (the
    // slider finds them ready).
    const auto requests = viewer.WarmRequests();
    if (!requests.empty()) viewer.Handle(requests.front());
    warm = std::thread([&viewer, requests] {
      for (std::size_t k = 1; k < requests.size(); ++k) viewer.Handle(requests[k]);
    });
    std::cout << "ltmapper view: serving " << o.cfg.store << " on http://" << o.host << ":" << port
              << "/ (Ctrl-C to stop)\n" << std::flush;
  });
}

void Setup(CLI::App& parent) {
  auto opts = std::make_shared<ViewOptions>();
  ViewOptions& o = *opts;
  auto* cmd = parent.add_subcommand("view", "Serve a 3D viewer of the map store in the browser (three.js)");
  AddCommonOptions(*cmd, o.common);
  cmd->add_option("--store", o.cfg.store, "Map store file (NAME.ltmap), opened read-only")->required();
  cmd->add_option("--run", o.cfg.run_dir, "Run folder with objects/ and aligned/ (default: the store's folder)");
  cmd->add_option("--port", o.port, "TCP port (0 = any free port, printed)")->check(CLI::Range(0, 65535));
  cmd->add_option("--host", o.host, "Address to bind (127.0.0.1: this machine only)");
  cmd->add_option("--web", o.cfg.web_dir, "Folder of the page (index.html, viewer.js, three/)");
  cmd->add_option("--voxel", o.cfg.base_voxel_m, "Finest voxel of served clouds [m] (base_voxel_m, default 0.1)");
  cmd->add_option("--budget", o.cfg.point_budget, "Most points in one served cloud and drawn by the page (point_budget, default 2000000)");
  cmd->add_option("--set", o.set,
                  "Override a view config key: base_voxel_m, point_budget, max_voxel_m, cache_clouds, tile_m, "
                  "lod_levels, cache_mb, max_query_chars, max_path_chars, max_static_mb (repeatable)");
  cmd->add_option("--config", o.map_config, "params_ltmap.yaml (meta_carve_radius_m for the meta map)");
  o.cfg.web_dir = LTM_WEB_DIR;
  cmd->callback([opts] { RunView(*opts); });
}

}  // namespace

LTM_COMMAND(95, Setup);

}  // namespace ltm::app
