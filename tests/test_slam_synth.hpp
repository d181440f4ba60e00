// Tiny synthetic worlds for the slam tests (header-only, tests only): boxes on a ground plane
// sampled as points, "scans" = world points within a range of the sensor, in the sensor frame.
// No occlusion; enough for Scan Context and GICP on small sessions that run in seconds.
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

namespace ltm::test {

inline Pose MakePose(double x, double y, double z, double yaw, double pitch = 0, double roll = 0) {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// Random boxes (buildings, poles) on a ground plane at z = 0, within [-half, half]^2.
inline PointCloud SynthWorld(unsigned seed, double half = 70.0, int boxes = 60, double step = 0.35) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  PointCloud w;
  for (double x = -half; x <= half; x += 1.0) {
    for (double y = -half; y <= half; y += 1.0) w.push_back(float(x), float(y), 0.f);
  }
  for (int b = 0; b < boxes; ++b) {
    const double cx = (2 * U(rng) - 1) * half, cy = (2 * U(rng) - 1) * half;
    if (std::abs(cy) < 6.0) continue;  // keep the road along y = 0 free
    const bool pole = U(rng) < 0.3;
    const double sx = pole ? 0.4 : 3 + 8 * U(rng), sy = pole ? 0.4 : 3 + 8 * U(rng);
    const double h = pole ? 6 : 3 + 12 * U(rng);
    const double yaw = U(rng) * M_PI;
    const Eigen::Rotation2Dd R(yaw);
    auto add = [&](double u, double v, double z) {
      const Eigen::Vector2d p = R * Eigen::Vector2d(u, v) + Eigen::Vector2d(cx, cy);
      w.push_back(float(p.x()), float(p.y()), float(z));
    };
    for (double z = 0; z <= h; z += step) {
      for (double u = -sx / 2; u <= sx / 2; u += step) {
        add(u, -sy / 2, z);
        add(u, sy / 2, z);
      }
      for (double v = -sy / 2; v <= sy / 2; v += step) {
        add(-sx / 2, v, z);
        add(sx / 2, v, z);
      }
    }
    for (double u = -sx / 2; u <= sx / 2; u += step) {
      for (double v = -sy / 2; v <= sy / 2; v += step) add(u, v, h);
    }
  }
  return w;
}

// World points within `range` of the sensor (xy), expressed in the sensor frame, with noise.
inline std::shared_ptr<PointCloud> SynthScan(const PointCloud& world, const Pose& T_world_sensor,
                                             double range, unsigned seed, double noise = 0.01) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N(0.0, noise);
  auto scan = std::make_shared<PointCloud>();
  const Pose T_sensor_world = T_world_sensor.inverse();
  const Eigen::Vector3d c = T_world_sensor.translation();
  for (const auto& p : world.points) {
    const double dx = p.x - c.x(), dy = p.y - c.y();
    if (dx * dx + dy * dy > range * range) continue;
    const Eigen::Vector3d q = T_sensor_world * Eigen::Vector3d(p.x, p.y, p.z);
    scan->push_back(float(q.x() + N(rng)), float(q.y() + N(rng)), float(q.z() + N(rng)));
  }
  return scan;
}

// Drifted odometry of a drive through the true poses `world`, in the session frame
// T_world_session: the first pose exact (the session frame is well defined), then the true
// increments with a yaw error of `yaw_drift` rad each step. T_session_sensor per keyframe; the
// drifted increments (world.size() - 1) into `increments` when given.
inline std::vector<Pose> DriftedOdometry(const std::vector<Pose>& world, const Pose& T_world_session, double yaw_drift,
                                         std::vector<Pose>* increments = nullptr) {
  std::vector<Pose> out;
  Pose est = T_world_session.inverse() * world[0];
  for (std::size_t k = 0; k < world.size(); ++k) {
    if (k > 0) {
      Pose inc = world[k - 1].inverse() * world[k];
      inc.linear() = Eigen::AngleAxisd(yaw_drift, Eigen::Vector3d::UnitZ()) * inc.linear();
      est = est * inc;
      if (increments) increments->push_back(inc);
    }
    out.push_back(est);
  }
  return out;
}

// A session driving along the road y = 0 from x0 to x1 in the world, keyframes every `spacing`
// m, sensor 1.8 m above ground. Its own frame is T_world_session (the anchor to recover); its
// odometry drifts in yaw by `yaw_drift` rad per keyframe.
inline Session SynthSession(const PointCloud& world, const std::string& name,
                            const Pose& T_world_session, double x0, double x1, double spacing,
                            double yaw_drift, unsigned seed, std::vector<Pose>* truth = nullptr) {
  Session s;
  s.name = name;
  std::vector<Pose> world_poses;
  for (double x = x0; x <= x1 + 1e-9; x += spacing) {
    world_poses.push_back(MakePose(x, 0.3 * std::sin(x / 10.0), 1.8, 0.05 * std::sin(x / 17.0)));
  }
  const std::vector<Pose> odometry = DriftedOdometry(world_poses, T_world_session, yaw_drift);
  for (std::size_t k = 0; k < world_poses.size(); ++k) {
    const Pose& est = odometry[k];
    Keyframe kf;
    kf.index = int(k);
    kf.T_session_sensor = est;
    kf.cloud = SynthScan(world, world_poses[k], 40.0, seed * 1000 + unsigned(k));
    s.keyframes.push_back(kf);
    if (k > 0) {
      Edge e;
      e.from = int(k) - 1;
      e.to = int(k);
      e.T_from_to = s.keyframes[k - 1].T_session_sensor.inverse() * est;
      s.odometry.push_back(e);
    }
  }
  if (truth) *truth = world_poses;
  return s;
}

}  // namespace ltm::test
