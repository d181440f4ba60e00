// Loop verification by GICP: synthetic known offsets, rejection of wrong places, and real data
// (fast_gicp sample pair against its reference; KITTI scans 0 and 5 from a Scan Context yaw; the
// KITTI 08 revisit, and a place of another sequence).
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"
#include "test_slam_synth.hpp"
#include "test_util.hpp"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <functional>
#include <random>
#include <thread>

using namespace ltm;
using namespace ltm::slam;

namespace {
constexpr double kDeg = M_PI / 180.0;
// Loop threshold of the original Scan Context code (1 - mean cosine).
constexpr double kScOriginalThreshold = 0.4;
double AngleDeg(const Pose& T) { return Eigen::AngleAxisd(T.linear()).angle() / kDeg; }
}  // namespace

TEST(SlamRegistration, RecoversSyntheticOffset) {
  SlamConfig cfg;
  const PointCloud world = test::SynthWorld(21);
  const Pose Ta = test::MakePose(0, 0, 1.8, 0.1), Tb = test::MakePose(2.5, 0.4, 1.8, 0.5);
  const PointCloud a = geometry::VoxelDownsample(*test::SynthScan(world, Ta, 40, 1), cfg.reg_voxel_m);
  const PointCloud b = geometry::VoxelDownsample(*test::SynthScan(world, Tb, 40, 2), cfg.reg_voxel_m);
  const Pose truth = Ta.inverse() * Tb;
  // Initial guess: the yaw only (as Scan Context gives it), translation unknown.
  const Pose init(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()));
  const RegistrationResult r = RegisterGicp(a, b, init, cfg);
  ASSERT_TRUE(r.accepted) << r.reason;
  const Pose err = truth.inverse() * r.T_target_source;
  EXPECT_LT(err.translation().norm(), 0.05);
  EXPECT_LT(AngleDeg(err), 0.2);
  EXPECT_LT(r.plane_z, 1.0);
  EXPECT_LE(r.plane_tail, r.plane_tail_bound);
  EXPECT_GT(r.overlap, 0.8);
}

// Clouds prepared once (every plane made up front, as the keyframe steps use them, two
// registrations sharing one at once) register exactly as the clouds given each time, coarse stage
// off: a plane depends on its cloud alone.
TEST(SlamRegistration, PreparedCloudsRegisterExactlyAsTheCloudsGiven) {
  SlamConfig cfg;
  cfg.reg_coarse_correspondence_m = 0.0;
  const PointCloud world = test::SynthWorld(21);
  const Pose Ta = test::MakePose(0, 0, 1.8, 0.1), Tb = test::MakePose(0.8, 0.1, 1.8, 0.15);
  const PointCloud a = geometry::VoxelDownsample(*test::SynthScan(world, Ta, 40, 1), cfg.reg_voxel_m);
  const PointCloud b = geometry::VoxelDownsample(*test::SynthScan(world, Tb, 40, 2), cfg.reg_voxel_m);
  const Pose init = test::MakePose(0.7, 0.0, 0.0, 0.05);
  const RegistrationResult given = RegisterGicp(a, b, init, cfg);
  GicpCloud ta(a, cfg.reg_covariance_neighbours), tb(b, cfg.reg_covariance_neighbours);
  ta.PrepareAllPlanes();
  tb.PrepareAllPlanes();
  RegistrationResult twice[2];
  std::thread other([&] { twice[1] = RegisterGicp(ta, tb, init, cfg); });
  twice[0] = RegisterGicp(ta, tb, init, cfg);
  other.join();
  ASSERT_TRUE(given.accepted) << given.reason;
  for (const RegistrationResult& r : twice) {
    EXPECT_TRUE(r.accepted) << r.reason;
    EXPECT_TRUE(r.T_target_source.matrix() == given.T_target_source.matrix());
    EXPECT_EQ(r.overlap, given.overlap);
    EXPECT_EQ(r.plane_z, given.plane_z);
    EXPECT_TRUE(r.fisher == given.fisher);
  }
  SlamConfig coarse = cfg;  // the coarse stage needs the clouds themselves: an error, not skipped
  coarse.reg_coarse_correspondence_m = SlamConfig().reg_coarse_correspondence_m;
  ASSERT_GT(coarse.reg_coarse_correspondence_m, 0.0);
  test::ExpectError([&] { RegisterGicp(ta, tb, init, coarse); }, {"fine stage alone", "coarse_correspondence_m"});
}

TEST(SlamRegistration, RejectsDifferentPlaces) {
  SlamConfig cfg;
  const PointCloud w1 = test::SynthWorld(31), w2 = test::SynthWorld(32);
  const PointCloud a = geometry::VoxelDownsample(
      *test::SynthScan(w1, test::MakePose(0, 0, 1.8, 0), 40, 1), cfg.reg_voxel_m);
  const PointCloud b = geometry::VoxelDownsample(
      *test::SynthScan(w2, test::MakePose(0, 0, 1.8, 0), 40, 2), cfg.reg_voxel_m);
  const RegistrationResult r = RegisterGicp(a, b, Pose::Identity(), cfg);
  EXPECT_FALSE(r.accepted) << "fitness " << r.fitness << " overlap " << r.overlap;
  EXPECT_FALSE(r.reason.empty());
  // Too few points: not accepted, no crash.
  PointCloud tiny;
  tiny.push_back(0, 0, 0);
  EXPECT_FALSE(RegisterGicp(a, tiny, Pose::Identity(), cfg).accepted);
}

