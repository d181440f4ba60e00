// ltmapper removert: LT-removert (LT-mapper paper, section "LT-removert").
//
//   HD removal   per session, remove-then-revert on multi-resolution range images (Removert,
//                Kim & Kim, IROS 2020): a map point that a keyframe scan *sees through* (the
//                scan's range at the point's pixel exceeds the point's range by a tolerance)
//                gets a vote; points with enough votes at any removal resolution (fine to
//                coarse) are removed; removed points that enough keyframes observe as a surface
//                at a coarser revert resolution are reverted (false removals at grazing angles,
//                edges and thin structures).
//   LD detection between the HD-free central and query maps (kd-tree: fewer than k neighbours
//                within r in the other session = change): ND from central, PD from query. A
//                raw change whose surface the other session's scans observed (BeamTest: the two
//                beams around the exact ray towards it) and did not see through is the same
//                surface sampled more sparsely (far ground between rings): no change
//                (ld.same_min_hits).
//   Occlusion    ND the query never saw through = weak ND (kept in the map); PD in space some
//                central scan saw through (observed free) = weak PD; otherwise strong.
//
// All work is per keyframe and parallel (TBB, threads passed in); scans are streamed from disk
// (at most one per worker in memory) and each keyframe only touches the map points within
// `submap_radius_m` of it (tile index), so memory is the maps of at most two sessions (the
// central and the current query: a session's maps are freed when no later pair needs them) plus
// O(threads) scans; it still grows with the length of a session (its whole map is in memory).
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/geometry/sensor.hpp"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace ltm::removert {

// Did a scan observe the surface of a point (LD "same surface": the other session has it, only
// sampled more sparsely)? The exact ray towards the point is not among the beams, so it is
// judged from the beams around it, in the point's column (col_deg wide, rows of row_deg):
//  - a return in the point's own cell: on the point's plane (within tol_m + tol_rel * range)
//    and within the along-ray tolerance of it, tol / cos(incidence) capped at grazing_max_m;
//  - else the nearest returns above and below its direction (within span_deg): both on the
//    plane, and the ray towards the point meets the surface between them (the plane through
//    both returns along the point's surface contour) within that along-ray tolerance: so a
//    point in a trough behind a crest the lower beam hit, or behind an occluder, is not observed;
//  - else one of them on the plane at most edge_max_m from the point in range and the other
//    without a return or beyond the point (the surface's edge, far ground below the sky).
// The tolerances mirror the sim truth's (truth.visibility_tolerance_m, _grazing_max_m).
// The defaults are those of RemovertConfig::ld_beam (config keys ld.beam_*).
struct BeamTest {
  double col_deg = 0.4;         // [deg] column width (>= the scans' azimuth step)
  double row_deg = 0.1;         // [deg] row height (well below the beams' elevation spacing)
  double span_deg = 1.5;        // [deg] how far above / below the point's direction to look for the beams
  double tol_m = 0.3;           // [m] a return this close to the point's plane is on its surface ...
  double tol_rel = 0.005;       // [-] ... plus this times the range (rotation error between the sessions)
  double grazing_max_m = 2.0;   // [m] the along-ray tolerance tol / cos(incidence) at most this
  double edge_max_m = 60.0;     // [m] at a surface's edge (one beam on it, the other without a return or
                                //     beyond it) the return on it at most this far from the point in range
};

