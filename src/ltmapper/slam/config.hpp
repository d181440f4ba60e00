// ltmapper slam: SlamConfig (params_ltslam.yaml).
#pragma once

#include "ltmapper/core/core.hpp"

#include <string>
#include <vector>

namespace ltm::slam {

struct SlamConfig {
  // --- Scan Context (Kim & Kim 2018; defaults of the original code)
  int sc_rings = 20;                  // radial bins
  int sc_sectors = 60;                // azimuth bins
  double sc_max_range_m = 80.0;       // points farther than this (in xy) are ignored
  double sc_lidar_height_m = 2.0;     // bin value = max(z + height): height above the ground
  int sc_candidates = 10;             // top-k ring-key neighbours compared per query keyframe
  double sc_search_ratio = 0.1;       // fine shift search window, fraction of the sectors
  // No fixed distance threshold: per session pair, a candidate must beat the median of that
  // pair's best distances (one per query keyframe), and the pair's budget goes to the lowest.
  int sc_per_query = 3;               // candidates kept per query keyframe: the best and ...
  double sc_close_ratio = 0.1;        // ... others within (1 + this) x the best distance
  bool sc_read_files = true;          // use <session>/SCDs/NNNNNN.scd when present
  int sc_max_loops_per_pair = 30;     // registrations per session pair and round, lowest first
  int sc_min_gap_keyframes = 1;       // min gap between the query keyframes of selected candidates
  int sc_retry_rounds = 3;            // unaligned sessions: rounds of the next-ranked candidates
  // --- global registration: fallback for sessions still unaligned after the retries
  bool global_enabled = true;         // FPFH + RANSAC placements of query submaps in aligned maps
  int global_queries = 12;            // query keyframes tried per unaligned session and reference

  // --- registration (GICP between keyframe submaps, gicp.cpp)
  double reg_min_range_m = 1.0;       // scan points closer than this are dropped (the vehicle)
  double reg_max_range_m = 60.0;      // scan points farther than this are dropped
  double reg_voxel_m = 0.5;           // voxel of keyframe clouds and submaps
  int reg_submap_neighbours = 1;      // keyframes on each side merged into a submap
  double reg_cache_mb = 64.0;         // downsampled keyframe clouds kept for reuse (least recently used
                                      // dropped beyond it, read again when needed): memory vs rereads
  double reg_coarse_voxel_m = 1.0;    // coarse stage (Scan Context gives no translation) ...
  double reg_coarse_correspondence_m = 8.0;  // ... with this correspondence distance; 0 = off
  double reg_max_correspondence_m = 1.0;  // fine GICP correspondence distance
  int reg_max_iterations = 30;        // GICP outer iterations
  int reg_covariance_neighbours = 20; // k for GICP point covariances
  // Verification (see RegisterGicp): the inlier radius derives from the voxel and the range noise;
  // inlier ratio >= min_overlap and residuals along the surface normals that the surfaces' own
  // spread and the range noise explain (no tail beyond 3 sigma) accept a loop.
  double reg_range_noise_m = 0.02;    // std-dev of the sensor's range noise
  double reg_min_overlap = 0.3;       // min inlier ratio (source points with a NN within radius)
  double reg_max_correction_deg = 45.0;  // reject when GICP rotates this far from the initial guess
  // Reject when GICP moves this far from the initial guess. Not a key: AlignSessions derives it
  // (the farthest distance at which the sessions' own keyframes still overlap by reg_min_overlap).
  double reg_max_translation_m = 15.0;
  double loop_sigma_t_m = 0.1;        // loop std-dev at fitness <= reg_fitness_floor
  double loop_sigma_r_deg = 0.5;
  double reg_fitness_floor = 0.02;    // [m^2]; sigma grows with sqrt(fitness / floor) above it
  bool reg_steps = true;              // register each keyframe onto the one before (WithRegisteredSteps)

  // --- pose graph (Ceres)
  double odom_sigma_t_m = 0.05;       // odometry std-dev when the g2o carries no information
  double odom_sigma_r_deg = 0.2;
  bool use_g2o_information = true;    // use the g2o edge information when present
  std::string robust_loss = "cauchy"; // cauchy | dcs | none, on every inter-session loop
  double robust_scale = 1.0;          // Cauchy scale / DCS Phi, in whitened units
  int solver_max_iterations = 100;
  int min_loops = 3;                  // consistent loops needed to call a query aligned
  bool gate_inconsistent_loops = true;  // drop loops whose implied anchor disagrees with consensus
  double consensus_t_m = 4.0;         // implied anchors agree within this ...
  double consensus_r_deg = 5.0;
  double consensus_drift_ratio = 0.03;  // ... plus this fraction of the path between the loops
  double outlier_t_m = 1.0;           // after optimisation, loops with larger residual are rejected
  double outlier_r_deg = 3.0;

