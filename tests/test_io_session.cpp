// Session directories: write + load round trip, the pose/scan matching rules, bad sessions,
// InspectSession and the `ltmapper info` command.
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

namespace fs = std::filesystem;

namespace ltm {
namespace {

Pose Planar(double x, double y, double yaw) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0.0);
  return T;
}

// n keyframes on a line 1 m apart, each scan with 50 + k points, one loop 0 -> n-1.
Session MakeSession(int n) {
  Session s;
  s.name = "demo";
  for (int k = 0; k < n; ++k) {
    Keyframe kf;
    kf.index = k;
    kf.T_session_sensor = Planar(double(k), 0.1 * k, 0.05 * k);
    auto cloud = std::make_shared<PointCloud>();
    for (int p = 0; p < 50 + k; ++p) cloud->push_back(float(p), float(k), 0.5f, float(p % 7));
    kf.cloud = cloud;
    s.keyframes.push_back(kf);
  }
  for (int k = 0; k + 1 < n; ++k) {
    Edge e;
    e.from = k;
    e.to = k + 1;
    e.T_from_to = s.keyframes[k].T_session_sensor.inverse() * s.keyframes[k + 1].T_session_sensor;
    s.odometry.push_back(e);
  }
  Edge loop;
  loop.from = 0;
  loop.to = n - 1;
  loop.T_from_to = s.keyframes[0].T_session_sensor.inverse() * s.keyframes[n - 1].T_session_sensor;
  loop.has_information = true;
  loop.information = Matrix6d::Identity() * 100.0;
  s.loops.push_back(loop);
  return s;
}

void ExpectSamePose(const Pose& a, const Pose& b, double tol = 1e-9) {
  EXPECT_LT((a.matrix() - b.matrix()).cwiseAbs().maxCoeff(), tol);
}

TEST(Session, WriteLoadRoundTrip) {
  test::TempDir tmp;
  const Session s = MakeSession(12);
  std::vector<Eigen::MatrixXd> scds(12, Eigen::MatrixXd::Constant(20, 60, 1.5));
  io::WriteSession(tmp / "sess", s, scds);
  EXPECT_TRUE(fs::exists(tmp / "sess/Scans/000011.pcd"));
  EXPECT_TRUE(fs::exists(tmp / "sess/SCDs/000003.scd"));
  io::SessionLoadOptions opt;
  opt.load_clouds = true;
  const Session r = io::LoadSession(tmp / "sess", opt);
  EXPECT_EQ(r.name, "sess");
  ASSERT_EQ(r.keyframes.size(), 12u);
  for (std::size_t k = 0; k < 12; ++k) {
    EXPECT_EQ(r.keyframes[k].index, int(k));
    ExpectSamePose(r.keyframes[k].T_session_sensor, s.keyframes[k].T_session_sensor);
    ASSERT_TRUE(r.keyframes[k].cloud);
    EXPECT_EQ(r.keyframes[k].cloud->size(), 50 + k);
  }
  EXPECT_EQ(r.odometry.size(), 11u);
  ASSERT_EQ(r.loops.size(), 1u);
  EXPECT_EQ(r.loops[0].to, 11);
  EXPECT_TRUE(r.loops[0].has_information);
  EXPECT_DOUBLE_EQ(r.loops[0].information(0, 0), 100.0);
  // Lazy loading: path only; KeyframeCloud reads it.
  const Session lazy = io::LoadSession(tmp / "sess");
  EXPECT_FALSE(lazy.keyframes[3].cloud);
  EXPECT_EQ(io::KeyframeCloud(lazy.keyframes[3])->size(), 53u);
  // Writing twice into the same directory is fine (same indices).
  EXPECT_NO_THROW(io::WriteSession(tmp / "sess", s));
}