struct RemovertConfig {
  // --- sensor and range images
  std::string sensor = "auto";    // auto: estimated from the scans (geometry::EstimateSensor); a preset
                                  // name (geometry::SensorPresetNames); table: sensor.elevations_deg
  std::vector<double> sensor_elevations_deg;  // [deg] per-beam elevations (sensor: table)
  // Resolved by WithSensor() (not keys): the model, and the range images' vertical FOV (the
  // outer beams plus one beam spacing). Each image row's vertical window reaches at least one
  // beam spacing above and below it (SensorModel::SpacingAt), so a map point is always judged
  // against the beams on both sides of its direction: a single beam above grazing ground that
  // returns farther is no see-through evidence.
  geometry::SensorModel sensor_model;
  double fov_up_deg = 0.0;        // [deg] upper edge of the range images' vertical FOV
  double fov_down_deg = 0.0;      // [deg] lower edge
  double min_range_m = 2.0;       // [m] scan returns closer than this are ignored (ego vehicle)
  double max_range_m = 100.0;     // [m] scan returns farther than this are ignored
  double submap_radius_m = 60.0;  // [m] a keyframe tests only map points this close to it
  double tile_m = 10.0;           // [m] edge of the 2D tiles indexing map points for submaps
  // --- session map
  double map_voxel_m = 0.1;       // [m] voxel of the session map (union of keyframe scans)
  // --- see-through test: scan range > point range + tol_abs_m + tol_rel * point range
  double tol_abs_m = 0.10;        // [m]
  double tol_rel = 0.01;          // [-]
  int window_px = 1;              // [pixels] see-through needs the window's nearest return beyond
  // --- HD removal (remove then revert)
  std::vector<double> remove_resolutions_deg = {0.4, 0.6, 0.8};  // [deg/pixel] fine to coarse
  std::vector<double> revert_resolutions_deg = {1.2, 1.6};       // [deg/pixel] coarser
  bool revert = true;             // false: removal only (ablation)
  int remove_min_votes = 1;       // [keyframes] see-through votes to become a removal candidate
  double remove_min_ratio = 0.3;  // [-] and see-through votes / (see-through + hit votes)
  int revert_min_hits = 5;        // [keyframes] hits at a revert resolution to revert ...
  double revert_hit_ratio = 4.0;  // [-] ... and hits >= ratio * see-through votes there
  double revert_surface_max_m = 10.0;  // [m] revert hits include hits on the candidate's surface plane
                                       // (VisibilityOptions; normals over ld.normal_radius_m) up to this
                                       // far in range: grazing ground; 0 = plain range hits
  double dilate_voxels = 1.5;     // [map voxels] map points within one map voxel of a removed HD point, and
                                  // within this many voxels of a removed body's point (dilate_body_m), are removed
                                  // too: where a mover touched the ground (wheels, feet) its trace and the ground
                                  // share voxels and cannot be told apart; 1.5 = the centroids of the neighbouring
                                  // voxels (one voxel apart, each up to half a voxel off its centre); 0 = off
  double DilateM() const { return dilate_voxels * map_voxel_m; }  // [m]
  double dilate_body_m = 0.5;     // [m] a removed body's points: removed points with removed points within this
                                  // distance and at least half of it above or below them (a car's flank, a
                                  // pedestrian's legs), not removed patches of flat ground
  // --- LD detection
  double ld_radius_m = 0.3;       // [m] neighbour radius in the other session's map
  double ld_radius_rel = 0.01;    // [-] ... plus this times the larger of the point's distances to either session's
                                  // nearest keyframe ... (rotation error grows with viewing distance)
  double ld_radius_max_m = 1.0;   // [m] ... at most this
  int ld_min_neighbors = 1;       // [points] fewer neighbours than this = change
  double ld_rim_frac = 0.45;      // [-] a point whose neighbours are all beyond ld.radius_m and to one side of
                                  // it (centroid of the nearest 16 off it by more than this times r, along
                                  // their surface) is past the rim of the other session's coverage: a raw
                                  // change for the beam test (0 = off)
  std::vector<double> ld_resolutions_deg = {0.6, 1.0};  // [deg/pixel] visibility for weak/strong
  int ld_min_votes = 1;           // [keyframes] see-through votes for strong ND / weak PD
  double ld_min_ratio = 0.3;      // [-] and see-through / (see-through + hit) votes
  bool weak_nd = true;            // false: every ND is strong (ablation: no weak-ND preservation)
  int ld_window_px = 1;           // [pixels] window half-size of the LD see-through test (0 = the pixel alone)
  double ld_submap_radius_m = 100.0;  // [m] keyframes this close to a raw change vote on it (far ground
                                      // is sampled sparsely: use the sensor's max range)
  double ld_normal_radius_m = 1.0;   // [m] neighbourhood (own map, at most 16 points) for the normals of
                                      // raw changes; a line-like neighbourhood (far ground rings) takes
                                      // the normal perpendicular to the line closest to vertical
  double ld_surface_max_m = 10.0;     // [m] a return on the point's plane at most this far from it in range is
                                      // a same-surface hit (grazing far ground; an occluder is off the plane)
  int ld_same_min_hits = 1;       // [keyframes] a raw change not seen through that this many of the other
                                  // session's keyframes hit on its surface plane (surface hits, see
                                  // VisibilityOptions) is the same surface, sampled more sparsely:
                                  // no change (0 = off)
  std::string ld_same_test = "beams";  // beams: the beam test (ld_beam, BeamTest); pixel: the nearest return of
                                      // the point's LD-resolution pixel or window on its plane (ld.surface_max_m)
  BeamTest ld_beam;                    // keys ld.beam_*
  bool covisible_only = false;    // true: a raw change counts only where the other session had its line
                                  // of sight at all (a return in the window); else unobserved
  std::string pairs = "central";  // central: (0, q) for every query q; consecutive: (q-1, q)
  // --- outputs
  double assign_radius_m = 60.0;       // [m] changes farther from every central keyframe ...
  double new_keyframe_dist_m = 20.0;   // [m] ... go to query keyframes this far from all central ones
  double keyframe_voxel_m = 0.0;       // [m] extra voxel for per-keyframe clouds (0 = map voxel)
  bool write_keyframes = true;         // per keyframe local clouds
  bool write_ply = true;               // PLY twins with a class field

