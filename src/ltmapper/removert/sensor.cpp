// The sensor model of a removert run: resolved once from the config or the scans.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/io/io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <deque>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <string_view>

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

// The sensor estimated from `scans`; none (no beams) when they hold too few points to show them.
geometry::SensorModel EstimatedOrNone(const std::vector<PointCloud>& scans) {
  try {
    return geometry::EstimateSensor(scans);
  } catch (const Error&) {
    geometry::SensorModel none;
    none.ring_based = false;
    return none;
  }
}

// When the columns of the deskewed `scans` of `picks` fired (detail::EstimateSweepTiming), kept
// when the scans re-skewed with it make a larger share of the beams found tell their returns than
// as they are; *scans are then re-skewed. Unknown for raw sweeps and sessions without keyframe times.
SweepTiming TimingOf(const std::vector<const WorldKeyframe*>& picks, double min_range_m, int threads,
                     std::vector<PointCloud>* scans) {
  std::vector<SweepMotion> motions;
  for (std::size_t k = 0; k < picks.size(); ++k) {
    if (!picks[k]->sweep.known || !(*scans)[k].time.empty()) return {};
    motions.push_back(picks[k]->sweep);
  }
  const SweepTiming t = detail::EstimateSweepTiming(*scans, motions, min_range_m, threads);
  if (!t.known) return {};
  std::vector<PointCloud> reskewed;
  for (std::size_t k = 0; k < picks.size(); ++k) reskewed.push_back(io::Reskew((*scans)[k], motions[k], t));
  // Compared as shares of the beams found: a few returns at the seam mistimed may add clusters
  // of their own, "beams" that tell.
  const geometry::SensorModel as_is = EstimatedOrNone(*scans), back = EstimatedOrNone(reskewed);
  const int before = detail::ColumnImage::BeamsThatTell(as_is), after = detail::ColumnImage::BeamsThatTell(back);
  const bool better =
      double(after) * double(std::max(1, as_is.beams())) > double(before) * double(std::max(1, back.beams()));
  spdlog::info("removert sweep timing of the deskewed scans estimated: period {:.3f} s, first column at {:+.1f} deg, "
               "azimuth {} with time, timestamp after {:.2f} of the sweep; re-skewed, {} of {} beams tell their "
               "returns, spread {:.3f} deg (as deskewed {} of {}, {:.3f} deg){}",
               t.period_s, t.start_rad / kRadPerDeg, t.turn > 0 ? "decreasing" : "increasing", t.stamp_share, after,
               back.beams(), back.spread_deg, before, as_is.beams(), as_is.spread_deg, better ? "" : ": not used");
  if (!better) return {};
  *scans = std::move(reskewed);
  return t;
}

// The sensors resolved in this process, by their inputs: a run resolves the central session's in
// each stage (HD, LD, the map's objects), the same function of the same scans. The key hashes the
// config's sensor keys and each scan's bytes and motion; the last kRemembered are kept.
struct Resolved {
  std::size_t key = 0;
  SweepTiming timing;
  geometry::SensorModel model;
};
constexpr std::size_t kRemembered = 8;
std::mutex remembered_mutex;
std::deque<Resolved> remembered;

template <class T>
std::size_t HashBytes(const std::vector<T>& v) {
  return std::hash<std::string_view>()(std::string_view(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T)));
}
std::size_t KeyOf(const RemovertConfig& cfg, const std::vector<const WorldKeyframe*>& picks,
                  const std::vector<PointCloud>& scans) {
  std::size_t key = std::hash<std::string>()(cfg.sensor);
  const auto mix = [&](std::size_t h) { key ^= h + 0x9e3779b97f4a7c15ull + (key << 6) + (key >> 2); };
  mix(HashBytes(cfg.sensor_elevations_deg));
  mix(std::hash<double>()(cfg.min_range_m));
  for (std::size_t k = 0; k < scans.size(); ++k) {
    mix(HashBytes(scans[k].points));
    mix(HashBytes(scans[k].time));
    const SweepMotion& m = picks[k]->sweep;
    mix(HashBytes(std::vector<double>{double(m.known), m.v_mps.x(), m.v_mps.y(), m.v_mps.z(), m.w_radps.x(),
                                      m.w_radps.y(), m.w_radps.z()}));
  }
  return key;
}
std::optional<Resolved> Remembered(std::size_t key) {
  std::lock_guard<std::mutex> lock(remembered_mutex);
  for (const Resolved& r : remembered)
    if (r.key == key) return r;
  return std::nullopt;
}
void Remember(const Resolved& r) {
  std::lock_guard<std::mutex> lock(remembered_mutex);
  remembered.push_back(r);
  if (remembered.size() > kRemembered) remembered.pop_front();
}

// The timing and the sensor of the picks' `scans` as LoadVoterScan reads them (none: the preset or
// table alone), or those resolved before from the same (*before).
Resolved Resolve(const RemovertConfig& cfg, const std::vector<const WorldKeyframe*>& picks, bool timed,
                 std::vector<PointCloud> scans, int threads, bool* before) {
  const bool estimated = !scans.empty();
  const std::size_t key = estimated ? KeyOf(cfg, picks, scans) : 0;
  if (std::optional<Resolved> r = estimated ? Remembered(key) : std::nullopt) {
    *before = true;
    return *r;
  }
  Resolved r{key, {}, {}};
  if (timed && !picks.empty()) r.timing = TimingOf(picks, cfg.min_range_m, threads, &scans);
  if (cfg.sensor != "auto") scans.clear();
  r.model = geometry::ResolveSensor(cfg.sensor, cfg.sensor_elevations_deg, scans, "sensor");
  if (estimated) Remember(r);
  return r;
}
}  // namespace

RemovertConfig WithSensor(const RemovertConfig& cfg, const std::vector<WorldKeyframe>& keyframes, int threads) {
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
  bool before = false;
  const Resolved r = Resolve(cfg, picks, timed, std::move(scans), threads, &before);
  out.sweep_timing = r.timing;
  out.sensor_model = r.model;
  const geometry::SensorModel& m = out.sensor_model;
  // One beam spacing beyond the outer beams: their returns land inside the images.
  out.fov_up_deg = std::min(89.9, m.fov_up_deg + m.SpacingAt(m.fov_up_deg));
  out.fov_down_deg = std::max(-89.9, m.fov_down_deg - m.SpacingAt(m.fov_down_deg));
  spdlog::info("removert sensor {}{}", m.Describe(), before ? " (resolved before, from the same scans)" : "");
  return out;
}

}  // namespace ltm::removert
