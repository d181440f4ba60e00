// ltmapper map: MapConfig (params_ltmap.yaml).
#pragma once

#include "ltmapper/core/core.hpp"

#include <string>

namespace ltm::map {

struct MapConfig {
  // Store encoding (fixed when the store is created; an existing store keeps its own values).
  double resolution_m = 0.001;   // coordinate quantisation step in the keyframe frame
  double intensity_step = 0.01;  // intensity quantisation step [intensity units]
  int zstd_level = 3;            // blob compression level
  // Integration.
  double nd_match_radius_m = 0.1;        // a keyframe point within this of an ND point is removed
  double new_keyframe_radius_m = 10.0;   // query keyframe with no map keyframe within -> new one
  bool store_weak_nd = false;            // keep all weak ND points in deltas (else those in the columns of strong ND)
  // Outputs.
  double meta_carve_radius_m = 0.2;      // meta map: points this close to any strong ND are carved
  double output_voxel_m = 0.1;           // voxel size of written maps (0 = every point)
  // Objects (Euclidean clustering of strong ND and PD per session step; rules in objects.cpp).
  double object_tolerance_m = 0.5;
  int object_min_points = 20;
  int object_max_points = 1000000;
  double object_ground_cell_m = 2.0;     // xy cell for the local ground height (0 = keep ground)
  double object_ground_height_m = 0.25;  // change points this close above the lowest map point
                                         // of their cell are ground, not clustered
  double object_max_extent_m = 0.0;      // clusters with a larger xy box edge are not objects (0 = off)
  double object_min_length_m = 2.0;      // clusters with a shorter longest horizontal edge are not objects
  double object_min_observed_fraction = 0.5;  // appeared: share of weak PD (reference saw the space free)
  double object_min_height_m = 0.5;      // top above the local ground
  double object_max_clearance_m = 1.0;  // lowest point above ground: higher = floating (0 = off)
  double object_sensor_step_deg = 0.0;   // [deg] the sensor's coarser angular sampling step; 0 = from the run's
                                         // sensor model (WithSensorStep: `ltmapper run`, `map objects --session`)
  double object_sensor_azimuth_step_deg = 0.0;  // [deg] the sensor's horizontal sampling step (far clusters join
                                         // columns up to 2 r x it apart); 0 = from the run's sensor model, or
                                         // unknown: columns join within object_tolerance_m only
  double object_sensor_azimuth_center_deg = 0.0;    // [deg] the sensor's horizontal field of view: its middle
  double object_sensor_azimuth_half_fov_deg = 0.0;  // [deg] and half its width (180: all around); 0 = from the
                                         // run's sensor model (estimated from the scans: a forward cone's half angle)
  double object_min_samples = 2.0;       // rows of sensor samples across the cluster's width (objects.cpp MinWidth)
  double object_flat_sigma_m = 0.05;     // thickness (std along the smallest axis) of a flat patch
  double object_flat_tilt_deg = 20.0;    // flat patches with a normal this close to vertical are ground
  double object_twin_radius_m = 1.0;     // other side's change this close = the same surface, misaligned
  double object_twin_max_fraction = 0.5; // clusters with at least this share of such points are ghosts
  double object_max_attached_fraction = 0.5;  // clusters mostly touching unchanged surfaces are fragments
  double object_merge_inside_fraction = 0.5;  // a cluster this much inside a larger one's box joins it
  double object_moved_min_dist_m = 1.0;  // ends closer than this are one object re-scanned, not moved

  template <class V>
  void Visit(V& v) {
    v("resolution_m", resolution_m, "m", 1e-4, 0.1);
    v("intensity_step", intensity_step, "", 1e-6, 100.0);
    v("zstd_level", zstd_level, "", 1, 19);
    v("nd_match_radius_m", nd_match_radius_m, "m", 1e-4, 5.0);
    v("new_keyframe_radius_m", new_keyframe_radius_m, "m", 0.1, 1000.0);
    v("store_weak_nd", store_weak_nd);
    v("meta_carve_radius_m", meta_carve_radius_m, "m", 0.0, 5.0);
    v("output_voxel_m", output_voxel_m, "m", 0.0, 10.0);
    v("object_tolerance_m", object_tolerance_m, "m", 0.01, 10.0);
    v("object_min_points", object_min_points, "", 1, 100000000);
    v("object_max_points", object_max_points, "", 1, 100000000);
    v("object_ground_cell_m", object_ground_cell_m, "m", 0.0, 100.0);
    v("object_ground_height_m", object_ground_height_m, "m", 0.0, 10.0);
    v("object_max_extent_m", object_max_extent_m, "m", 0.0, 10000.0);
    v("object_min_length_m", object_min_length_m, "m", 0.0, 10000.0);
    v("object_min_observed_fraction", object_min_observed_fraction, "", 0.0, 1.0);
    v("object_min_height_m", object_min_height_m, "m", 0.0, 100.0);
    v("object_max_clearance_m", object_max_clearance_m, "m", 0.0, 100.0);
    v("object_sensor_step_deg", object_sensor_step_deg, "deg", 0.0, 45.0);
    v("object_sensor_azimuth_step_deg", object_sensor_azimuth_step_deg, "deg", 0.0, 45.0);
    v("object_sensor_azimuth_center_deg", object_sensor_azimuth_center_deg, "deg", -180.0, 180.0);
    v("object_sensor_azimuth_half_fov_deg", object_sensor_azimuth_half_fov_deg, "deg", 0.0, 180.0);
    v("object_min_samples", object_min_samples, "", 0.0, 1000.0);
    v("object_flat_sigma_m", object_flat_sigma_m, "m", 0.0, 10.0);
    v("object_flat_tilt_deg", object_flat_tilt_deg, "deg", 0.0, 90.0);
    v("object_twin_radius_m", object_twin_radius_m, "m", 0.0, 100.0);
    v("object_twin_max_fraction", object_twin_max_fraction, "", 0.0, 1.0);
    v("object_max_attached_fraction", object_max_attached_fraction, "", 0.0, 1.0);
    v("object_merge_inside_fraction", object_merge_inside_fraction, "", 0.0, 1.0);
    v("object_moved_min_dist_m", object_moved_min_dist_m, "m", 0.0, 10000.0);
  }
};

}  // namespace ltm::map