  template <class V>
  void Visit(V& v) {
    v("sensor.model", sensor, SensorChoices());
    v("sensor.elevations_deg", sensor_elevations_deg, "deg", -89.9, 89.9, true);
    v("sensor.min_range_m", min_range_m, "m", 0.0, 1000.0);
    v("sensor.max_range_m", max_range_m, "m", 0.1, 10000.0);
    v("submap_radius_m", submap_radius_m, "m", 1.0, 10000.0);
    v("tile_m", tile_m, "m", 0.5, 1000.0);
    v("map_voxel_m", map_voxel_m, "m", 0.01, 10.0);
    v("tol_abs_m", tol_abs_m, "m", 0.0, 10.0);
    v("tol_rel", tol_rel, "", 0.0, 1.0);
    v("window_px", window_px, "pixels", 0, 10);
    v("hd.remove_resolutions_deg", remove_resolutions_deg, "deg", 0.01, 10.0);
    v("hd.revert_resolutions_deg", revert_resolutions_deg, "deg", 0.01, 10.0);
    v("hd.revert", revert);
    v("hd.remove_min_votes", remove_min_votes, "keyframes", 1, 65535);
    v("hd.remove_min_ratio", remove_min_ratio, "", 0.0, 1.0);
    v("hd.revert_min_hits", revert_min_hits, "keyframes", 1, 65535);
    v("hd.revert_hit_ratio", revert_hit_ratio, "", 0.0, 1000.0);
    v("hd.revert_surface_max_m", revert_surface_max_m, "m", 0.0, 100.0);
    v("hd.dilate_voxels", dilate_voxels, "map voxels", 0.0, 10.0);
    v("hd.dilate_body_m", dilate_body_m, "m", 0.01, 10.0);
    v("ld.radius_m", ld_radius_m, "m", 0.01, 10.0);
    v("ld.radius_rel", ld_radius_rel, "", 0.0, 1.0);
    v("ld.radius_max_m", ld_radius_max_m, "m", 0.01, 10.0);
    v("ld.min_neighbors", ld_min_neighbors, "points", 1, 1000);
    v("ld.rim_frac", ld_rim_frac, "", 0.0, 1.0);
    v("ld.resolutions_deg", ld_resolutions_deg, "deg", 0.01, 10.0);
    v("ld.min_votes", ld_min_votes, "keyframes", 1, 65535);
    v("ld.min_ratio", ld_min_ratio, "", 0.0, 1.0);
    v("ld.weak_nd", weak_nd);
    v("ld.window_px", ld_window_px, "pixels", 0, 10);
    v("ld.submap_radius_m", ld_submap_radius_m, "m", 1.0, 10000.0);
    v("ld.normal_radius_m", ld_normal_radius_m, "m", 0.05, 10.0);
    v("ld.surface_max_m", ld_surface_max_m, "m", 0.0, 100.0);
    v("ld.same_min_hits", ld_same_min_hits, "keyframes", 0, 65535);
    v("ld.same_test", ld_same_test, {"beams", "pixel"});
    v("ld.beam_col_deg", ld_beam.col_deg, "deg", 0.01, 10.0);
    v("ld.beam_row_deg", ld_beam.row_deg, "deg", 0.01, 10.0);
    v("ld.beam_span_deg", ld_beam.span_deg, "deg", 0.01, 30.0);
    v("ld.beam_tol_m", ld_beam.tol_m, "m", 0.0, 10.0);
    v("ld.beam_tol_rel", ld_beam.tol_rel, "", 0.0, 1.0);
    v("ld.beam_grazing_max_m", ld_beam.grazing_max_m, "m", 0.0, 100.0);
    v("ld.beam_edge_max_m", ld_beam.edge_max_m, "m", 0.0, 1000.0);
    v("ld.covisible_only", covisible_only);
    v("ld.pairs", pairs, {"central", "consecutive"});
    v("out.assign_radius_m", assign_radius_m, "m", 0.0, 1e6);
    v("out.new_keyframe_dist_m", new_keyframe_dist_m, "m", 0.0, 1e6);
    v("out.keyframe_voxel_m", keyframe_voxel_m, "m", 0.0, 10.0);
    v("out.write_keyframes", write_keyframes);
    v("out.write_ply", write_ply);
  }
  // Range checks plus the cross-field rules (non-empty resolution lists, sensor table, ...).
  void Validate(const std::string& where = "removert config") const;
  bool SensorResolved() const { return fov_up_deg > fov_down_deg; }
  // Allowed values of sensor.model: auto, table and the presets.
  static std::vector<std::string> SensorChoices();
};