// A straight corridor (ground and two walls along x, every 0.2 m, 1 cm noise) seen twice.
namespace {
PointCloud Corridor(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, 0.01f);
  PointCloud c;
  for (float x = -30.f; x <= 30.f; x += 0.2f) {
    for (float y = -5.f; y <= 5.f; y += 0.2f) c.push_back(x, y, noise(rng));
    for (float z = 0.2f; z <= 6.f; z += 0.2f) {
      c.push_back(x, -5.f + noise(rng), z);
      c.push_back(x, 5.f + noise(rng), z);
    }
  }
  return c;
}
}  // namespace

// ViewShare: a scan's points lie where the scan looked (share 1); a forward cone facing +x did not
// look at points behind it (share 0), nor at points beyond the returns in their direction.
TEST(SlamRegistration, ViewShareIsWhereTheTargetLooked) {
  PointCloud cone;  // returns 20 m ahead, within 30 deg of +x
  for (double az = -30.0; az <= 30.0; az += 1.0)
    for (double el = -20.0; el <= 20.0; el += 1.0)
      cone.push_back(float(20.0 * std::cos(el * kDeg) * std::cos(az * kDeg)),
                     float(20.0 * std::cos(el * kDeg) * std::sin(az * kDeg)), float(20.0 * std::sin(el * kDeg)));
  const Pose turned = test::MakePose(0, 0, 0, M_PI);  // the same cone facing -x
  PointCloud beyond;                                  // the same directions, 30 m out
  for (const auto& p : cone.points) beyond.push_back(1.5f * p.x, 1.5f * p.y, 1.5f * p.z);
  EXPECT_DOUBLE_EQ(ViewShare(cone, cone, Pose::Identity(), 0.5), 1.0);
  EXPECT_DOUBLE_EQ(ViewShare(cone, cone, turned, 0.5), 0.0);
  EXPECT_DOUBLE_EQ(ViewShare(cone, beyond, Pose::Identity(), 0.5), 0.0);
}

// A forward cone of +-30 deg leaves 300 deg round it without a return (to its 5 deg bins), a ring
// none, half a ring 180 (not yet "one way": LT-SLAM registers by place clouds beyond half a turn),
// nothing the whole turn; a real ring sensor's scan (KITTI) none.
TEST(SlamRegistration, WidestBlindArcIsTheTurnWithoutAReturn) {
  const auto ring = [](double from_deg, double to_deg) {
    PointCloud c;
    for (double az = from_deg; az < to_deg; az += 1.0)
      c.push_back(float(10.0 * std::cos(az * kDeg)), float(10.0 * std::sin(az * kDeg)), -1.5f);
    return c;
  };
  EXPECT_NEAR(WidestBlindArcDeg(ring(-30.0, 30.0)), 300.0, 5.0);
  EXPECT_NEAR(WidestBlindArcDeg(ring(150.0, 210.0)), 300.0, 5.0);  // a cone facing back: the run through 0 deg
  EXPECT_DOUBLE_EQ(WidestBlindArcDeg(ring(-180.0, 180.0)), 0.0);
  EXPECT_NEAR(WidestBlindArcDeg(ring(0.0, 180.0)), 180.0, 5.0);
  EXPECT_DOUBLE_EQ(WidestBlindArcDeg(PointCloud()), 360.0);
}

TEST(SlamRegistrationReal, AKittiScanLeavesNoTurnWithoutAReturn) {
  LTM_REQUIRE_REAL_DATA(data);
  EXPECT_DOUBLE_EQ(WidestBlindArcDeg(io::ReadKittiBin(data + "/kitti00_head/velodyne/000000.bin")), 0.0);
}

