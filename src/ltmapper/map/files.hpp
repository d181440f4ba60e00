// ltmapper map: the store's blob codec, reading the stage folders (LT-SLAM / LT-removert
// outputs) into the store, and the files written from it.
#pragma once

#include "ltmapper/map/store.hpp"
#include "ltmapper/geometry/sensor.hpp"

#include <functional>
#include <string>
#include <vector>

namespace ltm::map {

// The store's blob codec on a cloud (cls / session arrays kept when present): coordinates
// quantised to `resolution_m` (error <= resolution/2), intensity to `intensity_step`, zstd, and an
// FNV-1a 64 checksum verified by DecodeBlob (ltm::Error naming `what` on any mismatch).
std::string EncodeBlob(const PointCloud& cloud, double resolution_m, double intensity_step,
                       int zstd_level = 3);
PointCloud DecodeBlob(const std::string& blob, const std::string& what = "blob");

// ------------------------------------------------------------------------------- file layer
// Reads LT-SLAM (aligned/<s>/poses_world.txt, anchor.txt) and LT-removert (changes/pair_<c>_<q>/
// keyframes/NNNNNN/*.pcd, changes/<s>/static_map.pcd) outputs as in docs/FORMATS.md.
struct PipelineDirs {
  std::string aligned;   // LT-SLAM output
  std::string changes;   // LT-removert output
  std::string sessions;  // optional: input session dirs (maps keyframe index -> pose line)
};
// Aligned session names in run order, from the run manifest (io::ReadRunManifest); without a
// manifest (folders made by hand), the aligned folders sorted by name, `central` moved first.
// With a manifest, a `central` other than the run's first session is an error.
std::vector<std::string> AlignedSessions(const PipelineDirs& dirs, const std::string& central = "");
// Creates `store_path` atomically (temporary file, then rename) with the central session as base.
IntegrationResult InitFromDirs(const std::string& store_path, const MapConfig& cfg,
                               const PipelineDirs& dirs, const std::string& central, int threads = 0);
// Integrates one query session from the pair directory central -> query.
IntegrationResult IntegrateFromDirs(Store& store, const PipelineDirs& dirs, const std::string& query);

// ------------------------------------------------------------------------------------ outputs
// Writes .pcd (x y z intensity class session object fields) or .ply by extension, atomically.
void WriteLabelledCloud(const std::string& path, const PointCloud& cloud);
// The same for a cloud that arrives in parts (`parts(sink)` hands each to sink, e.g. a Store's
// StreamLive), voxelised at voxel_m (0: every point). A .pcd is written as the parts come; with a
// voxel they are first spilled into 32 m world tiles (whole voxels) in a folder next to `path`
// and each tile is voxelised alone: memory is a tile, not the map, and the points are those of
// VoxelDownsample on the whole (in tile order). A .ply is assembled in memory. Returns the points.
std::size_t WriteLabelledCloudParts(const std::string& path, double voxel_m,
                                    const std::function<void(const PartSink&)>& parts, int threads = 0);
// objects.csv, objects.json, objects.ply (all points with object ids), clouds/object_NNNN.pcd.
// With `rejected`, also rejected.csv (same columns plus `reason`, no clouds).
// The config with object_sensor_step_deg taken from the sensor when it is 0: the beam spacing at
// the horizon (where a vehicle sees objects) or the azimuth step, whichever is coarser; and
// object_sensor_azimuth_step_deg when it is 0: the azimuth step; object_sensor_azimuth_half_fov_deg
// (with its centre) when it is 0: the horizontal field of view.
MapConfig WithSensorStep(MapConfig cfg, const geometry::SensorModel& sensor);
void WriteObjects(const std::string& dir, const std::vector<MapObject>& objects,
                  const std::vector<MapObject>* rejected = nullptr);
// Human-readable `log` table.
std::string FormatLog(const Store& store);

}  // namespace ltm::map