TEST(Session, NumericSortAndPosesFileWithoutG2o) {
  test::TempDir tmp;
  const std::string dir = tmp / "fastlio";
  std::vector<Pose> poses;
  // Unpadded names, as some savers write: 2.pcd must come before 10.pcd.
  for (int k : {0, 1, 2, 10}) {
    PointCloud c;
    c.push_back(float(k), 0, 0);
    io::WritePcd(dir + "/Scans/" + std::to_string(k) + ".pcd", c);
    poses.push_back(Planar(k, 0, 0));
  }
  io::WriteKittiPoses(dir + "/optimized_poses.txt", poses);
  const Session s = io::LoadSession(dir);
  ASSERT_EQ(s.keyframes.size(), 4u);
  EXPECT_EQ(s.keyframes[2].index, 2);
  EXPECT_EQ(s.keyframes[3].index, 10);
  EXPECT_DOUBLE_EQ(s.keyframes[3].T_session_sensor.translation().x(), 10.0);
  EXPECT_EQ(io::KeyframeCloud(s.keyframes[3])->points[0].x, 10.f);
  ASSERT_EQ(s.odometry.size(), 3u);  // derived from consecutive poses
  EXPECT_FALSE(s.odometry[2].has_information);
  EXPECT_EQ(s.odometry[2].from, 2);
  EXPECT_EQ(s.odometry[2].to, 10);
  EXPECT_NEAR(s.odometry[2].T_from_to.translation().x(), 8.0, 1e-12);
  EXPECT_TRUE(s.loops.empty());
  test::ExpectError([&] { io::SessionLoadOptions o; o.require_g2o = true; io::LoadSession(dir, o); }, {"g2o"});
}

TEST(Session, BadSessions) {
  test::TempDir tmp;
  const Session s = MakeSession(5);
  test::ExpectError([&] { io::LoadSession(tmp / "absent"); }, {tmp / "absent", "no such"});
  fs::create_directories(tmp / "noscans");
  test::ExpectError([&] { io::LoadSession(tmp / "noscans"); }, {"noscans", "Scans/"});

  // Pose count != scan count (optimized_poses.txt only).
  io::WriteSession(tmp / "count", s);
  fs::remove(tmp / "count/singlesession_posegraph.g2o");
  fs::remove(tmp / "count/Scans/000004.pcd");
  test::ExpectError([&] { io::LoadSession(tmp / "count"); }, {"optimized_poses.txt", "5 poses", "4 scans"});

  // g2o vertex without a scan and scan without a vertex.
  io::WriteSession(tmp / "ids", s);
  fs::rename(tmp / "ids/Scans/000004.pcd", tmp / "ids/Scans/000007.pcd");
  test::ExpectError([&] { io::LoadSession(tmp / "ids"); }, {"singlesession_posegraph.g2o", "scans without a vertex: 7", "vertices without a scan: 4"});

  // Duplicate indices.
  io::WriteSession(tmp / "dup", s);
  fs::copy_file(tmp / "dup/Scans/000001.pcd", tmp / "dup/Scans/1.pcd");
  test::ExpectError([&] { io::LoadSession(tmp / "dup"); }, {"duplicate index 1", "000001.pcd", "1.pcd"});

  // No poses at all.
  io::WriteSession(tmp / "nop", s);
  fs::remove(tmp / "nop/singlesession_posegraph.g2o");
  fs::remove(tmp / "nop/optimized_poses.txt");
  test::ExpectError([&] { io::LoadSession(tmp / "nop"); }, {"no poses"});

  // Bad g2o inside a session: the g2o's file:line is in the message.
  io::WriteSession(tmp / "badg2o", s);
  test::WriteText(tmp / "badg2o/singlesession_posegraph.g2o", "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nHELLO 1\n");
  test::ExpectError([&] { io::LoadSession(tmp / "badg2o"); }, {"singlesession_posegraph.g2o:2", "HELLO"});
}

TEST(Session, InspectReportsProblems) {
  test::TempDir tmp;
  Session s = MakeSession(6);
  s.keyframes[2].cloud = std::make_shared<PointCloud>();  // empty scan: loads, but is a problem
  io::WriteSession(tmp / "s", s);
  io::SessionInfo info = io::InspectSession(tmp / "s");
  EXPECT_EQ(info.keyframes, 6u);
  EXPECT_EQ(info.scans_found, 6u);
  EXPECT_EQ(info.scans_read, 6u);
  EXPECT_EQ(info.points_min, 0u);
  EXPECT_EQ(info.points_max, 55u);
  EXPECT_EQ(info.odometry_edges, 5u);
  EXPECT_EQ(info.loop_edges, 1u);
  EXPECT_EQ(info.pose_source, "singlesession_posegraph.g2o");
  EXPECT_NEAR(info.path_length_m, 5 * std::hypot(1.0, 0.1), 1e-9);
  EXPECT_NEAR(info.bbox_max.x(), 5.0, 1e-9);
  EXPECT_TRUE(info.load_error.empty()) << info.load_error;
  ASSERT_EQ(info.problems.size(), 1u);
  EXPECT_NE(info.problems[0].find("empty scan"), std::string::npos);
  EXPECT_NE(info.problems[0].find("000002.pcd"), std::string::npos);
  EXPECT_NE(io::FormatSessionInfo(info).find("PROBLEMS (1)"), std::string::npos);

  // Missing scan, extra scan, count mismatch all listed at once.
  fs::rename(tmp / "s/Scans/000005.pcd", tmp / "s/Scans/000009.pcd");
  info = io::InspectSession(tmp / "s", false);
  const std::string text = io::FormatSessionInfo(info);
  EXPECT_NE(text.find("missing scans"), std::string::npos) << text;
  EXPECT_NE(text.find("extra scans without poses"), std::string::npos) << text;
  EXPECT_FALSE(info.load_error.empty());
  EXPECT_NE(text.find("CANNOT LOAD"), std::string::npos) << text;

  EXPECT_THROW(io::InspectSession(tmp / "absent"), Error);
}

