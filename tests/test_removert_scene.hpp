// Tiny analytic scenes for the removert tests: ground plane + axis-aligned boxes, ray cast by a
// spinning LiDAR model, every return labelled with the box (or ground) it hit.
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace ltm::test {

struct Box {
  Eigen::Vector3d lo, hi;
  int id = 0;  // label written into PointCloud::object of hits
};

struct Lidar {
  int beams = 64;
  double fov_up_deg = 2.0, fov_down_deg = -24.8;
  int cols = 900;  // 0.4 deg
  double max_range = 80.0;
};

// The removert config for scans of `lidar`: its beam table given explicitly (sensor.model:
// table), resolved, as a user of that sensor would write it.
inline removert::RemovertConfig ConfigFor(const Lidar& lidar = {}) {
  removert::RemovertConfig cfg;
  cfg.sensor = "table";
  for (int b = 0; b < lidar.beams; ++b)
    cfg.sensor_elevations_deg.push_back(lidar.fov_up_deg - b * (lidar.fov_up_deg - lidar.fov_down_deg) / (lidar.beams - 1));
  // The scenes' poses are exact; LD's tolerances get the rotation uncertainty LT-SLAM measures on
  // the simulated drives (0.06-0.08 deg), not the pose_sigma_deg prior of poses given without it.
  cfg.ld_rotation_sigma_deg = 0.1;
  return removert::WithSensor(cfg, {});
}

// ConfigFor a ring sensor that fires every beam at each of its `cols` azimuth steps (its beams tell
// their returns: the beam tests that read a beam's empty cells, PassedWithoutReturn and kin).
inline removert::RemovertConfig RingConfigFor(const Lidar& lidar) {
  removert::RemovertConfig cfg = ConfigFor(lidar);
  cfg.sensor_model.azimuth_step_deg = 360.0 / lidar.cols;
  return cfg;
}

// Ray / box slab test: entry distance t > 0 or +inf.
inline double HitBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Box& b) {
  double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(d[a]) < 1e-12) {
      if (o[a] < b.lo[a] || o[a] > b.hi[a]) return std::numeric_limits<double>::infinity();
      continue;
    }
    double ta = (b.lo[a] - o[a]) / d[a], tb = (b.hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return std::numeric_limits<double>::infinity();
  }
  return t0 > 1e-9 ? t0 : std::numeric_limits<double>::infinity();
}

// Scan in the sensor frame (sensor at T_world_sensor, axes aligned with world up) along the unit
// directions `dirs` (sensor frame). Ground z = 0 has object id -1; boxes their id. `object` holds
// the label.
inline PointCloud CastDirections(const Pose& T_world_sensor, const std::vector<Box>& boxes,
                                 const std::vector<Eigen::Vector3d>& dirs, double max_range) {
  PointCloud scan;
  const Eigen::Vector3d o = T_world_sensor.translation();
  const Eigen::Matrix3d R = T_world_sensor.linear();
  for (const Eigen::Vector3d& ds : dirs) {
    const Eigen::Vector3d dw = R * ds;
    double best = max_range;
    int label = -2;
    if (dw.z() < -1e-9) {
      const double tg = -o.z() / dw.z();
      if (tg < best) best = tg, label = -1;
    }
    for (const Box& bx : boxes) {
      const double t = HitBox(o, dw, bx);
      if (t < best) best = t, label = bx.id;
    }
    if (label == -2) continue;
    const Eigen::Vector3d p = ds * best;
    scan.push_back(float(p.x()), float(p.y()), float(p.z()));
    scan.object.push_back(label);
  }
  return scan;
}

// Unit direction at elevation / azimuth [rad].
inline Eigen::Vector3d Direction(double el, double az) {
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

// A spinning LiDAR's scan: L.beams rings x L.cols columns.
inline PointCloud CastScan(const Pose& T_world_sensor, const std::vector<Box>& boxes, const Lidar& L) {
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  std::vector<Eigen::Vector3d> dirs;
  dirs.reserve(std::size_t(L.beams) * std::size_t(L.cols));
  for (int b = 0; b < L.beams; ++b) {
    const double el = (L.fov_up_deg - (b + 0.5) * (L.fov_up_deg - L.fov_down_deg) / L.beams) * kDeg;
    for (int c = 0; c < L.cols; ++c) dirs.push_back(Direction(el, (c + 0.5) * 2.0 * 3.14159265358979323846 / L.cols));
  }
  return CastDirections(T_world_sensor, boxes, dirs, L.max_range);
}

inline Pose At(double x, double y, double z = 1.8, double yaw = 0.0) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

inline Box MakeBox(double x0, double y0, double z0, double x1, double y1, double z1, int id) {
  return Box{Eigen::Vector3d(x0, y0, z0), Eigen::Vector3d(x1, y1, z1), id};
}

// World points of a scan with their labels.
inline PointCloud ToWorld(const PointCloud& scan, const Pose& T) {
  PointCloud out = scan;
  for (auto& p : out.points) {
    const Eigen::Vector3d w = T * Eigen::Vector3d(p.x, p.y, p.z);
    p.x = float(w.x()), p.y = float(w.y()), p.z = float(w.z());
  }
  return out;
}

// A session (SC-LIO-SAM layout in `dir`) driving along y = 0 from x0 for n keyframes, 2 m apart,
// between two long walls (and a parked car at x = 0 when asked); returns world poses.
inline std::vector<Pose> WriteStreetSession(const std::string& dir, double x0, int n, bool parked_car) {
  std::vector<Box> boxes = {MakeBox(-60, 8, 0, 120, 8.3, 4, 1), MakeBox(-60, -8.3, 0, 120, -8, 4, 2)};
  if (parked_car) boxes.push_back(MakeBox(-2, -6, 0.3, 2, -4, 1.8, 7));
  Session s;
  s.name = std::filesystem::path(dir).filename().string();
  std::vector<Pose> world;
  const Pose origin = At(x0, 0.0, 0.0, 0.0);  // session frame = first keyframe's ground point
  for (int k = 0; k < n; ++k) {
    const Pose T = At(x0 + 2.0 * k, 0.0, 1.8);
    Keyframe kf;
    kf.index = k;
    kf.T_session_sensor = origin.inverse() * T;
    auto scan = CastScan(T, boxes, Lidar{});
    scan.object.clear();
    kf.cloud = std::make_shared<PointCloud>(std::move(scan));
    s.keyframes.push_back(kf);
    if (k > 0) {
      Edge e;
      e.from = k - 1;
      e.to = k;
      e.T_from_to = s.keyframes[std::size_t(k - 1)].T_session_sensor.inverse() * kf.T_session_sensor;
      s.odometry.push_back(e);
    }
    world.push_back(T);
  }
  io::WriteSession(dir, s);
  return world;
}

}  // namespace ltm::test
