// ltmapper sensor model: what a LiDAR samples, so that every stage derives its range-image rows,
// resolutions and tolerances from the sensor in the data instead of hand-tuned degrees.
//
// Three ways to get one, in this order (ResolveSensor):
//   1. a preset name (the real beam tables of common sensors: SensorPresetNames()) or an explicit
//      per-beam elevation table from the params file;
//   2. estimated from the scans (EstimateSensor): a histogram of point elevations over a few scans;
//      on a ring sensor every beam is a narrow peak (its elevation), the gaps between them empty;
//      a scanner without rings (Livox-style rosette) fills the histogram and gets a uniform grid
//      whose resolution follows the measured angular point density;
//   3. otherwise a clear error.
#pragma once

#include "ltmapper/core/core.hpp"

#include <algorithm>
#include <string>
#include <vector>

namespace ltm::geometry {

struct SensorModel {
  std::string source;                  // preset name, "table" or "estimated"
  bool ring_based = true;              // false: non-repetitive pattern (no beams)
  std::vector<double> elevations_deg;  // [deg] per beam, top beam first (strictly decreasing)
  double azimuth_step_deg = 0.0;       // [deg] horizontal step between columns (0 = unknown)
  double grid_deg = 0.0;               // [deg] non-repetitive: angular spacing of the points
  double fov_up_deg = 0.0;             // [deg] highest elevation sampled
  double fov_down_deg = 0.0;           // [deg] lowest elevation sampled
  double spread_deg = 0.0;             // [deg] estimated: scatter of point elevations about their beam (RMS
                                       // from the histogram; robust sigma from the point order)
  double azimuth_center_deg = 0.0;     // [deg] middle of the horizontal field of view (sensor frame, from +x)
  double azimuth_half_fov_deg = 180.0; // [deg] half its width: 180 all around; estimated: the azimuths with
                                       // returns (a forward cone: its half angle)

  // Whether a direction at azimuth `azimuth_deg` (sensor frame) lies in the horizontal field of view.
  bool InAzimuthView(double azimuth_deg) const;

  int beams() const { return int(elevations_deg.size()); }
  // Elevation gap between the two beams around `elevation_deg` (the grid for non-repetitive
  // scanners; beyond the outer beams the outermost gap).
  double SpacingAt(double elevation_deg) const;
  // The largest gap between neighbouring beams (the grid for non-repetitive scanners): the
  // coarsest vertical sampling anywhere in the field of view.
  double MaxSpacing() const;
  // The median gap between neighbouring beams (the grid for non-repetitive scanners).
  double MedianSpacing() const;
  // The coarser of the beam gap at the horizon and the azimuth step: how far apart a far
  // surface's samples lie at most along its rows or its columns (clustering gaps).
  double CoarserStepDeg() const { return std::max(SpacingAt(0.0), azimuth_step_deg); }
  // One line for logs: "hdl32e: 32 beams +10.67 .. -30.67 deg, spacing 1.33 (max 1.33) deg, ...".
  std::string Describe() const;
};

// Whether azimuth `azimuth_deg` lies within `half_deg` of `center_deg` (across the wrap at +-180;
// a half of 180 or more: every azimuth).
bool InAzimuthArc(double azimuth_deg, double center_deg, double half_deg);

// Names of the presets ("vlp16", "hdl32e", "vlp32c", "hdl64e", "os1-64", "os1-128", "pandar64",
// "sim64": the simulator's default uniform 64 beams, +15 / -25 deg).
std::vector<std::string> SensorPresetNames();
// The preset's real beam table; ltm::Error naming the known presets when `name` is unknown.
SensorModel SensorPreset(const std::string& name);
// A model from an explicit elevation table (any order; sorted top first). ltm::Error naming
// `key` when the table has fewer than 2 beams, repeats an elevation or lies outside +-90 deg.
SensorModel SensorFromTable(const std::vector<double>& elevations_deg, double azimuth_step_deg,
                            const std::string& key);

struct SensorEstimateOptions {
  double min_range_m = 3.0;     // [m] nearer points are skipped (vertical offsets of the lasers
                                //     inside the housing bend their elevation at short range)
  double bin_deg = 0.02;        // [deg] elevation histogram bin (well below any beam spacing)
  double ring_fill_max = 0.5;   // [-] a ring sensor's peaks fill at most this share of the
                                //     elevation span (gaps between beams are empty)
};
// Estimates the sensor from scans in the sensor frame (a few are enough). ltm::Error when there
// are too few finite points beyond min_range_m to tell.
SensorModel EstimateSensor(const std::vector<PointCloud>& scans, const SensorEstimateOptions& opt = {});

// The sensor for a stage's config keys `<key>.model` ("auto", a preset name, or "table" with
// `<key>.elevations_deg`): preset / table first, else estimated from `scans` (which may be empty
// only when no estimate is needed). Errors name the keys.
SensorModel ResolveSensor(const std::string& sensor, const std::vector<double>& elevations_deg,
                          const std::vector<PointCloud>& scans, const std::string& key);

}  // namespace ltm::geometry