TEST(Session, KittiLayoutWithExtrinsic) {
  test::TempDir tmp;
  const std::string dir = tmp / "seq";
  PointCloud c;
  c.push_back(1, 2, 3, 4);
  for (int k = 0; k < 3; ++k) io::WriteKittiBin(dir + "/velodyne/00000" + std::to_string(k) + ".bin", c);
  const Pose Tr = Planar(0.3, -0.1, 0.7);
  std::vector<Pose> cam;
  for (int k = 0; k < 5; ++k) cam.push_back(Planar(0, 0, 0.1 * k) * Planar(2.0 * k, 0, 0));
  io::WriteKittiPoses(tmp / "poses.txt", cam);
  const Session s = io::LoadKittiSession(dir, tmp / "poses.txt", &Tr);
  ASSERT_EQ(s.keyframes.size(), 3u);
  for (int k = 0; k < 3; ++k)
    ExpectSamePose(s.keyframes[k].T_session_sensor, Tr.inverse() * cam[k] * Tr, 1e-12);
  EXPECT_EQ(s.odometry.size(), 2u);
  const Session plain = io::LoadKittiSession(dir, tmp / "poses.txt");
  ExpectSamePose(plain.keyframes[2].T_session_sensor, cam[2], 1e-12);
  // Fewer poses than scans.
  io::WriteKittiPoses(tmp / "short.txt", {cam[0], cam[1]});
  test::ExpectError([&] { io::LoadKittiSession(dir, tmp / "short.txt"); }, {"short.txt", "000002.bin"});
}

TEST(Cli, InfoMissingDirFailsWithPath) {
  test::TempDir tmp;
  std::string out;
  const std::string missing = tmp / "no_such_session";
  EXPECT_NE(test::RunCli("info " + missing, &out), 0);
  EXPECT_NE(out.find(missing), std::string::npos) << out;
}

TEST(Cli, InfoGoodSessionPrintsCounts) {
  test::TempDir tmp;
  io::WriteSession(tmp / "good", MakeSession(4));
  std::string out;
  EXPECT_EQ(test::RunCli("info " + (tmp / "good"), &out), 0) << out;
  test::ExpectContains(out, {"keyframes:       4", "min 50 / mean 52 / max 53", "3 odometry, 1 loops",
                             "problems:        none"});
}

TEST(Cli, InfoBrokenSessionExitsNonZero) {
  test::TempDir tmp;
  io::WriteSession(tmp / "bad", MakeSession(4));
  fs::remove(tmp / "bad/singlesession_posegraph.g2o");
  fs::remove(tmp / "bad/Scans/000003.pcd");
  std::string out;
  EXPECT_NE(test::RunCli("info " + (tmp / "bad"), &out), 0) << out;
  EXPECT_NE(out.find("pose count != scan count"), std::string::npos) << out;
}

