// The sensor model of a removert run: resolved once from the config or the scans.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>

namespace ltm::removert {

std::vector<std::string> RemovertConfig::SensorChoices() {
  std::vector<std::string> c = {"auto", "table"};
  for (const std::string& n : geometry::SensorPresetNames()) c.push_back(n);
  return c;
}

std::vector<WorldKeyframe> KeyframesOf(const Session& session) {
  std::vector<WorldKeyframe> out;
  for (const Keyframe& kf : session.keyframes) {
    WorldKeyframe w;
    w.index = kf.index;
    w.T_world_sensor = kf.T_session_sensor;
    w.cloud = kf.cloud;
    w.cloud_path = kf.cloud_path;
    w.sweep = kf.sweep;
    out.push_back(std::move(w));
  }
  return out;
}

std::vector<WorldKeyframe> LoadWorldKeyframes(const std::string& session_dir, const std::string& poses_file,
                                              std::string* name) {
  const Session sess = io::LoadSession(session_dir);
  if (name) *name = sess.name.empty() ? std::filesystem::path(session_dir).filename().string() : sess.name;
  if (poses_file.empty()) return KeyframesOf(sess);
  const std::vector<Pose> poses = io::ReadKittiPoses(poses_file);
  if (poses.size() != sess.keyframes.size())
    throw Error(poses_file, 0,
                std::to_string(poses.size()) + " poses but session " + session_dir + " has " +
                    std::to_string(sess.keyframes.size()) + " keyframes (one pose per keyframe, in order)");
  std::vector<WorldKeyframe> kfs = KeyframesOf(sess);
  for (std::size_t k = 0; k < poses.size(); ++k) kfs[k].T_world_sensor = poses[k];
  return kfs;
}

PointCloud detail::Positions(const std::vector<WorldKeyframe>& keyframes) {
  PointCloud c;
  for (const auto& kf : keyframes) {
    const Eigen::Vector3d t = kf.T_world_sensor.translation();
    c.push_back(float(t.x()), float(t.y()), float(t.z()));
  }
  return c;
}

RemovertConfig WithSensor(const RemovertConfig& cfg, const std::vector<WorldKeyframe>& keyframes) {
  if (cfg.SensorResolved()) return cfg;
  constexpr std::size_t kEstimateScans = 8;  // enough points for every beam's peak
  std::vector<PointCloud> scans;
  if (cfg.sensor == "auto") {
    const std::size_t n = std::min(kEstimateScans, keyframes.size());
    // The scans as the range images see them (a raw sweep's in its firing frames: the beams' own
    // elevations; LoadVoterScan).
    for (std::size_t k = 0; k < n; ++k)
      scans.push_back(*detail::LoadVoterScan(keyframes[k * keyframes.size() / n], nullptr));
  }
  RemovertConfig out = cfg;
  out.sensor_model = geometry::ResolveSensor(cfg.sensor, cfg.sensor_elevations_deg, scans, "sensor");
  const geometry::SensorModel& m = out.sensor_model;
  // One beam spacing beyond the outer beams: their returns land inside the images.
  out.fov_up_deg = std::min(89.9, m.fov_up_deg + m.SpacingAt(m.fov_up_deg));
  out.fov_down_deg = std::max(-89.9, m.fov_down_deg - m.SpacingAt(m.fov_down_deg));
  spdlog::info("removert sensor {}", m.Describe());
  return out;
}

}  // namespace ltm::removert
