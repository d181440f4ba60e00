// Config checks and the tiny test scenario.
#include "ltmapper/sim/config.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <algorithm>
#include <cmath>

namespace ltm::sim {

void CheckConfig(const SimConfig& c, const std::string& where) {
  ValidateConfig(c, where);
  auto fail = [&](const std::string& what) { throw Error(where + ": " + what); };
  if (c.fov_up_deg <= c.fov_down_deg && c.beams > 1) fail("lidar.fov_up_deg must be above lidar.fov_down_deg");
  if (c.min_range_m >= c.max_range_m) fail("lidar.min_range_m must be below lidar.max_range_m");
  if (c.building_max_height_m < c.building_min_height_m) {
    fail("world.building_max_height_m must be >= world.building_min_height_m");
  }
  if (std::floor(c.extent_m / c.block_m + 1e-9) < 2) {
    fail("world.extent_m must hold at least two streets (extent >= 2 * world.block_m)");
  }
  if (c.road_half_width_m + c.sidewalk_m + 2.0 > 0.5 * c.block_m) {
    fail("world.road_half_width_m + world.sidewalk_m leave no room for blocks (must be < block_m / 2 - 2)");
  }
  if (c.lane_offset_m >= c.road_half_width_m) fail("route.lane_offset_m must lie inside the road");
}

std::vector<std::string> LidarPresetChoices() {
  std::vector<std::string> c = {"uniform"};
  for (const std::string& n : geometry::SensorPresetNames()) c.push_back(n);
  return c;
}

bool InFieldOfView(const SimConfig& cfg, const Eigen::Vector3d& d) {
  constexpr double kDeg = M_PI / 180.0, kEps = 1e-6;
  const double n = d.norm();
  if (!(n > 0.0)) return false;
  if (cfg.lidar_pattern == "rosette") return std::acos(std::clamp(d.x() / n, -1.0, 1.0)) <= cfg.rosette_half_angle_deg * kDeg + kEps;
  const double el = std::atan2(d.z(), std::hypot(d.x(), d.y()));
  return !(el < cfg.fov_down_deg * M_PI / 180.0 - kEps || el > cfg.fov_up_deg * M_PI / 180.0 + kEps);
}

std::vector<Eigen::Vector3f> RosetteDirections(const SimConfig& cfg, std::uint64_t scan_index) {
  constexpr double kGoldenAngle = 2.399963229728653;  // [rad] pi (3 - sqrt(5)): turns never repeat
  constexpr double kPetals = 11.0;                     // rose curve cos(k theta): 2k petals per turn
  const double alpha = cfg.rosette_half_angle_deg * M_PI / 180.0;
  const double phase = kGoldenAngle * double(scan_index % 1000003);
  std::vector<Eigen::Vector3f> dirs(std::size_t(cfg.rosette_points));
  for (int i = 0; i < cfg.rosette_points; ++i) {
    const double theta = 2.0 * M_PI * i / cfg.rosette_points;
    const double rho = alpha * std::fabs(std::cos(kPetals * theta + phase)), phi = theta + phase;
    dirs[std::size_t(i)] = Eigen::Vector3f(float(std::cos(rho)), float(std::sin(rho) * std::cos(phi)),
                                           float(std::sin(rho) * std::sin(phi)));
  }
  return dirs;
}

SimConfig ResolveLidar(const SimConfig& cfg) {
  if (cfg.lidar_pattern == "rosette") {
    SimConfig r = cfg;
    r.beams = 1;
    r.columns = cfg.rosette_points;
    r.fov_up_deg = cfg.rosette_half_angle_deg;
    r.fov_down_deg = -cfg.rosette_half_angle_deg;
    return r;
  }
  if (cfg.lidar_preset == "uniform") return cfg;
  const geometry::SensorModel m = geometry::SensorPreset(cfg.lidar_preset);
  SimConfig r = cfg;
  r.beams = m.beams();
  r.fov_up_deg = m.fov_up_deg;
  r.fov_down_deg = m.fov_down_deg;
  r.columns = int(std::lround(360.0 / m.azimuth_step_deg));
  return r;
}

std::vector<double> BeamElevationsDeg(const SimConfig& cfg) {
  if (cfg.lidar_preset != "uniform") return geometry::SensorPreset(cfg.lidar_preset).elevations_deg;
  const int B = cfg.beams;
  std::vector<double> e(std::size_t(B), cfg.fov_up_deg);
  for (int b = 1; b < B; ++b) e[std::size_t(b)] = cfg.fov_up_deg - b * (cfg.fov_up_deg - cfg.fov_down_deg) / (B - 1);
  return e;
}

SimConfig TinyConfig() {
  SimConfig c;
  c.seed = 7;
  c.extent_m = 100.0;
  c.block_m = 50.0;
  c.ground_cell_m = 2.0;
  c.beams = 16;
  c.columns = 360;
  c.max_range_m = 60.0;
  c.sessions = 2;
  c.keyframes = 15;
  c.keyframe_spacing_m = 2.0;
  c.hd_cars = 3;
  c.hd_pedestrians = 3;
  c.ld_parked_cars = 2;
  c.ld_trees_cut = 1;
  c.ld_fences = 1;
  c.ld_containers = 1;
  c.ld_structures = 1;
  c.ld_wall_reveals = 1;
  c.ld_occluded = 1;
  c.open_lot_fraction = 0.5;
  c.min_route_overlap = 0.0;  // the query may leave the central's streets: unobserved territory
  return c;
}

}  // namespace ltm::sim