TEST(SlamRegistration, LoopInformationFollowsWhatTheSurfacesConstrain) {
  SlamConfig cfg;
  const PointCloud a = geometry::VoxelDownsample(Corridor(1), cfg.reg_voxel_m);
  const PointCloud b = geometry::VoxelDownsample(Corridor(2), cfg.reg_voxel_m);
  const RegistrationResult r = RegisterGicp(a, b, test::MakePose(0.0, 0.2, 0.1, 0.01), cfg);
  ASSERT_TRUE(r.accepted) << r.reason;
  // Walls fix y, the ground z, both the rotations; nothing fixes x (the corridor's axis).
  EXPECT_LT(r.fisher(0, 0), 1e-3 * r.fisher(1, 1));
  EXPECT_GT(r.fisher(2, 2), 1e3 * r.fisher(0, 0));
  // The loop's information: the fitness term where the surfaces constrain, none along the axis.
  const Matrix6d fit_only = LoopInformation(r.fitness, Matrix6d::Zero(), cfg);
  const Matrix6d info = LoopInformation(r.fitness, r.fisher, cfg);
  EXPECT_LT(info(0, 0), 0.2 * fit_only(0, 0));
  EXPECT_GT(info(1, 1), 0.9 * fit_only(1, 1));
  EXPECT_GT(info(2, 2), 0.9 * fit_only(2, 2));
  EXPECT_GT(info(5, 5), 0.9 * fit_only(5, 5));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Matrix6d>(info).eigenvalues().minCoeff(), 0.0);
  // Where every direction is constrained (the synthetic town), the fitness term rules.
  const PointCloud w = test::SynthWorld(21);
  const PointCloud ta = geometry::VoxelDownsample(*test::SynthScan(w, test::MakePose(0, 0, 1.8, 0.1), 40, 1), cfg.reg_voxel_m);
  const PointCloud tb = geometry::VoxelDownsample(*test::SynthScan(w, test::MakePose(1, 0.4, 1.8, 0.2), 40, 2), cfg.reg_voxel_m);
  const RegistrationResult t = RegisterGicp(ta, tb, test::MakePose(1, 0.4, 0, 0.1), cfg);
  ASSERT_TRUE(t.accepted) << t.reason;
  const Matrix6d town = LoopInformation(t.fitness, t.fisher, cfg), town_fit = LoopInformation(t.fitness, Matrix6d::Zero(), cfg);
  for (int k = 0; k < 6; ++k) EXPECT_GT(town(k, k), 0.8 * town_fit(k, k)) << k;
}

// A registered step's (and a loop's added) information is on the turn about the vertical alone:
// the registration's variance of that turn (g^T F^-1 g, g = (0, up)) and nothing in the other five
// directions but a negligible prior, whatever the sensor's tilt (`up` in its frame).
TEST(SlamRegistration, HeadingInformationIsOnTheTurnAboutTheVerticalAlone) {
  SlamConfig cfg;
  std::mt19937 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::Matrix<double, 6, 6> J;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) J(i, j) = N(rng);
  const Matrix6d fisher = 1e4 * (J * J.transpose() + 0.1 * Matrix6d::Identity());
  const Eigen::Vector3d up = Eigen::Vector3d(0.0, std::sin(20 * kDeg), std::cos(20 * kDeg));  // pitched 20 deg
  const Matrix6d H = HeadingInformation(HeadingVariance(fisher, up, cfg), up, cfg);
  Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
  g.tail<3>() = up;
  const double var = g.dot(fisher.inverse() * g);
  EXPECT_NEAR(g.dot(H * g), 1.0 / var, 1e-3 / var);
  // Perpendicular turns and translations: the prior alone, a millionth of the odometry's.
  const double odometry_r = 1.0 / std::pow(cfg.odom_sigma_r_deg * kDeg, 2), odometry_t = 1.0 / std::pow(cfg.odom_sigma_t_m, 2);
  const Eigen::Vector3d across = up.cross(Eigen::Vector3d::UnitX()).normalized();
  Eigen::Matrix<double, 6, 1> turn = Eigen::Matrix<double, 6, 1>::Zero(), shift = turn;
  turn.tail<3>() = across;
  shift(0) = 1.0;
  EXPECT_LE(turn.dot(H * turn), 1.01e-6 * odometry_r);
  EXPECT_LE(shift.dot(H * shift), 1.01e-6 * odometry_t);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Matrix6d>(H).eigenvalues().minCoeff(), 0.0);
}

// VarianceScale: squared errors of variance s v over v give s back, whatever the v; one in fifty
// of them gross (a wrong loop's cycle) moves it by a few percent.
TEST(SlamRegistration, VarianceScaleIsTheErrorsMedianRatioToTheModelsVariance) {
  std::mt19937 rng(3);
  std::normal_distribution<double> N(0.0, 1.0);
  std::uniform_real_distribution<double> U(0.5, 5.0);
  for (const double s : {0.06, 1.0, 12.0}) {
    std::vector<double> ratio;
    for (int i = 0; i < 8000; ++i) {
      const double v = U(rng) * 1e-8, e = N(rng) * std::sqrt(s * v);
      ratio.push_back((i % 50 == 0 ? 1e4 * e * e : e * e) / v);
    }
    EXPECT_NEAR(VarianceScale(ratio), s, 0.12 * s) << s;
  }
  EXPECT_EQ(VarianceScale({}), 1.0);
}