TEST(Cli, InfoKittiLayout) {
  test::TempDir tmp;
  PointCloud c;
  c.push_back(1, 2, 3, 4);
  c.push_back(5, 6, 7, 8);
  for (int k = 0; k < 3; ++k) io::WriteKittiBin(tmp / ("seq/velodyne/00000" + std::to_string(k) + ".bin"), c);
  io::WriteKittiPoses(tmp / "poses.txt", {Planar(0, 0, 0), Planar(1, 0, 0), Planar(3, 0, 0), Planar(6, 0, 0)});
  test::WriteText(tmp / "calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  std::string out;
  EXPECT_EQ(test::RunCli("info " + (tmp / "seq") + " --kitti-poses " + (tmp / "poses.txt") +
                         " --calib " + (tmp / "calib.txt"), &out), 0) << out;
  EXPECT_NE(out.find("keyframes:       3"), std::string::npos) << out;
  EXPECT_NE(out.find("path length:     3.00 m"), std::string::npos) << out;
  EXPECT_NE(test::RunCli("info " + (tmp / "seq") + " --kitti-poses " + (tmp / "missing.txt"), &out), 0);
  EXPECT_NE(out.find("missing.txt"), std::string::npos) << out;
}

// `info` on one cloud file: its points, box and range, and the sensor estimated from it as a scan
// (a 16-beam ring scan written as ascii PCD); a truncated file is an error naming it.
TEST(Cli, InfoOfOneCloudFile) {
  test::TempDir tmp;
  PointCloud scan;
  for (int beam = 0; beam < 16; ++beam)
    for (int col = 0; col < 1800; ++col) {
      const double el = (-15.0 + 2.0 * beam) * M_PI / 180.0, az = col * 0.2 * M_PI / 180.0, r = 12.0;
      scan.push_back(float(r * std::cos(el) * std::cos(az)), float(r * std::cos(el) * std::sin(az)),
                     float(r * std::sin(el)), 1.f);
    }
  io::WritePcd(tmp / "scan.pcd", scan, io::PcdFormat::kAscii);
  std::string out;
  EXPECT_EQ(test::RunCli("info " + (tmp / "scan.pcd"), &out), 0) << out;
  test::ExpectContains(out, {"points:          28800 (28800 in the file, 0 NaN/Inf dropped)",
                             "median 12.00 / max 12.00 m", "16 beams +15.000 .. -15.000 deg"});
  const std::string text = test::ReadText(tmp / "scan.pcd");
  test::WriteText(tmp / "cut.pcd", text.substr(0, text.rfind('\n', text.size() / 2) + 1));  // whole rows
  EXPECT_NE(test::RunCli("info " + (tmp / "cut.pcd"), &out), 0);
  test::ExpectContains(out, {"cut.pcd", "truncated"});
}

// ---------------------------------------------------------------- layouts users' tools write
void ExpectPosesNear(const Session& s, const Session& ref) {
  ASSERT_EQ(s.keyframes.size(), ref.keyframes.size());
  for (std::size_t k = 0; k < s.keyframes.size(); ++k) {
    EXPECT_EQ(s.keyframes[k].index, ref.keyframes[k].index);
    EXPECT_LT((s.keyframes[k].T_session_sensor.matrix() - ref.keyframes[k].T_session_sensor.matrix()).norm(), 1e-5);
  }
}

TEST(SessionLayouts, ScanFolderWithKittiOrTumPoses) {
  const Session ref = MakeSession(4);
  std::vector<Pose> poses;
  std::vector<io::StampedPose> stamped;
  for (const auto& kf : ref.keyframes) {
    poses.push_back(kf.T_session_sensor);
    stamped.push_back({0.1 * kf.index, kf.T_session_sensor});
  }
  for (const std::string pose_file : {"poses_kitti.txt", "poses_tum.txt", "poses.txt"}) {
    test::TempDir tmp;
    const std::string dir = tmp / "drive";
    fs::create_directories(dir + "/scans");
    for (const auto& kf : ref.keyframes) io::WritePcd(dir + "/scans/" + std::to_string(kf.index) + ".pcd", *kf.cloud);
    if (pose_file == "poses_tum.txt")
      io::WriteTumPoses(dir + "/" + pose_file, stamped);
    else
      io::WriteKittiPoses(dir + "/" + pose_file, poses);
    const io::SessionLayout l = io::DetectSessionLayout(dir);
    EXPECT_EQ(l.name, pose_file == "poses_tum.txt" ? "scans+tum-poses" : "scans+kitti-poses");
    const Session s = io::LoadSession(dir);
    ExpectPosesNear(s, ref);
    EXPECT_EQ(s.odometry.size(), 3u);
    const io::SessionInfo info = io::InspectSession(dir);
    EXPECT_EQ(info.layout, l.name);
    EXPECT_EQ(info.keyframes, 4u);
    EXPECT_TRUE(info.load_error.empty()) << info.load_error;
  }
}

TEST(SessionLayouts, KittiOdometryWithCalib) {
  test::TempDir tmp;
  const std::string dir = tmp / "seq";
  const Session ref = MakeSession(3);
  Pose Tr = Planar(0.3, -0.1, 0.2);  // a camera-from-LiDAR transform
  std::vector<Pose> cam;
  fs::create_directories(dir + "/velodyne");
  for (const auto& kf : ref.keyframes) {
    io::WriteKittiBin(dir + "/velodyne/" + std::to_string(kf.index) + ".bin", *kf.cloud);
    cam.push_back(Tr * kf.T_session_sensor * Tr.inverse());  // P = Tr * T_w_velo * Tr^-1
  }
  io::WriteKittiPoses(dir + "/poses.txt", cam);
  std::ostringstream calib;
  calib << "Tr:";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) calib << " " << Tr.matrix()(r, c);
  test::WriteText(dir + "/calib.txt", calib.str() + "\n");
  EXPECT_EQ(io::DetectSessionLayout(dir).name, "kitti-odometry");
  ExpectPosesNear(io::LoadSession(dir), ref);
}

