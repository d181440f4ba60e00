// `ltmapper info <session-dir>`: what a session holds and what is wrong with it, before any
// stage runs on it. Exit code 1 when the session cannot be loaded at all or every scan is empty.
// `ltmapper info <cloud file>` (.pcd, .bin, .ply): the cloud's points, fields, box and range, and
// the sensor estimated from it as one scan.
#include "command.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/removert/removert.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <iostream>
#include <memory>

namespace {

struct InfoArgs {
  std::string dir;
  std::string kitti_poses;
  std::string calib;
  bool no_scans = false;
};

// The sensor as the stages will see it (removert::WithSensor: estimated from the session's scans).
void PrintSensor(const ltm::Session& session) {
  try {
    const ltm::removert::RemovertConfig defaults;
    const auto resolved = ltm::removert::WithSensor(defaults, ltm::removert::KeyframesOf(session));
    std::cout << "sensor: " << resolved.sensor_model.Describe() << "\n" << std::flush;
  } catch (const ltm::Error& e) {
    std::cout << "sensor: not estimated (" << e.what() << ")\n" << std::flush;
  }
}

// One cloud file; the sensor estimated from it as one scan in the sensor frame (a KTH-layout scan,
// in the world frame, is moved back by its VIEWPOINT first).
void RunCloudInfo(const InfoArgs& a) {
  if (!a.kitti_poses.empty() || !a.calib.empty() || a.no_scans)
    throw ltm::Error(a.dir + ": a cloud file takes no --kitti-poses, --calib or --no-scans");
  ltm::PointCloud cloud;
  const ltm::io::CloudInfo info = ltm::io::InspectCloud(a.dir, &cloud);
  std::cout << ltm::io::FormatCloudInfo(info) << std::flush;
  if (info.viewpoint) ltm::geometry::TransformInPlace(cloud, info.T_viewpoint.inverse());
  try {
    std::cout << "  sensor:          " << ltm::geometry::EstimateSensor({cloud}).Describe() << "\n" << std::flush;
  } catch (const ltm::Error& e) {
    std::cout << "  sensor:          not estimated (" << e.what() << ")\n" << std::flush;
  }
  if (info.points == 0) throw ltm::Error(a.dir + ": no finite points");
}

void RunInfo(const InfoArgs& a) {
  if (std::filesystem::is_regular_file(a.dir)) return RunCloudInfo(a);
  ltm::io::SessionInfo info;
  if (!a.kitti_poses.empty()) {
    std::unique_ptr<ltm::Pose> Tr;
    if (!a.calib.empty()) Tr = std::make_unique<ltm::Pose>(ltm::io::ReadTransform(a.calib));
    info = ltm::io::InspectKittiSession(a.dir, a.kitti_poses, Tr.get(), !a.no_scans);
  } else {
    if (!a.calib.empty()) throw ltm::Error("--calib needs --kitti-poses (KITTI layout)");
    info = ltm::io::InspectSession(a.dir, !a.no_scans);
  }
  std::cout << ltm::io::FormatSessionInfo(info) << std::flush;
  if (!info.load_error.empty()) throw ltm::Error("session cannot be loaded: " + info.load_error);
  if (info.scans_read > 0 && info.points_total == 0)
    throw ltm::Error(a.dir + ": every scan is empty (no finite points); slam, removert and run refuse it");
  if (!a.no_scans) {
    std::unique_ptr<ltm::Pose> Tr;
    if (!a.calib.empty()) Tr = std::make_unique<ltm::Pose>(ltm::io::ReadTransform(a.calib));
    PrintSensor(a.kitti_poses.empty() ? ltm::io::LoadSession(a.dir)
                                      : ltm::io::LoadKittiSession(a.dir, a.kitti_poses, Tr.get()));
  }
  if (!info.problems.empty())
    spdlog::warn("{}: {} problem(s) listed above", a.dir, info.problems.size());
}

LTM_COMMAND(10, [](CLI::App& parent) {
  auto args = std::make_shared<InfoArgs>();
  auto* cmd = parent.add_subcommand(
      "info", "What a session holds: keyframes, scan sizes, poses, edges, problems; or one cloud file");
  cmd->add_option("session-dir", args->dir, "Session directory (Scans/, g2o / optimized_poses.txt), "
                                            "KITTI sequence directory (velodyne/), or one cloud file (.pcd, .bin, .ply)")
      ->required();
  cmd->add_option("--kitti-poses", args->kitti_poses,
                  "KITTI layout: poses file (12 numbers per line, one per scan index)");
  cmd->add_option("--calib", args->calib,
                  "KITTI layout: calib.txt (its 'Tr:' line) or a 3x4/4x4 file; poses are camera poses");
  cmd->add_flag("--no-scans", args->no_scans, "Do not read the scans (faster; no point statistics)");
  cmd->callback([args] { RunInfo(*args); });
});

}  // namespace