  // --- radius-search refinement (paper: "radius search loop detection" after the SC loops)
  int refine_rounds = 2;
  // The search radius is derived: where the sessions' own keyframes stop overlapping by
  // reg_min_overlap (multi_session.cpp OverlapReach; reported as refine_radius_m).
  int refine_stride = 3;              // try every n-th query keyframe without a loop
  int refine_max_loops_per_pair = 100;
  // Not a key: whether the central session's keyframes look for loops within it too (multi_session.cpp
  // RadiusCandidates with a == b); false where its poses are the world already (lifelong add's reference).
  bool central_own_loops = true;

  template <class V>
  void Visit(V& v) {
    v("sc.rings", sc_rings, "bins", 1, 1000);
    v("sc.sectors", sc_sectors, "bins", 4, 3600);
    v("sc.max_range_m", sc_max_range_m, "m", 1.0, 1000.0);
    v("sc.lidar_height_m", sc_lidar_height_m, "m", -10.0, 10.0);
    v("sc.candidates", sc_candidates, "keyframes", 1, 1000);
    v("sc.search_ratio", sc_search_ratio, "fraction", 0.0, 1.0);
    v("sc.per_query", sc_per_query, "candidates", 1, 1000);
    v("sc.close_ratio", sc_close_ratio, "fraction", 0.0, 10.0);
    v("sc.read_files", sc_read_files);
    v("sc.max_loops_per_pair", sc_max_loops_per_pair, "loops", 0, 1000000);
    v("sc.min_gap_keyframes", sc_min_gap_keyframes, "keyframes", 0, 1000000);
    v("sc.retry_rounds", sc_retry_rounds, "rounds", 0, 100);
    v("global.enabled", global_enabled);
    v("global.queries", global_queries, "keyframes", 1, 100000);
    v("registration.min_range_m", reg_min_range_m, "m", 0.0, 100.0);
    v("registration.max_range_m", reg_max_range_m, "m", 1.0, 1000.0);
    v("registration.voxel_m", reg_voxel_m, "m", 0.01, 10.0);
    v("registration.submap_neighbours", reg_submap_neighbours, "keyframes", 0, 100);
    v("registration.cache_mb", reg_cache_mb, "MB", 0.01, 1e6);
    v("registration.coarse_voxel_m", reg_coarse_voxel_m, "m", 0.01, 20.0);
    v("registration.coarse_correspondence_m", reg_coarse_correspondence_m, "m", 0.0, 200.0);
    v("registration.max_correspondence_m", reg_max_correspondence_m, "m", 0.01, 100.0);
    v("registration.max_iterations", reg_max_iterations, "iterations", 1, 1000);
    v("registration.covariance_neighbours", reg_covariance_neighbours, "points", 5, 100);
    v("registration.range_noise_m", reg_range_noise_m, "m", 0.0, 10.0);
    v("registration.min_overlap", reg_min_overlap, "fraction", 0.0, 1.0);
    v("registration.max_correction_deg", reg_max_correction_deg, "deg", 0.0, 180.0);
    v("registration.loop_sigma_t_m", loop_sigma_t_m, "m", 1e-4, 100.0);
    v("registration.loop_sigma_r_deg", loop_sigma_r_deg, "deg", 1e-4, 180.0);
    v("registration.fitness_floor", reg_fitness_floor, "m^2", 1e-6, 100.0);
    v("registration.steps", reg_steps);
    v("graph.odom_sigma_t_m", odom_sigma_t_m, "m", 1e-5, 100.0);
    v("graph.odom_sigma_r_deg", odom_sigma_r_deg, "deg", 1e-5, 180.0);
    v("graph.use_g2o_information", use_g2o_information);
    v("graph.robust_loss", robust_loss, {"cauchy", "dcs", "none"});
    v("graph.robust_scale", robust_scale, "whitened", 1e-3, 1e3);
    v("graph.solver_max_iterations", solver_max_iterations, "iterations", 1, 10000);
    v("graph.min_loops", min_loops, "loops", 1, 100000);
    v("graph.gate_inconsistent_loops", gate_inconsistent_loops);
    v("graph.consensus_t_m", consensus_t_m, "m", 0.0, 1e4);
    v("graph.consensus_r_deg", consensus_r_deg, "deg", 0.0, 180.0);
    v("graph.consensus_drift_ratio", consensus_drift_ratio, "m/m", 0.0, 1.0);
    v("graph.outlier_t_m", outlier_t_m, "m", 0.0, 1e6);
    v("graph.outlier_r_deg", outlier_r_deg, "deg", 0.0, 360.0);
    v("refine.rounds", refine_rounds, "rounds", 0, 100);
    v("refine.stride", refine_stride, "keyframes", 1, 100000);
    v("refine.max_loops_per_pair", refine_max_loops_per_pair, "loops", 0, 1000000);
  }
};

}  // namespace ltm::slam
