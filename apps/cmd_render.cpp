// `ltmapper render`: top-down PNG of one or more clouds (world frame) with trajectories.
#include "command.hpp"

#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>

namespace ltm::app {
namespace {

struct RenderOptions {
  std::vector<std::string> clouds;
  std::vector<std::string> poses;
  std::string config;
  std::string color_by;
  std::string out;
  double meters_per_pixel = -1.0;
  int max_size_px = -1;
  CommonOptions common;
};

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Legend name of a pose file: its folder's name for generic names ("poses_world.txt").
std::string TrajectoryName(const std::string& path) {
  const std::filesystem::path p(path);
  const std::string stem = p.stem().string();
  const std::string parent = p.parent_path().filename().string();
  if (stem.find("poses") != std::string::npos && !parent.empty() && parent != ".") return parent;
  return stem;
}

// Legend name of a cloud: its file stem, or "folder/stem" when several clouds share a stem
// (e.g. every session's static_map.pcd).
std::string LayerName(const std::string& path, const std::vector<std::string>& all) {
  const std::filesystem::path p(path);
  const std::string stem = p.stem().string();
  const auto same = std::count_if(all.begin(), all.end(), [&](const std::string& other) {
    return std::filesystem::path(other).stem().string() == stem;
  });
  const std::string parent = p.parent_path().filename().string();
  return same > 1 && !parent.empty() ? parent + "/" + stem : stem;
}

void RunRender(const RenderOptions& o) {
  if (o.common.quiet) spdlog::set_level(spdlog::level::warn);
  viz::RenderConfig cfg;
  if (!o.config.empty()) io::LoadConfig(o.config, cfg);
  if (!o.color_by.empty()) cfg.color_by = o.color_by;
  if (o.meters_per_pixel >= 0) cfg.meters_per_pixel = o.meters_per_pixel;
  if (o.max_size_px > 0) cfg.max_size_px = o.max_size_px;
  ValidateConfig(cfg, "render options");
  spdlog::info("render config:\n{}", ConfigToString(cfg));

  const auto t0 = std::chrono::steady_clock::now();
  std::vector<PointCloud> clouds;
  clouds.reserve(o.clouds.size());
  std::vector<viz::Layer> layers;
  for (std::size_t i = 0; i < o.clouds.size(); ++i) {
    const std::string& path = o.clouds[i];
    const std::string ext = Lower(std::filesystem::path(path).extension().string());
    clouds.push_back(ext == ".ply" ? io::ReadPly(path) : io::ReadCloud(path));
    viz::Layer l;
    l.name = LayerName(path, o.clouds);
    l.default_class = viz::ClassFromFileName(path);
    l.default_session = int(i);
    spdlog::info("cloud {}: {} points{}{}", path, clouds.back().size(),
                 clouds.back().cls.empty() ? std::string(", class from name: ") + ToString(l.default_class)
                                           : std::string(", per-point class"),
                 clouds.back().session.empty() ? "" : ", per-point session");
    layers.push_back(l);
  }
  for (std::size_t i = 0; i < layers.size(); ++i) layers[i].cloud = &clouds[i];

  std::vector<viz::Trajectory> trajectories;
  for (const std::string& path : o.poses) {
    viz::Trajectory t;
    t.name = TrajectoryName(path);
    for (const Pose& p : io::ReadKittiPoses(path)) t.positions.push_back(p.translation());
    spdlog::info("trajectory {}: {} poses", path, t.positions.size());
    trajectories.push_back(std::move(t));
  }
  const auto t1 = std::chrono::steady_clock::now();
  const viz::RenderResult r = viz::RenderTopDown(layers, trajectories, cfg, o.out);
  const auto t2 = std::chrono::steady_clock::now();
  spdlog::info("wrote {}: {} x {} px, {:.4g} m/px, {} points drawn (read {:.2f} s, render+png {:.2f} s)",
               o.out, r.image.width, r.image.height, r.meters_per_pixel, r.points_drawn,
               std::chrono::duration<double>(t1 - t0).count(),
               std::chrono::duration<double>(t2 - t1).count());
}

}  // namespace

LTM_COMMAND(80, [](CLI::App& parent) {
  auto o = std::make_shared<RenderOptions>();
  CLI::App* cmd = parent.add_subcommand(
      "render", "Top-down PNG of clouds (world frame) colored by class, session or height");
  cmd->add_option("--cloud", o->clouds,
                  "Cloud file (.pcd/.bin/.ply), repeat for several sessions; class and session "
                  "fields are used when present, else class from the file name (pd_strong, hd, ...)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--poses", o->poses, "KITTI pose file drawn as a trajectory, repeatable")
      ->check(CLI::ExistingFile);
  cmd->add_option("--config", o->config, "YAML params (config/params_render.yaml)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--color-by", o->color_by, "class | session | height (overrides the config)")
      ->check(CLI::IsMember({"class", "session", "height"}));
  cmd->add_option("--resolution", o->meters_per_pixel, "Metres per pixel, 0 = fit --max-size")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_option("--max-size", o->max_size_px, "Longest map side in pixels")
      ->check(CLI::Range(32, 30000));
  cmd->add_option("--out", o->out, "Output PNG")->required();
  AddCommonOptions(*cmd, o->common);
  cmd->callback([o] { RunRender(*o); });
});

}  // namespace ltm::app
