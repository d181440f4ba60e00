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

namespace {
constexpr std::size_t kEstimateScans = 8;  // enough points for every beam's peak

// The beams that tell their returns on a sensor estimated from `scans` (0 when none can be).
int BeamsThatTell(const std::vector<PointCloud>& scans) {
  try {
    return detail::ColumnImage::BeamsThatTell(geometry::EstimateSensor(scans));
  } catch (const Error&) {  // too few points to show beams
    return 0;
  }
}

// When the columns of the deskewed `scans` of `picks` fired (detail::EstimateSweepTiming), kept
// when the scans re-skewed with it make more beams tell their returns than as they are; *scans
// are then re-skewed. Unknown for raw sweeps and sessions without keyframe times.
SweepTiming TimingOf(const std::vector<const WorldKeyframe*>& picks, double min_range_m,
                     std::vector<PointCloud>* scans) {
  std::vector<SweepMotion> motions;
  for (std::size_t k = 0; k < picks.size(); ++k) {
    if (!picks[k]->sweep.known || !(*scans)[k].time.empty()) return {};
    motions.push_back(picks[k]->sweep);
  }
  const SweepTiming t = detail::EstimateSweepTiming(*scans, motions, min_range_m);
  if (!t.known) return {};
  std::vector<PointCloud> reskewed;
  for (std::size_t k = 0; k < picks.size(); ++k) reskewed.push_back(io::Reskew((*scans)[k], motions[k], t));
  const int before = BeamsThatTell(*scans), after = BeamsThatTell(reskewed);
  spdlog::info("removert sweep timing of the deskewed scans estimated: period {:.3f} s, first column at {:+.1f} deg, "
               "azimuth {} with time, timestamp after {:.2f} of the sweep; re-skewed, {} beams tell their returns "
               "(as deskewed {}){}",
               t.period_s, t.start_rad * 180.0 / 3.141592653589793, t.turn > 0 ? "decreasing" : "increasing",
               t.stamp_share, after, before, after > before ? "" : ": not used");
  if (after <= before) return {};
  *scans = std::move(reskewed);
  return t;
}
}  // namespace

RemovertConfig WithSensor(const RemovertConfig& cfg, const std::vector<WorldKeyframe>& keyframes) {
  if (cfg.SensorResolved()) return cfg;
  std::vector<const WorldKeyframe*> picks;  // spread over the session
  const std::size_t n = std::min(kEstimateScans, keyframes.size());
  for (std::size_t k = 0; k < n; ++k) picks.push_back(&keyframes[k * keyframes.size() / n]);
  const bool timed = std::all_of(picks.begin(), picks.end(), [](const WorldKeyframe* kf) { return kf->sweep.known; });
  // The scans as the range images see them (a raw sweep's in its firing frames: the beams' own
  // elevations; LoadVoterScan), deskewed ones put back there when their timing is found.
  std::vector<PointCloud> scans;
  if (cfg.sensor == "auto" || timed)
    for (const WorldKeyframe* kf : picks) scans.push_back(*detail::LoadVoterScan(*kf, SweepTiming{}, nullptr));
  RemovertConfig out = cfg;
  if (timed && !picks.empty()) out.sweep_timing = TimingOf(picks, cfg.min_range_m, &scans);
  if (cfg.sensor != "auto") scans.clear();
  out.sensor_model = geometry::ResolveSensor(cfg.sensor, cfg.sensor_elevations_deg, scans, "sensor");
  const geometry::SensorModel& m = out.sensor_model;
  // One beam spacing beyond the outer beams: their returns land inside the images.
  out.fov_up_deg = std::min(89.9, m.fov_up_deg + m.SpacingAt(m.fov_up_deg));
  out.fov_down_deg = std::max(-89.9, m.fov_down_deg - m.SpacingAt(m.fov_down_deg));
  spdlog::info("removert sensor {}", m.Describe());
  return out;
}

}  // namespace ltm::removert