// OffTheGround: a scan of flat ground with a wall beside the road and a pole on it (from 1 m up),
// from a sensor 1.8 m up and pitched 10 deg: the ground goes, the wall and the pole stay.
TEST(SlamRegistration, OffTheGroundKeepsWhatStandsOnIt) {
  SlamConfig cfg;
  const Eigen::AngleAxisd pitch(10 * kDeg, Eigen::Vector3d::UnitY());
  PointCloud scan;
  std::vector<bool> ground;
  const auto add = [&](double x, double y, double z, bool on_ground) {
    const Eigen::Vector3d p = pitch.inverse() * Eigen::Vector3d(x, y, z - 1.8);  // world (sensor at 1.8 m) to sensor
    scan.points.push_back(PointXYZI{float(p.x()), float(p.y()), float(p.z()), 0.f});
    ground.push_back(on_ground);
  };
  for (double x = -20; x <= 20; x += 0.5)
    for (double y = -6; y <= 9; y += 0.5) add(x, y, 0.0, true);
  for (double x = -20; x <= 20; x += 0.5)
    for (double z = 1.0; z <= 6.0; z += 0.5) add(x, 7.0, z, false);
  for (double z = 1.0; z <= 5.0; z += 0.25) add(5.0, -4.0, z, false);
  const PointCloud off = OffTheGround(scan, pitch.inverse() * Eigen::Vector3d::UnitZ(), cfg);
  const std::size_t standing = std::size_t(std::count(ground.begin(), ground.end(), false));
  EXPECT_EQ(off.size(), standing);
  for (const auto& p : off.points) {
    const Eigen::Vector3d w = pitch * p.xyz().cast<double>();
    EXPECT_GT(w.z() + 1.8, cfg.reg_voxel_m) << w.transpose();
  }
}

TEST(SlamRegistrationReal, GicpPairMatchesReference) {
  LTM_REQUIRE_REAL_DATA(data);
  const std::string dir = data + "/gicp_pair";
  // Two dense single scans (no submaps): finer voxels and a tighter fine correspondence distance
  // than the submap defaults. With 0.2 m / 1.0 m PCL GICP lands 0.2-0.5 deg from the reference.
  SlamConfig cfg;
  cfg.reg_voxel_m = 0.1;
  cfg.reg_max_correspondence_m = 0.3;
  cfg.reg_max_iterations = 64;
  const PointCloud target = geometry::VoxelDownsample(io::ReadPcd(dir + "/251370668.pcd"), cfg.reg_voxel_m);
  const PointCloud source = geometry::VoxelDownsample(io::ReadPcd(dir + "/251371071.pcd"), cfg.reg_voxel_m);
  // relative.txt: source 251371071 -> target 251370668, i.e. T_target_source.
  const Pose ref = io::ReadTransform(dir + "/relative.txt");
  const RegistrationResult r = RegisterGicp(target, source, Pose::Identity(), cfg);
  const Pose err = ref.inverse() * r.T_target_source;
  std::printf("gicp_pair: |dt| = %.4f m, dR = %.4f deg, fitness %.4f, overlap %.3f\n",
              err.translation().norm(), AngleDeg(err), r.fitness, r.overlap);
  // Not asserted: r.accepted. The verification gates model clouds sampled at least once per
  // voxel; at 0.1 m the rings of these single scans (32 beams) lie decimetres apart, so the inlier
  // RMS (measured 0.084 m) exceeds the voxel model's bound (0.057 m). The submap default (0.5 m)
  // and the KITTI test below satisfy the model.
  EXPECT_GT(r.overlap, cfg.reg_min_overlap);
  EXPECT_LT(err.translation().norm(), 0.05);  // issue 4 acceptance: 5 cm / 0.2 deg
  EXPECT_LT(AngleDeg(err), 0.2);
}

TEST(SlamRegistrationReal, KittiScans0And5FromScanContextYaw) {
  LTM_REQUIRE_REAL_DATA(data);
  const std::string dir = data + "/kitti00_head";
  SlamConfig cfg;
  cfg.reg_voxel_m = 0.4;  // single scans (no submap): a finer voxel than the submap default
  const Pose Tr = io::ParseTransform(
      "4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 "
      "-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 "
      "9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01",
      "KITTI Tr (data README)");
  const std::vector<Pose> P = io::ReadKittiPoses(dir + "/poses_00.txt");
  ASSERT_GT(P.size(), 5u);
  // LiDAR poses: T_w_velo = Tr^-1 P Tr; relative pose of scan 5 in scan 0's frame.
  const Pose truth = (Tr.inverse() * P[0] * Tr).inverse() * (Tr.inverse() * P[5] * Tr);
  const PointCloud s0 = io::ReadKittiBin(dir + "/velodyne/000000.bin");
  const PointCloud s5 = io::ReadKittiBin(dir + "/velodyne/000005.bin");
  const ScMatch m = CompareScanContexts(MakeScanContext(s0, cfg), MakeScanContext(s5, cfg), cfg);
  ASSERT_LT(m.distance, kScOriginalThreshold);
  const auto prep = [&](const PointCloud& c) {
    return geometry::VoxelDownsample(
        geometry::RangeFilter(c, cfg.reg_min_range_m, cfg.reg_max_range_m), cfg.reg_voxel_m);
  };
  const Pose init(Eigen::AngleAxisd(m.yaw_rad, Eigen::Vector3d::UnitZ()));
  const PointCloud a = prep(s0), b = prep(s5);
  const RegistrationResult r = RegisterGicp(a, b, init, cfg);
  // The same registration started at the KITTI relative pose: the SC-yaw start (4.3 m of
  // translation unknown) must reach the same optimum.
  const RegistrationResult at_truth = RegisterGicp(a, b, truth, cfg);
  const Pose err = truth.inverse() * r.T_target_source;
  const Pose basin = at_truth.T_target_source.inverse() * r.T_target_source;
  std::printf("KITTI 0<-5: truth |t| = %.3f m; SC dist %.3f yaw %.2f deg; GICP from SC yaw vs "
              "GICP from truth: %.4f m %.4f deg; vs KITTI poses: %.4f m %.4f deg\n",
              truth.translation().norm(), m.distance, m.yaw_rad / kDeg,
              basin.translation().norm(), AngleDeg(basin), err.translation().norm(), AngleDeg(err));
  EXPECT_TRUE(r.accepted) << r.reason;
  EXPECT_LT(basin.translation().norm(), 0.05);
  EXPECT_LT(AngleDeg(basin), 0.2);
  // Measured: PCL GICP on these raw (not de-skewed) scans settles ~0.7 m short of the KITTI
  // pose whether started from the SC yaw or from the pose itself (also ~0.18 m for scans 0-1),
  // so the comparison with the KITTI poses is bounded loosely and reported.
  EXPECT_LT(err.translation().norm(), 1.0);
}

