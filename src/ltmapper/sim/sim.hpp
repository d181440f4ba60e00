// ltmapper sim: a seeded, deterministic multi-session urban LiDAR simulator with point-wise
// ground truth (docs/FORMATS.md "Simulator output").
//
// A street-grid city block (ground with relief and curbs, buildings with facade bays, walls,
// fences, poles, trees, parked cars) is built as triangle meshes and ray-cast with Embree 3 by a
// spinning LiDAR. Each session drives its own route over the same streets, starts at its own
// unknown origin T_world_session and has drifting odometry; high dynamic (HD) actors move during
// a session and low dynamic (LD) objects exist only in some sessions. Embree stays inside the
// .cpp files.
//
// Determinism: the scenario comes from one 64-bit seed through our own generator (no std
// distributions); the noise of every ray is a hash of (seed, session, keyframe, ray), so the
// thread count never changes a byte of the output.
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <memory>
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

// An LD object: exists only in the sessions of `present_in`.
struct LdObjectInfo {
  int id = 0;
  std::string cls;                 // car, truck, tree, fence, container, structure, wall, hoarding
  std::vector<int> present_in;     // sorted session indices
  std::string placement;           // open | occluded | revealed
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // world frame [m]
  Eigen::Vector3d box_min = Eigen::Vector3d::Zero(), box_max = Eigen::Vector3d::Zero();
};

// An HD actor: moves along its session's route during that session only.
struct HdActorInfo {
  int id = 0;          // unique over all sessions, after the LD object ids
  int session = 0;
  std::string cls;     // car | pedestrian
  double speed_mps = 0.0;
};

// Counts of the point-wise change truth of one pair (central 0, query k), in points after
// voxel downsampling (truth.voxel_m): every changed surface, and the LD-object-only part.
struct PairTruthCounts {
  int query = 0;
  std::size_t pd_strong = 0, pd_weak = 0, nd_strong = 0, nd_weak = 0;
  std::size_t objects_pd_strong = 0, objects_pd_weak = 0, objects_nd_strong = 0, objects_nd_weak = 0;
  std::size_t rays = 0;  // visibility rays cast for this pair
};

struct SimReport {
  int sessions = 0;
  std::size_t keyframes = 0;
  std::size_t triangles = 0;
  std::size_t ld_objects = 0, hd_actors = 0;
  std::size_t rays = 0, points = 0, hd_points = 0, ld_points = 0;
  double rays_per_s = 0.0;          // casting only
  double seconds_build = 0.0;       // scenario + Embree scenes
  double seconds_cast = 0.0;        // ray casting
  double seconds_write = 0.0;       // sessions, labels
  double seconds_truth = 0.0;       // static worlds, change truth with visibility
  double seconds_total = 0.0;
  std::size_t bytes_written = 0;
  std::vector<PairTruthCounts> pairs;
};

// Runs the whole simulation and writes DIR/sessions/session_XX and DIR/truth (FORMATS.md).
// `threads` = 0 uses all cores. Output bytes do not depend on `threads`.
SimReport Simulate(const SimConfig& cfg, const std::string& out_dir, int threads = 0);

// Result of one ray.
struct RayHit {
  bool hit = false;
  float range = 0.f;                         // [m] noise-free distance to the first hit
  PointClass cls = PointClass::kUnknown;     // kStatic (also LD objects) or kHD
  int object = -1;                           // LD object id, HD actor id, -1 permanent static
  float cos_incidence = 1.f;                 // |cos| of the angle between ray and surface normal
};

// The scenario and its Embree scenes in memory (for tests and benchmarks; Simulate uses it).
// Not thread-safe across calls: CastScan/CastRay first put the HD actors of (session, keyframe)
// in place. Each call runs its rays in parallel itself.
class Simulator {
 public:
  explicit Simulator(const SimConfig& cfg, int threads = 0);
  ~Simulator();
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;

  const SimConfig& config() const;
  int sessions() const;
  int keyframes(int session) const;
  std::size_t triangles() const;
  std::size_t hd_actors() const;
  const std::vector<LdObjectInfo>& ld_objects() const;
  std::vector<HdActorInfo> hd_actor_info() const;
  // HD actor ids are unique over all sessions and never collide with LD object ids.
  bool IsPresent(int ld_object, int session) const;

  Pose T_world_session(int session) const;                      // the true unknown origin
  const std::vector<Pose>& T_world_sensor(int session) const;   // true keyframe poses
  std::vector<Pose> T_session_sensor_true(int session) const;   // true poses, session frame
  const std::vector<Pose>& T_session_sensor_drifted(int session) const;  // written odometry

  // One keyframe scan in the sensor frame with per-point cls (kStatic / kHD), session and
  // object filled; noise and dropout applied (deterministic per ray). Points ordered beam by
  // beam (top beam first), column by column within a beam.
  PointCloud CastScan(int session, int keyframe);
  // The world pose each column of a keyframe's scan is fired from (lidar.sweep: all the keyframe
  // pose when instant, else moving on towards the next keyframe during sweep_s).
  std::vector<Pose> SweepPoses(int session, int keyframe) const;
  // Rays from `origin_world` along unit `dirs_world` in the world of `session` with the HD
  // actors at `keyframe` (noise free, up to max_range). Runs in parallel.
  std::vector<RayHit> CastRays(int session, int keyframe, const Eigen::Vector3d& origin_world,
                               const std::vector<Eigen::Vector3f>& dirs_world);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Odometry drift: a copy of the true session-frame poses whose consecutive increments carry a
// per-session scale error, x/y noise, a yaw and a z random walk (see SimConfig drift.*). The
// first pose is kept.
std::vector<Pose> DriftPoses(const std::vector<Pose>& T_session_sensor_true, const SimConfig& cfg,
                             std::uint64_t seed);

}  // namespace ltm::sim