// A keyframe placed in the world: its scan (sensor frame) is either in memory (`cloud`) or read
// on demand from `cloud_path` (.pcd / .bin).
struct WorldKeyframe {
  int index = 0;
  Pose T_world_sensor = Pose::Identity();
  std::shared_ptr<const PointCloud> cloud;
  std::string cloud_path;
};

// A session's keyframes placed with its own poses (T_session_sensor as the world frame): HD
// removal of one drive, e.g. a KTH DynamicMap sequence whose poses are already in its world.
std::vector<WorldKeyframe> KeyframesOf(const Session& session);

// The config with its sensor resolved (sensor_model, fov_*_deg): the preset or table, else
// estimated from up to 8 of the keyframes' scans (spread over the session). A resolved config is
// returned unchanged; every entry point below calls it, so callers may pass either.
RemovertConfig WithSensor(const RemovertConfig& cfg, const std::vector<WorldKeyframe>& keyframes);

// ------------------------------------------------------------------------------ HD removal
struct HdStats {
  std::size_t map_points = 0;
  std::vector<std::size_t> removed_per_resolution;  // candidates found at each removal resolution
  std::size_t candidates = 0;   // union over the removal resolutions
  std::size_t reverted = 0;
  std::size_t removed = 0;      // candidates - reverted
  std::size_t dilated = 0;      // further points within hd.dilate_voxels map voxels of a removed point
  double seconds_map = 0, seconds_votes = 0;
};
struct HdResult {
  PointCloud static_map;  // world frame, HD-free
  PointCloud hd_map;      // world frame, removed points
  HdStats stats;
};
// The session map: union of the keyframe scans in the world frame (range-filtered), voxel
// downsampled; built in batches so only a few scans are in memory at once.
PointCloud BuildSessionMap(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                           int threads = 0);
// HD removal of one session (builds its map first).
HdResult RemoveHd(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                  int threads = 0);
// HD removal of a given map (world frame) against the keyframes.
HdResult RemoveHdFromMap(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads = 0);

// ------------------------------------------------------------------------------ LD detection
struct LdStats {
  std::size_t central_points = 0, query_points = 0;
  std::size_t nd_strong = 0, nd_weak = 0, pd_strong = 0, pd_weak = 0;
  std::size_t pd_unobserved = 0, nd_unobserved = 0;
  std::size_t pd_same = 0, nd_same = 0;  // raw changes the other session observed as the same surface
  double seconds = 0;
};
struct LdResult {
  PointCloud nd_strong, nd_weak;  // central map points, world frame
  PointCloud pd_strong, pd_weak;  // query map points, world frame
  PointCloud pd_unobserved;       // query points the central never had in view (new territory)
  PointCloud nd_unobserved;       // central points the query never had in view (kept, no change)
  std::vector<bool> central_nd;   // per central map point: it is in nd_strong or nd_weak
  LdStats stats;
};
// LD changes between the HD-free central and query maps (world frame). The keyframes (scans +
// world poses) decide occlusion: ND seen through by a query scan is strong (else weak), PD seen
// through by a central scan is weak (else strong).
LdResult DetectLd(const PointCloud& central_map, const PointCloud& query_map,
                  const std::vector<WorldKeyframe>& central_keyframes,
                  const std::vector<WorldKeyframe>& query_keyframes, const RemovertConfig& cfg,
                  int threads = 0);

