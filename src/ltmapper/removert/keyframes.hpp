// ltmapper removert: keyframes placed in the world, and the sensor resolved from their scans.
#pragma once

#include "ltmapper/removert/config.hpp"

#include <memory>
#include <string>
#include <vector>

namespace ltm::removert {

// A keyframe placed in the world: its scan (sensor frame) is either in memory (`cloud`) or read
// on demand from `cloud_path` (.pcd / .bin).
struct WorldKeyframe {
  int index = 0;
  Pose T_world_sensor = Pose::Identity();
  std::shared_ptr<const PointCloud> cloud;
  std::string cloud_path;
  SweepMotion sweep;  // deskews a raw sweep read from cloud_path (io::ReadScan)
};

// A session's keyframes placed with its own poses (T_session_sensor as the world frame): HD
// removal of one drive, e.g. a KTH DynamicMap sequence whose poses are already in its world.
std::vector<WorldKeyframe> KeyframesOf(const Session& session);
// A session folder's keyframes (scans read on demand) placed with the world poses of a KITTI pose
// file (one per keyframe, in order; ltm::Error naming the file otherwise), or with the session's
// own poses when `poses_file` is empty. `name` (optional): the session's name.
std::vector<WorldKeyframe> LoadWorldKeyframes(const std::string& session_dir, const std::string& poses_file,
                                              std::string* name = nullptr);

// The config with its sensor resolved (sensor_model, fov_*_deg): the preset or table, else
// estimated from up to 8 of the keyframes' scans (spread over the session). A resolved config is
// returned unchanged; every entry point below calls it, so callers may pass either. The estimates
// run on `threads` workers (0: all cores).
RemovertConfig WithSensor(const RemovertConfig& cfg, const std::vector<WorldKeyframe>& keyframes, int threads = 0);

}  // namespace ltm::removert