// A real revisit (KITTI 08 frames 720 and 1500: opposite direction, 2.5 m to the side, 148.5 deg
// of yaw): from the Scan Context yaw, GICP must land on the ICP reference and be accepted; the
// same scan against another sequence's place (KITTI 00) must be rejected. Single scans at the
// submap voxel (0.5 m): at 0.3-0.4 m this revisit's inlier RMS exceeds the voxel model's bound.
TEST(SlamRegistrationReal, Kitti08RevisitAcceptedAndAnotherPlaceRejected) {
  LTM_REQUIRE_REAL_DATA(data);
  SlamConfig cfg;
  const auto prep = [&](const PointCloud& c) {
    return geometry::VoxelDownsample(geometry::RangeFilter(c, cfg.reg_min_range_m, cfg.reg_max_range_m),
                                     cfg.reg_voxel_m);
  };
  const PointCloud s720 = io::ReadKittiBin(data + "/kitti08_revisit/000720.bin");
  const PointCloud s1500 = io::ReadKittiBin(data + "/kitti08_revisit/001500.bin");
  const PointCloud other = io::ReadKittiBin(data + "/kitti00_head/velodyne/000000.bin");
  const Pose ref = io::ReadTransform(data + "/kitti08_revisit/relative_icp.txt");  // scan 1500 in 720's frame
  const ScMatch m = CompareScanContexts(MakeScanContext(s720, cfg), MakeScanContext(s1500, cfg), cfg);
  const Pose init(Eigen::AngleAxisd(m.yaw_rad, Eigen::Vector3d::UnitZ()));
  const PointCloud a = prep(s720);
  const RegistrationResult r = RegisterGicp(a, prep(s1500), init, cfg);
  const Pose err = ref.inverse() * r.T_target_source;
  std::printf("KITTI 08 720<-1500: SC yaw %.1f deg; ratio %.3f, inlier RMS %.3f m; vs ICP reference %.3f m %.3f deg\n",
              m.yaw_rad / kDeg, r.overlap, r.inlier_rms_m, err.translation().norm(), AngleDeg(err));
  EXPECT_TRUE(r.accepted) << r.reason;
  EXPECT_LT(err.translation().norm(), 0.1);
  EXPECT_LT(AngleDeg(err), 0.3);
  const ScMatch mo = CompareScanContexts(MakeScanContext(s720, cfg), MakeScanContext(other, cfg), cfg);
  const RegistrationResult w =
      RegisterGicp(a, prep(other), Pose(Eigen::AngleAxisd(mo.yaw_rad, Eigen::Vector3d::UnitZ())), cfg);
  std::printf("KITTI 08 720<-00 0 (another place): ratio %.3f, inlier RMS %.3f m: %s\n", w.overlap, w.inlier_rms_m,
              w.accepted ? "accepted" : w.reason.c_str());
  EXPECT_FALSE(w.accepted);
}

namespace {
// Two drives of n keyframes 1 m apart along x (the loops place them side by side), each keyframe
// tied to its neighbour by the odometry and by a registered step of the given information.
std::vector<Session> ParallelDrives(int n, const Matrix6d& step_information) {
  std::vector<Session> sessions(2);
  for (int s = 0; s < 2; ++s) {
    sessions[std::size_t(s)].name = "s" + std::to_string(s);
    for (int k = 0; k < n; ++k) {
      Keyframe kf;
      kf.index = k;
      kf.T_session_sensor.translation() = Eigen::Vector3d(k, 0, 0);
      sessions[std::size_t(s)].keyframes.push_back(kf);
      if (k == 0) continue;
      Edge e;
      e.from = k - 1, e.to = k;
      e.T_from_to.translation() = Eigen::Vector3d(1, 0, 0);
      sessions[std::size_t(s)].odometry.push_back(e);
      e.information = step_information;
      e.has_information = true;
      sessions[std::size_t(s)].registered.push_back(e);
    }
  }
  return sessions;
}
}  // namespace