TEST(SessionLayouts, KthDynamicMapWorldFrameScansWithViewpoints) {
  test::TempDir tmp;
  const std::string dir = tmp / "kth";
  const Session ref = MakeSession(3);
  for (const auto& kf : ref.keyframes) {
    // World-frame points, sensor pose in VIEWPOINT (tx ty tz qw qx qy qz), ascii.
    const Pose& T = kf.T_session_sensor;
    const Eigen::Quaterniond q(T.linear());
    std::ostringstream pcd;
    pcd.precision(9);
    pcd << "VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH "
        << kf.cloud->size() << "\nHEIGHT 1\nVIEWPOINT " << T.translation().x() << " " << T.translation().y() << " "
        << T.translation().z() << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z() << "\nPOINTS "
        << kf.cloud->size() << "\nDATA ascii\n";
    for (const PointXYZI& p : kf.cloud->points) {
      const Eigen::Vector3d w = T * p.xyz().cast<double>();
      pcd << w.x() << " " << w.y() << " " << w.z() << " " << p.intensity << "\n";
    }
    test::WriteText(dir + "/pcd/" + std::to_string(1000 + kf.index).substr(1) + ".pcd", pcd.str());
  }
  EXPECT_EQ(io::DetectSessionLayout(dir).name, "kth-dynamicmap");
  const Session s = io::LoadSession(dir);
  ExpectPosesNear(s, ref);
  for (std::size_t k = 0; k < s.keyframes.size(); ++k) {  // back in the sensor frame
    const PointCloud& got = *s.keyframes[k].cloud;
    const PointCloud& want = *ref.keyframes[k].cloud;
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < got.size(); ++i) EXPECT_LT((got.points[i].xyz() - want.points[i].xyz()).norm(), 1e-4);
  }
  const std::string bad = tmp / "bad";
  test::WriteText(bad + "/pcd/000000.pcd", "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\n"
                                           "HEIGHT 1\nVIEWPOINT 0 0 0 1\nPOINTS 0\nDATA ascii\n");
  EXPECT_THROW(io::LoadSession(bad), Error);  // VIEWPOINT with 4 numbers
}

TEST(SessionLayouts, UnknownLayoutNamesTheExpectedOnes) {
  test::TempDir tmp;
  fs::create_directories(tmp / "empty");
  try {
    io::LoadSession(tmp / "empty");
    FAIL() << "an empty folder loaded";
  } catch (const Error& e) {
    const std::string what = e.what();
    for (const char* name : {"SC-LIO-SAM", "FAST-LIO-SAM", "KITTI", "KTH"}) EXPECT_NE(what.find(name), std::string::npos) << what;
  }
}

// A binary PCD of one point (1, 2, 3) with a U4 field `name` holding `value` after x y z.
void WritePointWithUintField(const std::string& path, const std::string& name, std::uint32_t value) {
  std::ofstream out(path, std::ios::binary);
  out << "VERSION 0.7\nFIELDS x y z " << name << "\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 1\nHEIGHT 1\n"
      << "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA binary\n";
  const float xyz[3] = {1.f, 2.f, 3.f};
  out.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  out.write(reinterpret_cast<const char*>(&value), sizeof(value));
}