// ------------------------------------------------------------------------- visibility votes
// For each point (world frame) and each resolution, how many keyframes see through it (scan
// range > point range + tolerance) and how many hit it (|scan range - point range| <=
// tolerance), counting keyframes within submap_radius_m of the point. The building block of HD
// removal and of the weak/strong decisions; exposed for tests and ablations.
struct VisibilityVotes {
  std::size_t points = 0;
  int levels = 0;
  std::vector<std::uint16_t> see;  // [level * points + i]
  std::vector<std::uint16_t> hit;
  std::vector<std::uint16_t> occ;  // occluded (nearer return); only when count_occluded
  std::vector<std::uint16_t> beam_hits;  // [i] keyframes that observed the point's surface by the BeamTest
  std::uint16_t See(int level, std::size_t i) const { return see[std::size_t(level) * points + i]; }
  std::uint16_t Hit(int level, std::size_t i) const { return hit[std::size_t(level) * points + i]; }
};
// Optional per-point unit normals (world frame) enable surface hits: a point also counts as hit
// when the nearest return of its own pixel lies on the point's surface plane (distance to the
// plane within the tolerance) and at most surface_max_m from it in range: a surface seen at a
// grazing angle (far ground) is sampled metres apart in range, so the plain range test misses
// it, while an occluder in front of the point is off its plane (LD "same surface" test, revert).
struct VisibilityOptions {
  bool count_occluded = false;
  // Judge a point only within the beams' span (the outermost beams widened by their scatter):
  // beyond it only one beam passes near the point and that is no evidence (HD removal, revert).
  // LD's occlusion test judges anywhere in the images' FOV (a change above the top beam).
  bool within_beams = true;
  const std::vector<Eigen::Vector3f>* normals = nullptr;
  double surface_max_m = 0.0;  // [m]
  // With normals: the beam test per keyframe (BeamTest; VisibilityVotes::beam_hits).
  const BeamTest* beams = nullptr;
};
VisibilityVotes CountVisibility(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                                const std::vector<double>& resolutions_deg,
                                const RemovertConfig& cfg, int threads = 0,
                                const VisibilityOptions& options = {});

// ------------------------------------------------------------------------------------ stage
struct StageReport {
  std::vector<std::string> sessions;
  std::vector<HdStats> hd;
  std::vector<std::pair<int, int>> pairs;
  std::vector<LdStats> ld;
  std::vector<std::vector<int>> new_keyframes;  // per pair: query keyframe indices reported new
  double seconds = 0;
  std::size_t peak_rss_bytes = 0;
};
// The whole stage from files: session directories (io::LoadSession), one world pose file per
// session (KITTI, keyframe order: LT-SLAM's aligned/<session>/poses_world.txt or sim truth), and
// the output directory (layout in docs/FORMATS.md, "LT-removert output"). Session 0 is central.
StageReport RunRemovertStage(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                             const std::vector<std::string>& poses_files, const std::string& out_dir,
                             int threads = 0);
// The stage on an LT-SLAM output: the aligned sessions of `aligned_dir`'s run manifest
// (io::ReadRunManifest), in run order, with their aligned/<session>/poses_world.txt. Pair folder
// positions are therefore positions among the manifest's aligned sessions, as LT-map reads them.
StageReport RunRemovertStageOnRun(const RemovertConfig& cfg, const std::string& aligned_dir,
                                  const std::string& out_dir, int threads = 0);
// Lifelong add: the stage for one more session, into an existing output `changes_dir`.
// `session_dirs` / `poses_files` are the run's aligned sessions in run order with the new one
// last (position q). Runs HD removal of the new session only and LD of its pair (central 0 or,
// with `pairs: consecutive`, q-1), whose HD-free and HD maps are read from changes_dir, never
// recomputed; the sensor comes from the central's scans as in the batch. Replaces
// changes_dir/<new>/ (with its own report.json) and changes_dir/pair_<c>_<q>/ whole. With the
// same poses the files equal those of the batch stage. Cost: one session's HD + one pair's LD.
StageReport AddToRemovertStage(const RemovertConfig& cfg, const std::vector<std::string>& session_dirs,
                               const std::vector<std::string>& poses_files, const std::string& changes_dir,
                               int threads = 0);

}  // namespace ltm::removert