// LoopHeadingScale: two parallel drives 2 m apart, each keyframe tied to its neighbour by a
// registered step (heading variance 1e-12 rad^2) and to the other drive's by a loop whose heading
// is off by N(0, 9 v), v its declared variance. The cycles of consecutive loops give 9 back. With
// the odometry alone (the config's 0.2 deg a step, far coarser than the loops) no cycle measures,
// nor where loops declared coarser close cycles whose turns hide within the odometry's variance.
TEST(SlamRegistration, LoopHeadingScaleIsMeasuredOnCyclesOfTwoLoops) {
  SlamConfig cfg;
  constexpr int kKeyframes = 400;
  constexpr double kLoopVar = 1e-8, kScale = 9.0;
  std::mt19937 rng(11);
  std::normal_distribution<double> N(0.0, std::sqrt(kScale * kLoopVar));
  std::vector<Session> sessions = ParallelDrives(kKeyframes, HeadingInformation(1e-12, Eigen::Vector3d::UnitZ(), cfg));
  std::vector<LoopRecord> loops;
  for (int k = 0; k < kKeyframes; ++k) {
    LoopRecord l;
    l.a = {0, k}, l.b = {1, k};
    l.T_a_b = Pose(Eigen::AngleAxisd(N(rng), Eigen::Vector3d::UnitZ()));
    l.T_a_b.translation() = Eigen::Vector3d(0, 2, 0);
    l.verified = true;
    l.heading_variance = kLoopVar;
    loops.push_back(l);
  }
  // Each keyframe pair registered twice over, alike: two loops between the same keyframes close no
  // cycle (their zero turns had made half the ratios zero, and the cycles had measured nothing).
  for (int k = 0; k < kKeyframes; ++k) loops.push_back(loops[std::size_t(k)]);
  const LoopCycleScale h = LoopHeadingScale(sessions, loops, cfg);
  EXPECT_EQ(h.cycles, kKeyframes - 1);
  EXPECT_NEAR(h.scale, kScale, 0.3 * kScale);
  for (Session& s : sessions) s.registered.clear();
  EXPECT_EQ(LoopHeadingScale(sessions, loops, cfg).cycles, 0);
  // Loops declared coarser than the odometry (0.6 deg) close cycles through it, but their errors
  // (as above) hide within its variance: the cycles do not measure them, no heading information.
  for (LoopRecord& l : loops) l.heading_variance = 1e-4;
  EXPECT_EQ(LoopHeadingScale(sessions, loops, cfg).cycles, 0);
}

// LoopTranslationScale: the same two drives, their steps exact, each loop's translation off by
// N(0, 4 c) per horizontal axis, c the per-axis variance its registration declares (1 cm): the
// cycles of consecutive loops give 4 back (each gap holds two loops' errors, each of 4 c). Cycles
// through the odometry, or loops with no covariance (registered without registration.steps), none.
TEST(SlamRegistration, LoopTranslationScaleIsMeasuredOnCyclesOfTwoLoops) {
  SlamConfig cfg;
  constexpr int kKeyframes = 400;
  constexpr double kLoopVar = 1e-4, kScale = 4.0;
  std::mt19937 rng(13);
  std::normal_distribution<double> N(0.0, std::sqrt(kScale * kLoopVar));
  std::vector<Session> sessions =
      ParallelDrives(kKeyframes, HeadingInformation(1e-12, Eigen::Vector3d::UnitZ(), cfg) +
                                     HorizontalInformation(Eigen::Matrix2d::Identity() * 1e-10, Eigen::Vector3d::UnitZ()));
  std::vector<LoopRecord> loops;
  for (int k = 0; k < kKeyframes; ++k) {
    LoopRecord l;
    l.a = {0, k}, l.b = {1, k};
    l.T_a_b.translation() = Eigen::Vector3d(N(rng), 2 + N(rng), 0);
    l.verified = true;
    l.translation_covariance = Eigen::Matrix3d::Identity() * kLoopVar;
    loops.push_back(l);
  }
  // Each keyframe pair registered twice over (a place cloud's loop and a scan's), the second time
  // alike: two loops between the same keyframes close no cycle, so the count and scale stand.
  for (int k = 0; k < kKeyframes; ++k) loops.push_back(loops[std::size_t(k)]);
  const LoopCycleScale t = LoopTranslationScale(sessions, loops, cfg);
  std::printf("loops' translation: %d cycles, scale %.2f (truth %.2f)\n", t.cycles, t.scale, kScale);
  EXPECT_EQ(t.cycles, kKeyframes - 1);
  EXPECT_NEAR(t.scale, kScale, 0.3 * kScale);
  // Through the odometry alone (the config's 5 cm a step) the cycles measure the odometry: none.
  std::vector<Session> odometry = sessions;
  for (Session& s : odometry) s.registered.clear();
  EXPECT_EQ(LoopTranslationScale(odometry, loops, cfg).cycles, 0);
  for (LoopRecord& l : loops) l.translation_covariance.setZero();
  EXPECT_EQ(LoopTranslationScale(sessions, loops, cfg).cycles, 0);
}

