// ltmapper removert: RemovertConfig (params_ltremovert.yaml) and the BeamTest of LD "same surface".
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/geometry/sensor.hpp"

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace ltm::removert {

constexpr double kRadPerDeg = 3.14159265358979323846 / 180.0;

// Did a scan observe the surface of a point (LD "same surface": the other session has it, only
// sampled more sparsely)? As the sim's beam truth asks (FORMATS.md): did one of the scan's beams
// end on the point's surface near it? Judged in the point's column (col_deg wide, rows of
// row_deg) and the columns within asin(tol / range) of it (the truth counts a ray at any azimuth):
// in each, the return of the point's row and the nearest returns above and below it (within
// span_deg), one of them on the point's plane (within tol_m), its ray
// passing within that tolerance of the point and its return within the along-ray tolerance of
// the point's place along it (tol / cos(incidence), at most grazing_max_m, at the incidence on the
// point's plane and on the surface the beam met: the other session's map around its return,
// detail::HitSurfaces; the truth reads the surface its ray hit). A point between two
// beams that met its surface farther away (far ground between rings) was not sampled: unobserved;
// it is "around" (both beams on its plane and the ray towards it meets the surface through them
// within the along-ray tolerance, not in a trough behind a crest; or one on its plane and the
// other without a return or beyond it, the surface's edge), and a beam going on past it there is
// no evidence its place was free (LD's own-pixel rule of PD strength does not count it).
// The tolerances mirror the sim truth's (truth.visibility_tolerance_m, _grazing_max_m).
// The defaults are those of RemovertConfig::ld_beam (config keys ld.beam_*).
struct BeamTest {
  double col_deg = 0.4;         // [deg] column width where the sensor has no azimuth step (no rings);
                                // else the azimuth step (ForSensor): a cell holds one return per beam
  double row_deg = 0.1;         // [deg] row height (well below the beams' elevation spacing)
  double span_deg = 1.5;        // [deg] how far above / below the point's direction to look for the beams
  double tol_m = 0.3;           // [m] a return this close to the point's plane is on its surface, at any
                                // range: the rotation error between the sessions brings a beam nearer
                                // as often as it takes one away, so it widens nothing
  double grazing_max_m = 2.0;   // [m] the along-ray tolerance tol / cos(incidence) at most this (a beam
                                // that ended near; one that went through must end beyond it uncapped)
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
  // And, for scans saved deskewed in sessions with keyframe times, when their columns fired: the
  // votes then see each scan from there, as a raw sweep's (detail::LoadVoterScan). Unknown when
  // the scans are raw sweeps, or when re-skewing them makes no larger share of the beams tell their
  // returns.
  SweepTiming sweep_timing;
  double min_range_m = 2.0;       // [m] scan returns closer than this are ignored (ego vehicle)
  double max_range_m = 100.0;     // [m] scan returns farther than this are ignored; LD's voters are the
                                  // keyframes this close to a raw change (no farther one returned on it)
  double submap_radius_m = 60.0;  // [m] a keyframe tests only map points this close to it
  double tile_m = 10.0;           // [m] edge of the 2D tiles indexing map points for submaps
  // --- session map
  double map_voxel_m = 0.1;       // [m] voxel of the session map (union of keyframe scans)
  // --- see-through test: scan range > point range + tol_abs_m + tol_rel * point range
  double tol_abs_m = 0.10;        // [m]
  double tol_rel = 0.01;          // [-]
  int window_px = 1;              // [pixels] see-through needs the window's nearest return beyond
  double pose_sigma_deg = 0.3;    // [deg] relative rotation error of the poses between keyframes within
                                  // submap_radius_m: HD's see-through test also reads the window at yaw -+ it
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
  double body_max_m = 5.0;        // [m] a keyframe's cluster of returns above the ground no longer than this, at least
                                  // remove_min_ratio of it removed and its votes pooled passing removal's test, is a
                                  // mover's body: the map points that every keyframe returning on them met in such a
                                  // body go too; 0 = off
  // --- LD detection
  double ld_radius_m = 0.3;       // [m] neighbour radius in the other session's map
  // ... plus LdRadiusRel() times the larger of the point's distances to either session's nearest keyframe
  // (the rotation error between the sessions moves a surface seen from afar by that much) ...
  double ld_radius_max_m = 1.0;   // [m] ... at most this; also how far a surface both sessions' maps hold
                                  // may lie behind a displaced copy of it in one map (not seen through)
  int ld_min_neighbors = 1;       // [points] fewer neighbours than this = change
  // The rotation uncertainty between two sessions' poses at one place (1 sigma). 0: what LT-SLAM
  // measured for the pair's sessions (ForPair), else pose_sigma_deg.
  double ld_rotation_sigma_deg = 0.0;  // [deg]
  // Not a key: LT-SLAM's measures per session position, from the run manifest
  // (io::ManifestSession::rotation_sigma_deg, WithAlignment): each session's rotation uncertainty
  // against the run's central, 0 for the central itself, NaN where not measured; empty = none
  // (poses given).
  std::vector<double> session_rotation_sigma_deg;  // [deg]
  // The config of the LD pair (c, q) (session positions): ld.rotation_sigma_deg, left 0, takes the
  // two sessions' measures against the central, independent errors: sqrt(sigma_c^2 + sigma_q^2)
  // (the central's is 0, so a pair with the central takes its query's). Where either is not
  // measured, or both are 0, pose_sigma_deg stays. Measures given for fewer sessions than a
  // position needs are an ltm::Error (a run's manifest lists every aligned session).
  RemovertConfig ForPair(std::size_t c, std::size_t q) const {
    RemovertConfig out = *this;
    if (session_rotation_sigma_deg.empty()) return out;
    for (const std::size_t s : {c, q})
      if (s >= session_rotation_sigma_deg.size())
        throw Error("removert: no rotation measure for session position " + std::to_string(s) + " (" +
                    std::to_string(session_rotation_sigma_deg.size()) + " given)");
    const double sc = session_rotation_sigma_deg[c], sq = session_rotation_sigma_deg[q];
    const double pair = std::sqrt(sc * sc + sq * sq);  // NaN when either is not measured
    if (out.ld_rotation_sigma_deg <= 0.0 && pair > 0.0) out.ld_rotation_sigma_deg = pair;
    return out;
  }
  double LdRotationSigmaDeg() const { return ld_rotation_sigma_deg > 0.0 ? ld_rotation_sigma_deg : pose_sigma_deg; }
  // The kd-tree radius must hold a surface both sessions have wherever the rotation error puts it:
  // three sigma, as LT-SLAM's verification. (The beam test asks what the change truth asks, a beam
  // of the other session within ld.beam_tol_m of the point, and does not grow: BeamTest::tol_m.)
  static constexpr double kLdRadiusSigmas = 3.0;
  double LdRadiusRel() const { return std::tan(kLdRadiusSigmas * LdRotationSigmaDeg() * kRadPerDeg); }
  // The own pixel's see-through (PD strength) counts where the pixel's half size at the point is
  // within ld.beam_tol_m plus this times the range: where the other session's rotation error moves
  // its rays by as much as the pixel is wide, a ray that passed the point's pixel passed the point.
  double LdOwnTolRel() const { return std::tan(LdRotationSigmaDeg() * kRadPerDeg); }
  double ld_rim_frac = 0.45;      // [-] a point whose neighbours are all beyond ld.radius_m and to one side of
                                  // it (centroid of the nearest 16 off it by more than this times r, along
                                  // their surface) is past the rim of the other session's coverage: a raw
                                  // change for the beam test (0 = off); where the kd radius grew by at most
                                  // ld.beam_tol_m every query point (PD) with neighbours only beyond
                                  // ld.radius_m is one (Missing, ld_detection.cpp)
  std::vector<double> ld_resolutions_deg = {0.6, 1.0};  // [deg/pixel] visibility for weak/strong
  int ld_min_votes = 1;           // [keyframes] see-through votes for strong ND / weak PD (for ND also
                                  // keyframes a beam of which went through the point's surface, or passed
                                  // it without a return: BeamTest)
  double ld_min_ratio = 0.3;      // [-] and see-through / (see-through + hit) votes
  bool weak_nd = true;            // false: every ND is strong (ablation: no weak-ND preservation)
  int ld_window_px = 1;           // [pixels] window half-size of the LD see-through test (0 = the pixel alone)
  double ld_normal_radius_m = 1.0;   // [m] neighbourhood (own map, at most 16 points) for the normals of
                                      // raw changes; a line-like neighbourhood (far ground rings) takes
                                      // the normal perpendicular to the line closest to vertical; also how
                                      // near a scan's return on a point's plane makes a beam that went on
                                      // past it a ray past the surface's edge, no see-through
  double ld_surface_max_m = 10.0;     // [m] a return on the point's plane at most this far from it in range is
                                      // a same-surface hit (grazing far ground; an occluder is off the plane)
  int ld_same_min_hits = 1;       // [keyframes] a raw change not seen through (with the beam test, or on
                                  // level ground: see SeenThroughBy) that this many of the other
                                  // session's keyframes hit on its surface plane (surface hits, see
                                  // VisibilityOptions) is the same surface, sampled more sparsely:
                                  // no change (0 = off)
  std::string ld_same_test = "beams";  // beams: the beam test (ld_beam, BeamTest); pixel: the nearest return of
                                      // the point's LD-resolution pixel or window on its plane (ld.surface_max_m)
  BeamTest ld_beam;                    // keys ld.beam_*
  // Multi-session cleanup (paper Fig. 3(f)): seen-through changes (strong ND of the central, weak
  // PD of the query) are clustered (points closer than ld_residue_gap_m); a cluster that fits in
  // ld_residue_length_m (its longest horizontal edge, and its top above the ground under it, which
  // must reach ld_radius_m: lower is ground the other session did not cover), and that no larger
  // cluster comes that close to, is a residue of a moving object that its session's HD removal
  // missed: the session's HD, not a change (0 = off). So is a longer cluster that each keyframe of
  // its session hit only in pieces shorter than ld_residue_length_m (a walker's trail).
  double ld_residue_gap_m = 0.5;     // [m]
  double ld_residue_length_m = 2.0;  // [m]
  // So is a cluster of any length most of whose points at most this many keyframes of its session
  // met at their place while more had them in view: one pass of a mover. Consecutive keyframes are
  // close in time (0.125 s in the simulator: a car at 9 m/s has moved 1.1 m, less than its length),
  // so two can meet a passing car at one place; a thing that stood is met by more. A session that
  // keyframes far more often (or sparser) would set it higher (lower). On 14 kept rows of the
  // scenario matrix the true objects' points were met by 4-59 keyframes at the median, seed 61's
  // residues of passing cars by 1-4 (docs/RESULTS.md).
  int ld_residue_max_hits = 2;       // [keyframes]
  bool covisible_only = false;    // true: a raw change counts only where the other session had its line
                                  // of sight at all (a return in the window); else unobserved
  std::string pairs = "central";  // central: (0, q) for every query q; consecutive: (q-1, q)
  // --- outputs
  double assign_radius_m = 60.0;       // [m] changes farther from every central keyframe ...
  double new_keyframe_dist_m = 20.0;   // [m] ... go to query keyframes this far from all central ones
  double keyframe_voxel_m = 0.0;       // [m] extra voxel for per-keyframe clouds (0 = map voxel)
  bool write_keyframes = true;         // per keyframe local clouds
  bool write_ply = true;               // PLY twins with a class field
  // --- tiles (tiles.hpp: HD removal and LD tile by tile, memory bounded by the tile)
  double tiles_edge_m = 0.0;  // [m] edge of the square world tiles; 0 = 2 x the keyframes' reach
                              //     (TileReachM: max(sensor.max_range_m, submap_radius_m))
  int tiles_max_map_points = 500000;  // [points] a tile job's map (core + margin) holds at most about this
                              //     many (~100 B each): the plan estimates every tile's map from the scans and
                              //     shrinks the edge until the largest fits (PlanTiles); an LD tile's window
                              //     holds both sessions' maps (PlanLdTiles, counted exactly); 0 = no bound
  bool tiles_stage = false;   // true: the stage's HD removal and LD run tile by tile from files (the batch;
                              //     a lifelong add: in memory, RemoveHdTiled / DetectLdTiled): the same
                              //     files, more CPU where tiles share keyframes

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
    v("pose_sigma_deg", pose_sigma_deg, "deg", 0.0, 10.0);
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
    v("hd.body_max_m", body_max_m, "m", 0.0, 100.0);
    v("ld.radius_m", ld_radius_m, "m", 0.01, 10.0);
    v("ld.rotation_sigma_deg", ld_rotation_sigma_deg, "deg", 0.0, 10.0);
    v("ld.radius_max_m", ld_radius_max_m, "m", 0.01, 10.0);
    v("ld.min_neighbors", ld_min_neighbors, "points", 1, 1000);
    v("ld.rim_frac", ld_rim_frac, "", 0.0, 1.0);
    v("ld.resolutions_deg", ld_resolutions_deg, "deg", 0.01, 10.0);
    v("ld.min_votes", ld_min_votes, "keyframes", 1, 65535);
    v("ld.min_ratio", ld_min_ratio, "", 0.0, 1.0);
    v("ld.weak_nd", weak_nd);
    v("ld.window_px", ld_window_px, "pixels", 0, 10);
    v("ld.normal_radius_m", ld_normal_radius_m, "m", 0.05, 10.0);
    v("ld.surface_max_m", ld_surface_max_m, "m", 0.0, 100.0);
    v("ld.same_min_hits", ld_same_min_hits, "keyframes", 0, 65535);
    v("ld.same_test", ld_same_test, {"beams", "pixel"});
    v("ld.beam_col_deg", ld_beam.col_deg, "deg", 0.01, 10.0);
    v("ld.beam_row_deg", ld_beam.row_deg, "deg", 0.01, 10.0);
    v("ld.beam_span_deg", ld_beam.span_deg, "deg", 0.01, 30.0);
    v("ld.beam_tol_m", ld_beam.tol_m, "m", 0.0, 10.0);
    v("ld.beam_grazing_max_m", ld_beam.grazing_max_m, "m", 0.0, 100.0);
    v("ld.residue_gap_m", ld_residue_gap_m, "m", 0.01, 10.0);
    v("ld.residue_length_m", ld_residue_length_m, "m", 0.0, 100.0);
    v("ld.residue_max_hits", ld_residue_max_hits, "keyframes", 1, 65535);
    v("ld.covisible_only", covisible_only);
    v("ld.pairs", pairs, {"central", "consecutive"});
    v("out.assign_radius_m", assign_radius_m, "m", 0.0, 1e6);
    v("out.new_keyframe_dist_m", new_keyframe_dist_m, "m", 0.0, 1e6);
    v("out.keyframe_voxel_m", keyframe_voxel_m, "m", 0.0, 10.0);
    v("out.write_keyframes", write_keyframes);
    v("out.write_ply", write_ply);
    v("tiles.edge_m", tiles_edge_m, "m", 0.0, 1e6);
    v("tiles.max_map_points", tiles_max_map_points, "points", 0, 2000000000);
    v("tiles.stage", tiles_stage);
  }
  // Range checks plus the cross-field rules (non-empty resolution lists, sensor table, ...).
  void Validate(const std::string& where = "removert config") const;
  bool SensorResolved() const { return fov_up_deg > fov_down_deg; }
  // Allowed values of sensor.model: auto, table and the presets.
  static std::vector<std::string> SensorChoices();
};

}  // namespace ltm::removert