// The sensor's motion over t seconds at a constant body velocity v and yaw rate w, in the model
// io::Deskew uses (rotation by t w, translation t v).
Pose MotionOver(double t, const Eigen::Vector3d& v, double w) {
  Pose M = Pose::Identity();
  M.linear() = Eigen::AngleAxisd(t * w, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  M.translation() = t * v;
  return M;
}

// A raw sweep (points in the frame of their firing, a per-point `time`) written with times.txt
// loads deskewed: each point where it lies in the frame of its scan's timestamp. Without the
// times it is an error naming the scan; a `time` field that is not a float is an error too.
TEST(Session, RawSweepsAreDeskewedWithTheirTimes) {
  test::TempDir tmp;
  const Eigen::Vector3d v(10.0, 0.5, 0.0);  // m/s: 1 m during a 0.1 s sweep
  const double w = 0.6, dt = 0.1;           // rad/s; seconds between scans
  Session s;
  std::vector<std::vector<Eigen::Vector3f>> truth;
  for (int k = 0; k < 4; ++k) {
    Keyframe kf;
    kf.index = k;
    kf.time_s = 100.0 + k * dt;
    if (k > 0) kf.T_session_sensor = s.keyframes.back().T_session_sensor * MotionOver(dt, v, w);
    auto raw = std::make_shared<PointCloud>();
    truth.emplace_back();
    for (int j = 0; j < 360; ++j) {  // a ring of points 5-25 m away, fired in turn over the sweep
      const double a = j * M_PI / 180.0, r = 5.0 + 20.0 * (j % 7) / 6.0, t = dt * j / 360.0;
      const Eigen::Vector3d q(r * std::cos(a), r * std::sin(a), 0.1 * (j % 5));
      truth.back().push_back(q.cast<float>());
      const Eigen::Vector3d p = MotionOver(t, v, w).inverse() * q;  // where the sensor saw it at t
      raw->push_back(float(p.x()), float(p.y()), float(p.z()), 1.f);
      raw->time.push_back(float(t));
    }
    kf.cloud = raw;
    s.keyframes.push_back(kf);
  }
  io::WriteSession(tmp / "raw", s);
  ASSERT_TRUE(fs::exists(tmp / "raw/times.txt"));
  const Session r = io::LoadSession(tmp / "raw");
  ASSERT_EQ(r.keyframes.size(), 4u);
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_NEAR(r.keyframes[k].time_s, 100.0 + double(k) * dt, 1e-9);
    ASSERT_TRUE(r.keyframes[k].sweep.known);
    EXPECT_LT((r.keyframes[k].sweep.v_mps - v).norm(), 1e-6);
    EXPECT_NEAR(r.keyframes[k].sweep.w_radps.z(), w, 1e-6);
    const auto cloud = io::KeyframeCloud(r.keyframes[k]);
    ASSERT_EQ(cloud->size(), truth[k].size());
    EXPECT_TRUE(cloud->time.empty());
    double worst = 0.0, before = 0.0;
    for (std::size_t i = 0; i < cloud->size(); ++i) {
      worst = std::max(worst, double((cloud->points[i].xyz() - truth[k][i]).norm()));
      before = std::max(before, double((s.keyframes[k].cloud->points[i].xyz() - truth[k][i]).norm()));
    }
    EXPECT_LT(worst, 1e-4) << "keyframe " << k;
    EXPECT_GT(before, 0.9);  // the raw sweep was a metre off at its end
  }
  // Without times.txt the raw sweep cannot be deskewed: an error naming the scan and the fix.
  fs::remove(tmp / "raw/times.txt");
  const Session no_times = io::LoadSession(tmp / "raw");
  try {
    io::KeyframeCloud(no_times.keyframes[1]);
    ADD_FAILURE() << "a raw sweep without times loaded";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("Scans/000001.pcd"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("times.txt"), std::string::npos) << e.what();
  }
  // Times that do not increase are ignored (the session loads: its scans might need none), and
  // the raw sweep then cannot be deskewed.
  {
    std::ofstream(tmp / "raw/times.txt") << "0.0\n0.1\n0.1\n0.3\n";
    EXPECT_THROW(io::ReadTimes(tmp / "raw/times.txt"), Error);
    const Session bad_times = io::LoadSession(tmp / "raw");
    EXPECT_FALSE(bad_times.keyframes[1].sweep.known);
    EXPECT_THROW(io::KeyframeCloud(bad_times.keyframes[1]), Error);
  }
  // A `time` field of another type than float is refused, naming the file.
  const std::string bad = tmp / "int_time.pcd";
  WritePointWithUintField(bad, "time", 5);
  try {
    io::ReadPcd(bad);
    ADD_FAILURE() << "an integer time field was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("int_time.pcd"), std::string::npos) << e.what();
  }
  // Ouster's `t`: uint32 nanoseconds after the scan's timestamp.
  const std::string ouster = tmp / "ouster.pcd";
  WritePointWithUintField(ouster, "t", 50000000);
  const PointCloud o = io::ReadPcd(ouster);
  ASSERT_EQ(o.time.size(), 1u);
  EXPECT_NEAR(o.time[0], 0.05, 1e-7);
}

}  // namespace
}  // namespace ltm