// SquaresWithin: errors of the model pass but about one time in a thousand; errors 1.5 times wider
// fail.
TEST(SlamRegistration, SquaresWithinFailsTheRareAndTheWider) {
  std::mt19937 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  const double var = 4e-6;
  const auto failed = [&](double sigma_scale) {
    int fails = 0;
    for (int trial = 0; trial < 2000; ++trial) {
      double sum_sq = 0.0;
      for (int i = 0; i < 120; ++i) sum_sq += std::pow(sigma_scale * std::sqrt(var) * N(rng), 2);
      fails += !SquaresWithin(sum_sq, 120, var);
    }
    return fails / 2000.0;
  };
  EXPECT_LT(failed(1.0), 0.01);
  EXPECT_GT(failed(1.5), 0.95);
  EXPECT_TRUE(SquaresWithin(0.0, 0, var));
}

namespace {
// A session of 121 keyframes 1.5 m apart turning 1 deg a keyframe, its odometry turned off the
// truth by `odometry_bias` [rad] plus N(0, 0.05 deg) a step (stated: graph.odom_sigma_r_deg, no
// information in the file), and
// registered steps and two-steps whose turns are off the truth by `step_error(k)` and
// `skip_error(k)` [rad], with a Fisher information of 0.01 deg on the heading.
struct StepScene {
  Session session;
  std::vector<std::optional<RegistrationResult>> steps, skips;
};
StepScene MakeStepScene(const std::function<double(std::size_t)>& step_error,
                        const std::function<double(std::size_t)>& skip_error, double odometry_bias = 0.0) {
  constexpr std::size_t kKeyframes = 121;
  std::mt19937 rng(7);
  std::normal_distribution<double> N(0.0, 0.05 * kDeg);
  const auto turn = [](double rad) { return Pose(Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ())); };
  std::vector<Pose> truth(kKeyframes);
  for (std::size_t k = 0; k < kKeyframes; ++k)
    truth[k] = k == 0 ? Pose::Identity() : truth[k - 1] * Pose(Eigen::Translation3d(1.5, 0, 0)) * turn(kDeg);
  StepScene s;
  Pose odometry = Pose::Identity();
  for (std::size_t k = 0; k < kKeyframes; ++k) {
    if (k > 0) odometry = odometry * truth[k - 1].inverse() * truth[k] * turn(odometry_bias + N(rng));
    Keyframe kf;
    kf.index = int(k);
    kf.T_session_sensor = odometry;
    s.session.keyframes.push_back(kf);
  }
  Matrix6d fisher = Matrix6d::Zero();
  fisher.diagonal() << 1e6, 1e6, 1e6, 1e6, 1e6, 1.0 / std::pow(0.01 * kDeg, 2);
  const auto registered = [&](std::size_t from, std::size_t to, double error) {
    RegistrationResult r;
    r.T_target_source = truth[from].inverse() * truth[to] * turn(error);
    r.fisher = fisher;
    r.accepted = true;
    return std::optional<RegistrationResult>(r);
  };
  for (std::size_t k = 0; k + 1 < kKeyframes; ++k) {
    s.steps.push_back(registered(k, k + 1, step_error(k)));
    s.skips.push_back(k + 2 < kKeyframes ? registered(k, k + 2, skip_error(k)) : std::nullopt);
  }
  return s;
}
}  // namespace

namespace {
// A straight session of 121 keyframes 1.5 m apart whose odometry is `odometry_scale` too long and
// off by N(0, odometry_sigma) [m] a step on each horizontal axis, with registered steps and
// two-steps off the truth by `bias` [m] along the route (each registration's own) and N(0,
// step_sigma) on each axis, their Fisher information stating 10 times that sigma (off the ground
// it overstates).
StepScene MakeTranslationScene(double odometry_scale, double odometry_sigma, double step_sigma, double bias = 0.0) {
  constexpr std::size_t kKeyframes = 121;
  std::mt19937 rng(13);
  std::normal_distribution<double> N(0.0, 1.0);
  const auto off = [&](double sigma) { return Pose(Eigen::Translation3d(sigma * N(rng), sigma * N(rng), 0.0)); };
  const auto truth = [](std::size_t k) { return Pose(Eigen::Translation3d(1.5 * double(k), 0, 0)); };
  StepScene s;
  Pose odometry = Pose::Identity();
  for (std::size_t k = 0; k < kKeyframes; ++k) {
    if (k > 0) odometry = odometry * Pose(Eigen::Translation3d(1.5 * (1.0 + odometry_scale), 0, 0)) * off(odometry_sigma);
    Keyframe kf;
    kf.index = int(k);
    kf.T_session_sensor = odometry;
    s.session.keyframes.push_back(kf);
    if (k > 0) s.session.odometry.push_back(Edge{int(k - 1), int(k), s.session.keyframes[k - 1].T_session_sensor.inverse() * odometry});
  }
  Matrix6d fisher = Matrix6d::Zero();
  fisher.diagonal() << Eigen::Vector3d::Constant(1.0 / std::pow(10.0 * step_sigma, 2)), Eigen::Vector3d::Constant(1e10);
  const auto registered = [&](std::size_t from, std::size_t to) {
    RegistrationResult r;
    r.T_target_source = truth(from).inverse() * truth(to) * Pose(Eigen::Translation3d(bias, 0, 0)) * off(step_sigma);
    r.fisher = fisher;
    r.accepted = true;
    return std::optional<RegistrationResult>(r);
  };
  for (std::size_t k = 0; k + 1 < kKeyframes; ++k) {
    s.steps.push_back(registered(k, k + 1));
    s.skips.push_back(k + 2 < kKeyframes ? registered(k, k + 2) : std::nullopt);
  }
  return s;
}
}  // namespace

