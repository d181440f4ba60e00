// What `run` and `add` share inside the pipeline module: the run's paths, the stage configs,
// the resume keys and markers, the map export. Not a public header.
#pragma once

#include "ltmapper/map/map.hpp"
#include "ltmapper/pipeline/pipeline.hpp"
#include "ltmapper/removert/removert.hpp"
#include "ltmapper/slam/slam.hpp"

#include <chrono>
#include <string>
#include <vector>

namespace ltm::pipeline::detail {

double Since(std::chrono::steady_clock::time_point t0);
std::string SessionName(const std::string& dir);  // a session folder's name (= its output folder)

// Stage outputs of one run (io::layout names).
struct RunPaths {
  std::string aligned, changes, store, live, meta, objects;
  RunPaths(const std::string& out, const RunConfig& cfg);
};

// The three stages' resolved configs (each loaded, validated and printed once).
struct StageConfigs {
  slam::SlamConfig slam;
  removert::RemovertConfig removert;
  map::MapConfig map;
  explicit StageConfigs(const RunConfig& cfg);
};

// Resume markers of the three stages and their keys for a list of session folders (run order).
// The keys hold the code id: a rebuilt ltmapper never takes an older build's outputs as its own.
// With world poses given (`run --poses`) the first key also holds those files' digests (LT-SLAM's
// config stays in it: the given poses' measure registers loops with it).
std::vector<std::string> StageMarkers(const RunPaths& p);
std::vector<std::string> StageKeys(const RunConfig& cfg, const StageConfigs& sc,
                                   const std::vector<std::string>& session_dirs,
                                   const std::vector<std::string>& world_poses = {});

// Given poses whose measured rotation error exceeds LD's prior (pose_sigma_deg): a warning per
// session, as LD's tolerances widen with it and find fewer changes.
void WarnRoughPoses(const slam::SessionAlignment& a, const removert::RemovertConfig& cfg);

// live.pcd, meta.pcd and objects/ from the store (objects with the central session's sensor).
void ExportMaps(const RunPaths& p, const StageConfigs& sc, const std::string& central_dir, bool export_maps,
                int threads);
struct MapFigures {
  std::uint64_t store_bytes = 0;
  std::size_t live = 0, meta = 0, objects = 0;
};
MapFigures ReadMapFigures(const RunPaths& p, const map::MapConfig& map_cfg, bool export_maps);
// What a run or add report ends with: the map's figures, the total time since t0, peak memory.
template <class Report>
void FinishReport(Report& r, const MapFigures& fig, std::chrono::steady_clock::time_point t0) {
  r.store_bytes = fig.store_bytes;
  r.map_points_live = fig.live;
  r.objects = fig.objects;
  r.seconds = Since(t0);
  r.peak_rss_bytes = PeakRssBytes();
}

}  // namespace ltm::pipeline::detail
