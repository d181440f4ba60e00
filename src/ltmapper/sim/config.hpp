// ltmapper sim: SimConfig (params_sim.yaml), its checks and the LiDAR patterns derived from it.
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace ltm::sim {

// Allowed values of lidar.preset: "uniform" and the sensor presets (geometry::SensorPresetNames).
std::vector<std::string> LidarPresetChoices();

struct SimConfig {
  int seed = 1;
  // --- world (street grid city block) ---
  std::string scenario = "urban";       // urban | repetitive (rows of identical buildings)
  double extent_m = 200.0;              // [m] side of the square world
  double block_m = 50.0;                // [m] street spacing (centre to centre)
  double road_half_width_m = 6.0;       // [m] street centre to curb (2 lanes + parking strips)
  double sidewalk_m = 3.0;              // [m] curb to building line
  double curb_m = 0.15;                 // [m] curb height (sidewalks and lots are raised)
  double relief_m = 0.6;                // [m] amplitude of the gentle ground relief
  double relief_wavelength_m = 120.0;   // [m]
  double ground_cell_m = 1.0;           // [m] ground mesh resolution
  double building_min_height_m = 6.0;   // [m]
  double building_max_height_m = 24.0;  // [m]
  double open_lot_fraction = 0.3;       // share of frontage lots left open (walls, fences, yards)
  double tree_spacing_m = 12.0;         // [m] tree slots along sidewalks
  double tree_fill = 0.6;               // share of tree slots with a permanent tree
  double pole_spacing_m = 25.0;         // [m] street lamps along sidewalks
  double parking_fill = 0.4;            // share of parking slots with a permanently parked car
  // --- lidar ---
  std::string lidar_preset = "uniform"; // uniform: `beams` evenly from fov_up to fov_down; else a real
                                        // sensor's beam table and columns (geometry::SensorPreset), which
                                        // then set beams / fov_up_deg / fov_down_deg / columns
  int beams = 64;                       // 16 / 32 / 64 / 128 (any 1..256)
  double fov_up_deg = 15.0;             // [deg] top beam elevation
  double fov_down_deg = -25.0;          // [deg] bottom beam elevation (beams uniform in between)
  int columns = 1024;                   // rays per beam over 360 deg (horizontal resolution)
  double min_range_m = 1.5;             // [m] returns closer are dropped (own vehicle)
  double max_range_m = 100.0;           // [m]
  double range_noise_m = 0.02;          // [m] std of Gaussian range noise
  double dropout = 0.02;                // probability a return is lost
  double sensor_height_m = 1.8;         // [m] above the road surface
  double tilt_deg = 0.0;                // [deg] mounting pitch of the sensor on the vehicle (positive: nose
                                        // down); the keyframe poses are the tilted sensor's
  std::string lidar_pattern = "spinning";  // spinning: beams x columns; rosette: a Livox-like non-repetitive
                                        // pattern of rosette_points directions per scan in a forward cone,
                                        // turned by the golden angle from scan to scan (no rings)
  int rosette_points = 20000;           // points per rosette scan
  double rosette_half_angle_deg = 35.0; // [deg] half-angle of the rosette's cone around the forward axis
  std::string sweep = "instant";        // instant: every ray of a scan from the keyframe pose; distorted: column c
                                        // fired sweep_s * c / columns after the keyframe, from the pose of that
                                        // moment, its point written in the sensor frame of that moment (a raw
                                        // sweep, as KITTI's); deskewed: the same rays, points moved into the
                                        // keyframe's frame (as SC-LIO-SAM saves them)
  double sweep_s = 0.1;                 // [s] duration of one sweep (10 Hz)
  // --- sessions and routes ---
  int sessions = 3;
  int keyframes = 300;                  // per session
  double keyframe_spacing_m = 1.0;      // [m] distance between keyframes
  double ego_speed_mps = 8.0;           // [m/s] sets time per keyframe (HD actors move in time)
  double lane_offset_m = 2.0;           // [m] driving lane centre right of the street centre
  double corner_radius_m = 10.0;        // [m] turns at intersections
  double min_route_overlap = 0.25;      // share of a query's keyframed path on streets session 0 drove
  double origin_offset_m = 100.0;       // [m] |x|,|y| of T_world_session up to this
  double origin_offset_z_m = 2.0;       // [m] |z| of T_world_session up to this
  // --- odometry drift (random walk), written poses only ---
  double drift_scale = 0.005;           // std of a per-session odometry scale error [fraction]
  double drift_translation = 0.01;      // std of per-step x/y noise [fraction of step length]
  double drift_yaw_deg = 0.05;          // [deg/sqrt(m)] yaw random walk
  double drift_z_m = 0.005;             // [m/sqrt(m)] height random walk
  // --- HD actors, per session ---
  int hd_cars = 6;
  int hd_pedestrians = 8;
  double hd_car_speed_mps = 9.0;        // [m/s] mean (each car +-30 %)
  double hd_pedestrian_speed_mps = 1.3; // [m/s] mean (each +-30 %)
  // --- LD changes between sessions (near the routes) ---
  int ld_parked_cars = 6;               // cars parked in some sessions only
  int ld_trees_cut = 2;                 // trees cut after some session
  int ld_fences = 2;                    // construction fences built or removed
  int ld_containers = 2;                // containers moved between two lots
  int ld_structures = 2;                // new kiosks / sheds in open view
  int ld_wall_reveals = 1;              // wall removed, revealing a new structure behind it
  int ld_occluded = 2;                  // object gone behind a hoarding built later
  double ld_route_distance_m = 20.0;    // [m] slots this close to a route count as near it
  // --- truth ---
  double truth_voxel_m = 0.2;           // [m] static worlds and change clouds
  double visibility_tolerance_m = 0.3;  // [m] a ray observes a point when its first hit lies within
                                        // tol / cos(incidence) of it, passes through beyond that
  double visibility_grazing_max_m = 2.0;  // [m] cap of that along-ray tolerance at grazing incidence
  int visibility_max_rays = 0;          // per point and pair, 0 = every keyframe in range

  template <class V>
  void Visit(V& v) {
    v("seed", seed, "", 0, 2000000000);
    v("world.scenario", scenario, {"urban", "repetitive"});
    v("world.extent_m", extent_m, "m", 40.0, 2000.0);
    v("world.block_m", block_m, "m", 30.0, 500.0);
    v("world.road_half_width_m", road_half_width_m, "m", 3.0, 20.0);
    v("world.sidewalk_m", sidewalk_m, "m", 1.0, 10.0);
    v("world.curb_m", curb_m, "m", 0.0, 0.5);
    v("world.relief_m", relief_m, "m", 0.0, 5.0);
    v("world.relief_wavelength_m", relief_wavelength_m, "m", 10.0, 10000.0);
    v("world.ground_cell_m", ground_cell_m, "m", 0.25, 10.0);
    v("world.building_min_height_m", building_min_height_m, "m", 2.0, 200.0);
    v("world.building_max_height_m", building_max_height_m, "m", 2.0, 200.0);
    v("world.open_lot_fraction", open_lot_fraction, "", 0.0, 1.0);
    v("world.tree_spacing_m", tree_spacing_m, "m", 4.0, 200.0);
    v("world.tree_fill", tree_fill, "", 0.0, 1.0);
    v("world.pole_spacing_m", pole_spacing_m, "m", 5.0, 500.0);
    v("world.parking_fill", parking_fill, "", 0.0, 1.0);
    v("lidar.preset", lidar_preset, LidarPresetChoices());
    v("lidar.beams", beams, "", 1, 256);
    v("lidar.fov_up_deg", fov_up_deg, "deg", -89.0, 89.0);
    v("lidar.fov_down_deg", fov_down_deg, "deg", -89.0, 89.0);
    v("lidar.columns", columns, "", 16, 1000000);
    v("lidar.min_range_m", min_range_m, "m", 0.0, 50.0);
    v("lidar.max_range_m", max_range_m, "m", 1.0, 1000.0);
    v("lidar.range_noise_m", range_noise_m, "m", 0.0, 1.0);
    v("lidar.dropout", dropout, "", 0.0, 0.99);
    v("lidar.sensor_height_m", sensor_height_m, "m", 0.3, 10.0);
    v("lidar.tilt_deg", tilt_deg, "deg", -45.0, 45.0);
    v("lidar.pattern", lidar_pattern, {"spinning", "rosette"});
    v("lidar.rosette_points", rosette_points, "", 100, 1000000);
    v("lidar.rosette_half_angle_deg", rosette_half_angle_deg, "deg", 1.0, 89.0);
    v("lidar.sweep", sweep, {"instant", "distorted", "deskewed"});
    v("lidar.sweep_s", sweep_s, "s", 0.001, 1.0);
    v("route.sessions", sessions, "", 1, 64);
    v("route.keyframes", keyframes, "", 2, 100000);
    v("route.keyframe_spacing_m", keyframe_spacing_m, "m", 0.1, 20.0);
    v("route.ego_speed_mps", ego_speed_mps, "m/s", 0.5, 50.0);
    v("route.lane_offset_m", lane_offset_m, "m", 0.0, 10.0);
    v("route.corner_radius_m", corner_radius_m, "m", 2.0, 50.0);
    v("route.min_overlap", min_route_overlap, "", 0.0, 1.0);
    v("route.origin_offset_m", origin_offset_m, "m", 0.0, 10000.0);
    v("route.origin_offset_z_m", origin_offset_z_m, "m", 0.0, 1000.0);
    v("drift.scale", drift_scale, "", 0.0, 0.5);
    v("drift.translation", drift_translation, "", 0.0, 0.5);
    v("drift.yaw_deg", drift_yaw_deg, "deg/sqrt(m)", 0.0, 10.0);
    v("drift.z_m", drift_z_m, "m/sqrt(m)", 0.0, 1.0);
    v("hd.cars", hd_cars, "", 0, 1000);
    v("hd.pedestrians", hd_pedestrians, "", 0, 1000);
    v("hd.car_speed_mps", hd_car_speed_mps, "m/s", 0.1, 50.0);
    v("hd.pedestrian_speed_mps", hd_pedestrian_speed_mps, "m/s", 0.1, 10.0);
    v("ld.parked_cars", ld_parked_cars, "", 0, 1000);
    v("ld.trees_cut", ld_trees_cut, "", 0, 1000);
    v("ld.fences", ld_fences, "", 0, 1000);
    v("ld.containers", ld_containers, "", 0, 1000);
    v("ld.structures", ld_structures, "", 0, 1000);
    v("ld.wall_reveals", ld_wall_reveals, "", 0, 1000);
    v("ld.occluded", ld_occluded, "", 0, 1000);
    v("ld.route_distance_m", ld_route_distance_m, "m", 1.0, 1000.0);
    v("truth.voxel_m", truth_voxel_m, "m", 0.01, 10.0);
    v("truth.visibility_tolerance_m", visibility_tolerance_m, "m", 0.0, 10.0);
    v("truth.visibility_grazing_max_m", visibility_grazing_max_m, "m", 0.0, 100.0);
    v("truth.visibility_max_rays", visibility_max_rays, "", 0, 1000000);
  }
};

// Throws ltm::Error for combinations Visit() ranges cannot express (fov order, heights ...).
void CheckConfig(const SimConfig& cfg, const std::string& where = "sim config");
// The config with lidar.beams / fov_up_deg / fov_down_deg / columns taken from lidar.preset (a
// uniform config is returned as it is). Every stage of the simulator works on this.
SimConfig ResolveLidar(const SimConfig& cfg);
// Elevation of each beam [deg], top beam first: the preset's table, or uniform.
std::vector<double> BeamElevationsDeg(const SimConfig& cfg);
// Whether a sensor-frame direction is inside the field of view (vertical FOV of a spinning
// sensor, the cone of a rosette).
bool InFieldOfView(const SimConfig& cfg, const Eigen::Vector3d& d_sensor);
// The rosette's sensor-frame directions of one scan (lidar.pattern: rosette): a rose curve
// rho = half_angle * |cos(k theta)| in the cone, turned by the golden angle per scan index.
std::vector<Eigen::Vector3f> RosetteDirections(const SimConfig& cfg, std::uint64_t scan_index);
// A tiny scenario for tests: 16 beams x 360 columns, 2 sessions x 15 keyframes, 100 m world.
SimConfig TinyConfig();

}  // namespace ltm::sim