// MeasureStepTranslation reads a step's horizontal error off the closures (its own shift, their
// mean, and how far the Fisher information overstates the rest), and the odometry's, scale error
// included, against the steps: steps of 2 mm, shifted 1.5 mm along the route, against an odometry
// 1.5 % long and 3 cm off a step are finer and explained; steps of 5 cm against an odometry of 5 mm
// are not finer.
TEST(SlamRegistration, StepTranslationIsMeasuredAgainstClosuresAndTheOdometry) {
  SlamConfig cfg;
  const StepScene good = MakeTranslationScene(0.015, 0.03, 0.002, 0.0015);
  const StepTranslation g = MeasureStepTranslation(good.steps, good.skips, good.session, cfg);
  EXPECT_EQ(g.closures, 119u);
  EXPECT_NEAR(g.bias.x(), 0.0015, 0.0005);
  EXPECT_NEAR(g.bias.y(), 0.0, 0.0005);
  EXPECT_NEAR(std::sqrt(g.step_var), 0.002, 0.0006);
  EXPECT_NEAR(g.scale, 0.01, 0.005);
  EXPECT_GT(std::sqrt(g.odom_var), 0.02);
  EXPECT_NEAR(std::sqrt(g.stated_var), cfg.odom_sigma_t_m, 1e-9);
  EXPECT_TRUE(g.finer);
  EXPECT_TRUE(g.explained);

  const StepScene coarse = MakeTranslationScene(0.0, 0.005, 0.05);
  const StepTranslation c = MeasureStepTranslation(coarse.steps, coarse.skips, coarse.session, cfg);
  EXPECT_NEAR(std::sqrt(c.step_var), 0.05, 0.015);
  EXPECT_FALSE(c.finer);
}

// MeasureStepHeading admits steps finer than the odometry whose differences from it their own and
// the odometry's stated variances explain, also against an odometry biased 0.1 deg a step (a
// gyro's bias). Steps that err together (each scan's own turn, which a closure cancels) pass the
// closures and fail against the odometry.
TEST(SlamRegistration, StepsTheOdometryDisagreesWithAreLeftOut) {
  SlamConfig cfg;
  std::mt19937 rng(11);
  std::normal_distribution<double> N(0.0, 0.01 * kDeg);
  std::vector<double> noise(240);
  for (double& e : noise) e = N(rng);
  const double bias = 0.003 * kDeg;
  const StepScene good = MakeStepScene([&](std::size_t k) { return bias + noise[k]; },
                                       [&](std::size_t k) { return bias + noise[120 + k]; });
  const StepHeading g = MeasureStepHeading(good.steps, good.skips, good.session, cfg);
  EXPECT_NEAR(g.bias, bias, 0.003 * kDeg);
  EXPECT_NEAR(std::sqrt(g.odom_var), 0.05 * kDeg, 0.015 * kDeg);
  EXPECT_NEAR(std::sqrt(g.stated_var), cfg.odom_sigma_r_deg * kDeg, 1e-9);
  EXPECT_TRUE(g.finer);
  EXPECT_TRUE(g.explained);

  std::vector<double> own(121);  // each scan's own turn, 0.3 deg
  for (double& e : own) e = 30.0 * N(rng);
  const StepScene together = MakeStepScene([&](std::size_t k) { return own[k + 1] - own[k] + noise[k]; },
                                           [&](std::size_t k) { return own[k + 2] - own[k] + noise[120 + k]; });
  const StepHeading t = MeasureStepHeading(together.steps, together.skips, together.session, cfg);
  EXPECT_TRUE(t.finer);
  EXPECT_FALSE(t.explained);

  const StepScene gyro = MakeStepScene([&](std::size_t k) { return bias + noise[k]; },
                                      [&](std::size_t k) { return bias + noise[120 + k]; }, 0.1 * kDeg);
  const StepHeading y = MeasureStepHeading(gyro.steps, gyro.skips, gyro.session, cfg);
  EXPECT_NEAR(y.odom_mean, -0.1 * kDeg, 0.015 * kDeg);
  EXPECT_TRUE(y.finer);
  EXPECT_TRUE(y.explained);
}
