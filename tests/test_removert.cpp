// LT-removert HD removal: range-image projection, visibility votes, remove-then-revert on a
// synthetic street (ground, walls, thin pillars, a parked car) with a moving car and a walking
// pedestrian, scored point-wise like the KTH DynamicMap benchmark.
#include "test_removert_scene.hpp"
#include "test_util.hpp"

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/removert/removert.hpp"

#include "ltmapper/removert/detail.hpp"  // white-box: fast projection vs geometry
#include "ltmapper/removert/images.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>
#include <random>

namespace ltm {
namespace {

using removert::RemovertConfig;
using removert::WorldKeyframe;

TEST(RemovertProjection, FastPixelsAgreeWithGeometryRangeImage) {
  RemovertConfig cfg = test::ConfigFor();
  for (double res : {0.4, 1.0}) {
    const geometry::RangeImageConfig rc = removert::detail::LevelConfig(cfg, res);
    const geometry::RangeImage ref(rc);
    removert::detail::MultiResImage img(cfg, {res});
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-50.f, 50.f), uz(-15.f, 3.f);
    int same = 0, total = 0, off_by_more = 0;
    for (int i = 0; i < 20000; ++i) {
      const Eigen::Vector3f p(u(rng), u(rng), uz(rng));
      int row, col;
      float r;
      if (!ref.Project(p, &row, &col, &r)) continue;
      float r2, pitch, yaw;
      ASSERT_TRUE(img.Angles(p, &r2, &pitch, &yaw)) << p.transpose();
      const std::size_t pix = img.Pixel(0, pitch, yaw);
      const int frow = int(pix / std::size_t(img.Cols(0))), fcol = int(pix % std::size_t(img.Cols(0)));
      ++total;
      if (frow == row && fcol == col) ++same;
      const int dc = std::min(std::abs(fcol - col), rc.cols - std::abs(fcol - col));
      if (std::abs(frow - row) > 1 || dc > 1) ++off_by_more;
      EXPECT_NEAR(r, r2, 1e-4f);
    }
    EXPECT_GT(total, 5000);
    EXPECT_GE(double(same) / total, 0.995) << "res " << res;
    EXPECT_EQ(off_by_more, 0);
  }
}

TEST(RemovertVotes, SeeThroughHitAndOcclusion) {
  // One keyframe at the origin looking at a wall 10 m ahead.
  const std::vector<test::Box> boxes = {test::MakeBox(10, -20, -5, 10.5, 20, 10, 1)};
  const Pose T = test::At(0, 0, 1.8);
  WorldKeyframe kf;
  kf.T_world_sensor = T;
  kf.cloud = std::make_shared<PointCloud>(test::CastScan(T, boxes, test::Lidar{}));
  PointCloud pts;
  pts.push_back(5.f, 0.3f, 1.8f);    // in front of the wall: seen through
  pts.push_back(10.f, 0.3f, 1.8f);   // on the wall: hit
  pts.push_back(15.f, 0.3f, 1.8f);   // behind the wall: occluded, no vote
  pts.push_back(-200.f, 0.f, 1.8f);  // beyond the submap radius: no vote
  RemovertConfig cfg = test::ConfigFor();
  const auto v = removert::CountVisibility(pts, {kf}, {0.4, 1.0}, cfg, 1);
  for (int l = 0; l < 2; ++l) {
    EXPECT_EQ(v.See(l, 0), 1);
    EXPECT_EQ(v.Hit(l, 0), 0);
    EXPECT_EQ(v.See(l, 1), 0);
    EXPECT_EQ(v.Hit(l, 1), 1);
    EXPECT_EQ(v.See(l, 2), 0);
    EXPECT_EQ(v.Hit(l, 2), 0);
    EXPECT_EQ(v.See(l, 3) + v.Hit(l, 3), 0);
  }
}

// ND's beam evidence is a vote of the keyframes: a point is seen through where more keyframes had a
// beam go through its place than had one end near it. Seed 7's HDL-64E: a fence gone in the
// query, which passed 53-60 m away, whose lower panels 8-11 keyframes' beams went through and 2-4
// ended near (on the plane, within the tolerance): strong ND recall 0.911 -> 0.927 once the
// few stopped vetoing the many.
TEST(RemovertVotes, NdBeamsThatWentThroughOutvoteTheFewThatEndedNear) {
  RemovertConfig cfg;
  removert::VisibilityVotes v;
  v.points = 4;
  v.levels = 1;
  v.see.assign(4, 0);
  v.hit.assign(4, 0);
  v.beam_through = {9, 2, 1, 0};
  v.beam_hits = {3, 2, 0, 0};
  const std::vector<bool> seen = removert::detail::SeenThroughVotes(v, cfg);
  EXPECT_TRUE(seen[0]);   // 9 through, 3 ended near
  EXPECT_FALSE(seen[1]);  // a tie is no majority
  EXPECT_TRUE(seen[2]);   // ld.min_votes (1) through, none near
  EXPECT_FALSE(seen[3]);  // no evidence
}

TEST(RemovertVotes, SurfaceHitsNeedTheReturnOnThePointsPlane) {
  // Sensor 1.8 m above flat ground (z = 0), 2 deg pixels. Ground point A at 20 m: its own pixel's
  // return is the ground 24 m away (the next ring), the window also holds a nearer ring (17 m):
  // far ground sampled sparsely, a surface hit. Ground point B: its pixel's return is an object
  // 0.36 m above the ground in front of it: occluded, not a hit, although as near in range.
  const Pose T = test::At(0, 0, 1.8);
  WorldKeyframe kf;
  kf.T_world_sensor = T;
  auto scan = std::make_shared<PointCloud>();
  scan->push_back(24.f, -0.05f, -1.8f);        // ground ring beyond A, same pixel
  scan->push_back(17.f, -0.05f, -1.8f);        // ground ring before A, the row below
  scan->push_back(16.f, 4.f, 0.36f - 1.8f);    // object in front of B, same pixel
  kf.cloud = scan;
  PointCloud pts;
  pts.push_back(20.f, 0.f, 0.f);  // A
  pts.push_back(20.f, 5.f, 0.f);  // B
  const std::vector<Eigen::Vector3f> up(2, Eigen::Vector3f::UnitZ());
  RemovertConfig cfg = test::ConfigFor();
  removert::VisibilityOptions opt;
  opt.count_occluded = true;
  opt.within_beams = false;  // as LD's occlusion test
  opt.normals = &up;
  opt.surface_max_m = 10.0;
  const auto v = removert::CountVisibility(pts, {kf}, {2.0}, cfg, 1, opt);
  EXPECT_EQ(v.See(0, 0), 0);
  EXPECT_EQ(v.Hit(0, 0), 1);
  EXPECT_EQ(v.See(0, 1), 0);
  EXPECT_EQ(v.Hit(0, 1), 0);
  EXPECT_EQ(v.occ[1], 1);
  // Without normals A is only occluded too (the plain range test misses sparse far ground).
  opt.normals = nullptr;
  const auto plain = removert::CountVisibility(pts, {kf}, {2.0}, cfg, 1, opt);
  EXPECT_EQ(plain.Hit(0, 0), 0);
  EXPECT_EQ(plain.occ[0], 1);
}

// A beam that went on past a point in its own pixel is evidence that the point's place was free
// only where the pixel is narrow enough for its beams to pass within the beam tolerance of the
// point (half the pixel at the point's range <= 0.3 m + tan(0.1 deg) x range): at 1 deg, to 43 m.
// Farther, a return beyond the point in its pixel may be a beam that passed beside or above a
// low structure the other session sampled sparsely.
TEST(RemovertVotes, OwnPixelSeeThroughCountsWhereThePixelIsNarrowerThanTheTolerance) {
  const Pose T = test::At(0, 0, 1.8);
  auto scan = std::make_shared<PointCloud>();
  PointCloud pts;
  for (const auto& [yaw_deg, rho] : std::vector<std::pair<double, double>>{{0.0, 20.0}, {30.0, 50.0}}) {
    const double a = yaw_deg * M_PI / 180.0;
    pts.push_back(float(rho * std::cos(a)), float(rho * std::sin(a)), 1.8f);  // at the sensor's height
    const double beyond = rho + 15.0;                                          // the beam went on
    scan->push_back(float(beyond * std::cos(a)), float(beyond * std::sin(a)), 0.f);
  }
  WorldKeyframe kf;
  kf.T_world_sensor = T;
  kf.cloud = scan;
  std::vector<Eigen::Vector3f> normals;
  for (std::size_t i = 0; i < pts.size(); ++i) normals.push_back(-pts.points[i].xyz().normalized());  // facing the sensor
  RemovertConfig cfg = test::ConfigFor();
  removert::BeamTest beams;
  removert::VisibilityOptions opt;
  opt.normals = &normals;
  opt.beams = &beams;
  opt.count_own_see = true;
  const auto v = removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt);
  ASSERT_EQ(v.see_own.size(), pts.size());
  EXPECT_EQ(v.SeeOwn(0, 0), 1);  // 20 m: half a 1 deg pixel is 0.17 m
  EXPECT_EQ(v.SeeOwn(0, 1), 0);  // 50 m: 0.44 m, wider than the 0.39 m tolerance there
}

// The LD beam test, the sim's beam truth in the scan's own beams: a point's surface was observed
// when a beam ended on it near the point (its ray within the tolerance of the point, its return
// within the along-ray tolerance of it, at most grazing_max_m at grazing incidence), not when the
// point merely lies between two beams that hit the same surface farther away.
TEST(RemovertVotes, BeamTestAsksForABeamThatEndedNearThePoint) {
  // Sensor 1.8 m above flat ground (z = 0); ground points 20 m away (elevation -5.1 deg), none
  // sampled where they are, at azimuths 0, 30, -30, 60, 45, 90, 120 deg.
  const Pose T = test::At(0, 0, 1.8);
  auto at = [](double yaw_deg, double rho, double z) {
    const double a = yaw_deg * M_PI / 180.0;
    return Eigen::Vector3f(float(rho * std::cos(a)), float(rho * std::sin(a)), float(z - 1.8));
  };
  auto scan = std::make_shared<PointCloud>();
  auto add = [&](const Eigen::Vector3f& q) { scan->push_back(q.x(), q.y(), q.z()); };
  add(at(0, 19, 0));       // A: a ring 1 m before it (and one 1.5 m beyond): observed
  add(at(0, 21.5, 0));
  add(at(30, 19, 0.6));    // C: its beams hit a surface 0.6 m higher (a step, beyond the 0.3 m
  add(at(30, 21.5, 0.6));  //    tolerance): not C's surface
  add(at(-30, 19, 0.5));   // B: the lower beam hits an object in front, the upper one lands 4 m
  add(at(-30, 24, 0));     //    beyond it: not observed
  add(at(60, 19.2, 0));    // D: the ground 0.8 m before it, no return above (beyond max range): observed
  add(at(45, 17, 0));      // F: rings 3 m before and 4 m beyond it (more than grazing_max_m 2 m):
  add(at(45, 24, 0));      //    between the beams, not observed (the sim's beam truth: unobserved)
  add(at(90.6, 20, 0));    // G: a return 0.6 deg to its side (two columns away), 0.21 m from its ray
                           //    (within 0.3 m): observed, as the truth counts every ray within tol
  add(at(121.2, 20, 0));   // H: 1.2 deg to its side, 0.42 m from its ray: not observed
  WorldKeyframe kf;
  kf.T_world_sensor = T;
  kf.cloud = scan;
  PointCloud pts;
  for (double yaw : {0.0, 30.0, -30.0, 60.0, 45.0, 90.0, 120.0}) {
    const Eigen::Vector3f p = at(yaw, 20, 0);
    pts.push_back(p.x(), p.y(), 0.f);
  }
  const std::vector<Eigen::Vector3f> up(pts.size(), Eigen::Vector3f::UnitZ());
  RemovertConfig cfg = test::ConfigFor();
  removert::BeamTest beams;
  removert::VisibilityOptions opt;
  opt.normals = &up;
  opt.beams = &beams;
  opt.count_own_see = true;  // also counts "around" (the own-pixel rule's veto)
  const auto v = removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt);
  ASSERT_EQ(v.beam_hits.size(), pts.size());
  EXPECT_EQ(v.beam_hits[0], 1);
  EXPECT_EQ(v.beam_hits[1], 0);
  EXPECT_EQ(v.beam_hits[2], 0);
  EXPECT_EQ(v.beam_hits[3], 1);
  EXPECT_EQ(v.beam_hits[4], 0);
  EXPECT_EQ(v.beam_hits[5], 1);
  EXPECT_EQ(v.beam_hits[6], 0);
  // F lies between two beams that met its surface farther away ("around": the surface runs
  // through its place unsampled, so a beam going on past it there is no sign of free space); C's
  // beams met another surface: not around.
  ASSERT_EQ(v.beam_around.size(), pts.size());
  EXPECT_EQ(v.beam_around[4], 1);
  EXPECT_EQ(v.beam_around[1], 0);
  // With a wider along-ray cap (and a tolerance of 0.4 m, which its ray 0.31 m from F needs) F's
  // ring 3 m before it is near enough.
  removert::BeamTest wide = beams;
  wide.grazing_max_m = 3.5;
  wide.tol_m = 0.4;
  opt.beams = &wide;
  EXPECT_EQ(removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt).beam_hits[4], 1);
  opt.beams = &beams;
  // E: a wall (y = 6 m) seen obliquely (8 deg, 43 m away), its beams 0.15 deg off E's azimuth in the
  // same column and 0.35 deg above / below it (0.26 m off its ray, within the 0.3 m tolerance), so
  // 0.8 m nearer in range (more than the tolerance, within its along-ray tolerance at that
  // incidence): observed.
  removert::BeamTest defaults;
  const double col_scale = std::lround(360.0 / defaults.col_deg) / (2.0 * M_PI);
  const double yaw_e = M_PI - (std::floor((M_PI - 8.0 * M_PI / 180.0) * col_scale) + 0.5) / col_scale;
  auto on_wall = [](double yaw, double pitch_deg) {
    const double rho = 6.0 / std::sin(yaw);
    return Eigen::Vector3f(float(rho * std::cos(yaw)), 6.f, float(rho * std::tan(pitch_deg * M_PI / 180.0)));
  };
  const double off = 0.15 * M_PI / 180.0;
  add(on_wall(yaw_e + off, 0.35));
  add(on_wall(yaw_e + off, -0.35));
  const Eigen::Vector3f e = on_wall(yaw_e, 0.0);
  PointCloud wall;
  wall.push_back(e.x(), e.y(), e.z() + 1.8f);
  const std::vector<Eigen::Vector3f> wall_normal = {Eigen::Vector3f::UnitY()};
  opt.normals = &wall_normal;
  EXPECT_EQ(removert::CountVisibility(wall, {kf}, {1.0}, cfg, 1, opt).beam_hits[0], 1);
  opt.normals = &up;
  // The plain pixel test (2 deg pixel, surface hits up to 10 m) calls A the same surface too.
  opt.beams = nullptr;
  opt.surface_max_m = 10.0;
  const auto pixel = removert::CountVisibility(pts, {kf}, {2.0}, cfg, 1, opt);
  EXPECT_EQ(pixel.Hit(0, 0), 1);
}

// The beam truth takes a return's along-ray tolerance from the surface the ray met, not only from
// the point's: a grazing ray (sensor 1.8 m up, ground 40 m away) that ended on a curb's face 1.2 m
// short of a point on the road behind it did not end on the point's surface, though the face's foot
// lies within the tolerance of the road's plane. The same return on open road 1.2 m short of a point
// (the ground's incidence: tol / cos 2.6 deg, capped at 2 m) did observe it.
TEST(RemovertVotes, BeamTestReadsTheIncidenceOnTheSurfaceTheBeamMet) {
  const Pose T = test::At(0, 0, 1.8);
  auto world = [](double yaw_deg, double rho, double z) {
    const double a = yaw_deg * M_PI / 180.0;
    return Eigen::Vector3f(float(rho * std::cos(a)), float(rho * std::sin(a)), float(z));
  };
  // Points on the road 40 m out at azimuths 0 (behind a curb) and 30 deg (open road).
  PointCloud pts;
  for (double yaw : {0.0, 30.0}) {
    const Eigen::Vector3f p = world(yaw, 40.0, 0.0);
    pts.push_back(p.x(), p.y(), p.z());
  }
  // Each point's ray ended 1.2 m short of it.
  auto scan = std::make_shared<PointCloud>();
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector3f ray = pts.points[i].xyz() - Eigen::Vector3f(0.f, 0.f, 1.8f);
    const Eigen::Vector3f q = ray * (1.f - 1.2f / ray.norm());
    scan->push_back(q.x(), q.y(), q.z());
  }
  // The scan's session's map: the road, and at azimuth 0 a curb face (0.15 m high, x = 38.8 m,
  // across the ray) where that ray ended, sampled every 5 cm.
  PointCloud map;
  for (double x = 30.0; x <= 45.0; x += 0.2)
    for (double y = -1.0; y <= 26.0; y += 0.2) map.push_back(float(x), float(y), x > 38.8 ? 0.15f : 0.f);
  for (double y = -1.0; y <= 1.0; y += 0.05)
    for (double z = 0.0; z <= 0.151; z += 0.05) map.push_back(38.8f, float(y), float(z));
  WorldKeyframe kf;
  kf.T_world_sensor = T;
  kf.cloud = scan;
  const std::vector<Eigen::Vector3f> up(pts.size(), Eigen::Vector3f::UnitZ());
  const RemovertConfig cfg = test::ConfigFor();
  removert::BeamTest beams;
  removert::VisibilityOptions opt;
  opt.normals = &up;
  opt.beams = &beams;
  const auto plane_only = removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt);
  EXPECT_EQ(plane_only.beam_hits[0], 1);  // the point's plane alone: 1.2 m is within its 2 m
  EXPECT_EQ(plane_only.beam_hits[1], 1);
  const removert::detail::HitSurfaces hits(map, pts, beams, 1);
  opt.hit_surfaces = &hits;
  const auto v = removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt);
  EXPECT_EQ(v.beam_hits[0], 0);  // the curb's face: 1.2 m is beyond its 0.3 m
  EXPECT_EQ(v.beam_hits[1], 1);  // the road: as before
}

// The beam test's columns are one azimuth step wide: a cell keeps its nearest return, so a column
// two steps wide (0.4 deg for a VLP-16's 0.2 deg) would hold two returns of a beam and lose the
// farther. Here the return that ended on the ground 1 m beyond a point 33 m away shares a 0.4 deg
// column with its neighbour, which met a post at 20 m.
TEST(RemovertVotes, BeamTestKeepsEveryReturnOfABeam) {
  RemovertConfig cfg = test::ConfigFor();
  cfg.sensor = "vlp16";  // beams every 2 deg from +15 to -15, azimuth step 0.2 deg
  cfg.sensor_elevations_deg.clear();
  cfg.sensor_model = {};
  cfg.fov_up_deg = cfg.fov_down_deg = 0.0;
  cfg = removert::WithSensor(cfg, {});
  ASSERT_DOUBLE_EQ(cfg.sensor_model.azimuth_step_deg, 0.2);
  constexpr double kDeg = M_PI / 180.0, kHeight = 1.8, kBeam = -3.0 * kDeg;
  // Yaws 19.7 and 19.9 deg: one 0.4 deg column (columns count from yaw 180 deg), two 0.2 deg ones.
  const double yaw = 19.7 * kDeg, ring = kHeight / std::tan(-kBeam);  // the beam meets the ground 34.3 m out
  auto scan = std::make_shared<PointCloud>();
  auto add = [&](double az, double range) {
    const Eigen::Vector3d d = test::Direction(kBeam, az) * range;
    scan->push_back(float(d.x()), float(d.y()), float(d.z()));
  };
  add(yaw, ring / std::cos(kBeam));  // on the ground 1 m beyond the point
  add(yaw + 0.2 * kDeg, 20.0);        // its neighbour: a post
  WorldKeyframe kf;
  kf.T_world_sensor = test::At(0, 0, kHeight);
  kf.cloud = scan;
  PointCloud pts;
  pts.push_back(float((ring - 1.0) * std::cos(yaw)), float((ring - 1.0) * std::sin(yaw)), 0.f);
  const std::vector<Eigen::Vector3f> up = {Eigen::Vector3f::UnitZ()};
  removert::BeamTest beams;
  removert::VisibilityOptions opt;
  opt.normals = &up;
  opt.beams = &beams;
  EXPECT_EQ(removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt).beam_hits[0], 1);
}

// test::ConfigFor's settings with `sensor` (a preset, or auto) not yet resolved (WithSensor).
RemovertConfig UnresolvedConfig(const std::string& sensor) {
  RemovertConfig cfg = test::ConfigFor();
  cfg.sensor = sensor;
  cfg.sensor_elevations_deg.clear();
  cfg.sensor_model = {};
  cfg.fov_up_deg = cfg.fov_down_deg = 0.0;
  return cfg;
}

// test::ConfigFor's settings with the VLP-16 preset's sensor (16 beams 2 deg apart, 0.2 deg steps).
RemovertConfig Vlp16Config() { return removert::WithSensor(UnresolvedConfig("vlp16"), {}); }

// A ring sensor fires every beam at every azimuth step, so a beam that passed a point and has no
// return there went on and met nothing: the point's place was free (an appeared structure's place,
// the sky behind it; the beams below met the ground). Not where the cells hold a return of any
// range (a truck 1.8 m from the sensor, nearer than sensor.min_range_m, blocked the beam), nor at
// a lone empty cell (a dropped return, its neighbours met a wall), nor where whole columns hold no
// return (the seam where a deskewed sweep starts and ends).
TEST(RemovertVotes, ABeamThatPassedWithoutAReturnSawThePlaceFree) {
  RemovertConfig cfg = Vlp16Config();
  constexpr double kDeg = M_PI / 180.0;
  const double beam = 1.0 * kDeg, ground = -15.0 * kDeg;  // two of the VLP-16's beams
  PointCloud pts;
  const Eigen::Vector3d p = test::Direction(beam + 0.1 * kDeg, 10.1 * kDeg) * 40.0;  // 0.07 m off the beam
  pts.push_back(float(p.x()), float(p.y()), float(p.z() + 1.8));
  const std::vector<Eigen::Vector3f> side = {-p.cast<float>().normalized()};  // an upright face
  enum Case { kSky, kTruck, kDropped, kSeam, kBlind };
  // Every 0.2 deg of azimuth from 0 to 20 deg: the -15 deg beam on the ground, the +1 deg beam on a
  // wall 60 m away; within 1 deg of the point's azimuth the +1 deg beam meets nothing (sky, seam)
  // or the truck; dropped: only its return at 10.0 deg is missing; seam: the ground's too; blind: a
  // car passing beside the sensor, which the -1 deg beam meets just beyond the minimum range and
  // the +1 deg beam nearer than it (no return).
  auto scan_of = [&](Case what) {
    auto scan = std::make_shared<PointCloud>();
    auto add = [&](double el, double az, double r) {
      const Eigen::Vector3d q = test::Direction(el, az) * r;
      scan->push_back(float(q.x()), float(q.y()), float(q.z()));
    };
    for (int k = 0; k < 100; ++k) {
      const double a = 0.2 * k * kDeg;
      const bool near = std::fabs(0.2 * k - 10.1) < 1.0;
      if (!(what == kSeam && near)) add(ground, a, 1.8 / std::sin(-ground));
      if (what == kDropped ? k != 50 : !near) add(beam, a, 60.0);
      else if (what == kTruck) add(beam, a, 1.8);
      if (what == kBlind && near) add(-1.0 * kDeg, a, cfg.min_range_m + 0.1);
    }
    return scan;
  };
  auto passed = [&](Case what) {
    WorldKeyframe kf;
    kf.T_world_sensor = test::At(0, 0, 1.8);
    kf.cloud = scan_of(what);
    removert::BeamTest beams;
    removert::VisibilityOptions opt;
    opt.normals = &side;
    opt.beams = &beams;
    opt.count_own_see = true;
    return removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt).beam_passed.at(0);
  };
  EXPECT_EQ(passed(kSky), 1);
  EXPECT_EQ(passed(kTruck), 0);
  EXPECT_EQ(passed(kDropped), 0);
  EXPECT_EQ(passed(kSeam), 0);
  EXPECT_EQ(passed(kBlind), 0);
  // Scans whose beams scatter about the table (deskewed sweeps: here 3 x 0.4 deg reaches halfway
  // to the neighbours 2 deg away) cannot tell which beam is which: no evidence. Short of halfway
  // (3 x 0.3 deg) they can.
  using removert::detail::ColumnImage;
  EXPECT_TRUE(ColumnImage::TellsItsReturns(cfg.sensor_model, 1.0));
  cfg.sensor_model.spread_deg = 0.3;
  EXPECT_TRUE(ColumnImage::TellsItsReturns(cfg.sensor_model, 1.0));
  EXPECT_EQ(passed(kSky), 1);
  cfg.sensor_model.spread_deg = 0.4;
  EXPECT_FALSE(ColumnImage::TellsItsReturns(cfg.sensor_model, 1.0));
  EXPECT_EQ(passed(kSky), 0);
}

// A raw sweep of a 16-beam sensor (+15 .. -15 deg, 0.2 deg columns) turning once in 0.1 s while it
// moves 8 m/s along x, inside a cylinder of 8 m radius over the ground 1.8 m below: each point in the
// frame its column fired from, with its time (as a raw sweep file holds them). *deskewed: the same
// points moved into the keyframe frame (io::Deskew).
PointCloud RawSweepInACylinder(PointCloud* deskewed) {
  constexpr double kDeg = M_PI / 180.0, kRadius = 8.0, kHeight = 1.8, kSweepS = 0.1;
  const Eigen::Vector3d v(8.0, 0.0, 0.0);
  constexpr int kColumns = 1800;
  PointCloud raw;
  for (int c = 0; c < kColumns; ++c) {
    const double t = kSweepS * c / kColumns, az = (-180.0 + 0.2 * c) * kDeg;
    const Eigen::Vector3d o = t * v;
    for (int b = 0; b < 16; ++b) {
      const double e = (15.0 - 2.0 * b) * kDeg;
      const Eigen::Vector3d d(std::cos(e) * std::cos(az), std::cos(e) * std::sin(az), std::sin(e));
      // The cylinder |o + s d|_xy = R (s > 0), or the ground first.
      const double a = d.x() * d.x() + d.y() * d.y(), bb = 2.0 * (o.x() * d.x() + o.y() * d.y());
      const double cc = o.x() * o.x() + o.y() * o.y() - kRadius * kRadius;
      double s = (-bb + std::sqrt(bb * bb - 4.0 * a * cc)) / (2.0 * a);
      if (d.z() < 0.0) s = std::min(s, -kHeight / d.z());
      const Eigen::Vector3d p = s * d;  // in the firing frame (no turn: its axes are the keyframe's)
      raw.push_back(float(p.x()), float(p.y()), float(p.z()), 1.f);
      raw.time.push_back(float(t));
      deskewed->push_back(float(p.x() + o.x()), float(p.y() + o.y()), float(p.z() + o.z()), 1.f);
    }
  }
  return raw;
}

// The motion of RawSweepInACylinder's sensor: 8 m/s along x, no turn.
SweepMotion CylinderSweepMotion() {
  SweepMotion m;
  m.known = true;
  m.v_mps = Eigen::Vector3d(8.0, 0.0, 0.0);
  return m;
}

// A config whose sensor is estimated from the scans, returns from 1 m on.
RemovertConfig SensorFromTheScans() {
  RemovertConfig cfg = UnresolvedConfig("auto");
  cfg.min_range_m = 1.0;
  return cfg;
}

// The votes take four points at a time (SweepFrames::ToFiring4): each lane is the one-point
// ToFiring bit for bit, its rotation and its angles too, so a point's pixels do not depend on
// its neighbours in the tile. Every point of the sweep, seam included.
TEST(RemovertVotes, FourPointsAreSeenFromWhereTheirColumnsFiredAsOne) {
  PointCloud deskewed;
  const PointCloud raw = RawSweepInACylinder(&deskewed);
  const removert::detail::SweepFrames frames(raw, CylinderSweepMotion());
  ASSERT_TRUE(frames.active());
  std::size_t differ = 0;
  for (std::size_t i = 0; i + 4 <= deskewed.size(); i += 4) {
    float q[12], p[12], range[4], pitch[4], yaw[4];
    const Eigen::Matrix3f* turn[4];
    for (std::size_t k = 0; k < 4; ++k)
      for (int a = 0; a < 3; ++a) q[4 * a + int(k)] = deskewed.points[i + k].xyz()(a);
    frames.ToFiring4(q, p, turn, range, pitch, yaw);
    for (std::size_t k = 0; k < 4; ++k) {
      Eigen::Matrix3f R;
      const Eigen::Vector3f one = frames.ToFiring(deskewed.points[i + k].xyz(), &R);
      const Eigen::Vector3f four(p[k], p[4 + k], p[8 + k]);
      const bool same = one == four && R == *turn[k] && range[k] == one.norm() &&
                        pitch[k] == removert::detail::FastAtan2(one.z(), std::sqrt(one.x() * one.x() + one.y() * one.y())) &&
                        yaw[k] == removert::detail::FastAtan2(one.y(), one.x());
      differ += same ? 0 : 1;
    }
  }
  EXPECT_EQ(differ, 0u);
}

// A run resolves the central session's sensor in each stage; the estimate is remembered by the
// scans' contents, never by their paths: a file rewritten in between is estimated again.
TEST(RemovertSensor, AScanRewrittenBetweenTwoResolutionsIsEstimatedAgain) {
  PointCloud deskewed;
  const PointCloud raw = RawSweepInACylinder(&deskewed);
  PointCloud half;  // every other beam (the cylinder sweep's points run beam by beam per column)
  for (std::size_t i = 0; i < raw.size(); i += 2) {
    half.points.push_back(raw.points[i]);
    half.time.push_back(raw.time[i]);
  }
  test::TempDir tmp;
  WorldKeyframe kf;
  kf.cloud_path = tmp / "000000.pcd";
  kf.sweep = CylinderSweepMotion();
  io::WritePcd(kf.cloud_path, raw);
  EXPECT_EQ(removert::WithSensor(SensorFromTheScans(), {kf}).sensor_model.beams(), 16);
  io::WritePcd(kf.cloud_path, half);
  EXPECT_EQ(removert::WithSensor(SensorFromTheScans(), {kf}).sensor_model.beams(), 8);
  io::WritePcd(kf.cloud_path, raw);  // resolved before: the same model
  const geometry::SensorModel again = removert::WithSensor(SensorFromTheScans(), {kf}).sensor_model;
  EXPECT_EQ(again.beams(), 16);
  EXPECT_EQ(again.elevations_deg, removert::WithSensor(SensorFromTheScans(), {kf}, 1).sensor_model.elevations_deg);
}

// A raw sweep's range images keep the beams' own elevations: the sensor estimated from it scatters
// nothing about its beams, so every beam tells its returns from its neighbours' and a beam that
// passed a point without a return is evidence (ColumnImage::TellsItsReturns). Deskewed into the
// keyframe frame, the near ground's returns of the steep beams are bent by the sensor's travel
// during the sweep (0.8 m): the beams cannot be told apart. A point asked
// in the keyframe frame is asked in the frame its column fired from (SweepFrames::ToFiring).
TEST(RemovertVotes, ARawSweepIsSeenFromWhereItsColumnsFired) {
  PointCloud deskewed;
  const PointCloud raw = RawSweepInACylinder(&deskewed);
  const SweepMotion motion = CylinderSweepMotion();
  const removert::detail::SweepFrames frames(raw, motion);
  ASSERT_TRUE(frames.active());
  std::size_t near = 0;
  for (std::size_t i = 0; i < raw.size(); ++i)
    near += (frames.ToFiring(deskewed.points[i].xyz(), nullptr) - raw.points[i].xyz()).norm() < 0.01f ? 1 : 0;
  EXPECT_GT(double(near), 0.99 * double(raw.size()));  // all but the seam's, where the sweep begins and ends
  const RemovertConfig cfg = SensorFromTheScans();
  test::TempDir tmp;
  WorldKeyframe kf;
  kf.cloud_path = tmp / "000000.pcd";  // a raw sweep file: its points with their `time`
  io::WritePcd(kf.cloud_path, raw);
  kf.sweep = motion;
  const geometry::SensorModel from_raw = removert::WithSensor(cfg, {kf}).sensor_model;
  ASSERT_EQ(from_raw.beams(), 16);
  EXPECT_LT(from_raw.spread_deg, 0.01);
  using removert::detail::ColumnImage;
  for (const double e : from_raw.elevations_deg) EXPECT_TRUE(ColumnImage::TellsItsReturns(from_raw, e)) << e;
  kf.cloud_path = tmp / "000001.pcd";  // the same sweep deskewed (no `time`), its motion unknown
  io::WritePcd(kf.cloud_path, deskewed);
  kf.sweep = SweepMotion{};
  const RemovertConfig unknown = removert::WithSensor(cfg, {kf});
  EXPECT_FALSE(unknown.sweep_timing.known);
  const geometry::SensorModel& from_deskewed = unknown.sensor_model;
  bool all_tell = from_deskewed.ring_based;  // here the bent peaks blur: no rings found at all
  for (const double e : from_deskewed.elevations_deg) all_tell = all_tell && ColumnImage::TellsItsReturns(from_deskewed, e);
  EXPECT_FALSE(all_tell);
}

// A sweep saved deskewed in a session with keyframe times (its motion known) is put back into the
// frames its columns fired from. io::Reskew with the sweep's timing (azimuth rising from -180 deg
// through one turn in 0.1 s, stamped at its start) gives the raw sweep back; the timing is
// estimated from the deskewed scan alone (EstimateSweepTiming); WithSensor re-skews with it, so
// the sensor estimated from the scan is the raw sweep's: 16 beams, each telling its returns.
TEST(RemovertVotes, ADeskewedSweepIsPutBackWhereItsColumnsFired) {
  PointCloud deskewed;
  const PointCloud raw = RawSweepInACylinder(&deskewed);
  const SweepMotion motion = CylinderSweepMotion();
  const SweepTiming truth{true, 0.1, -M_PI, -1, 0.0};
  const PointCloud back = io::Reskew(deskewed, motion, truth);
  ASSERT_EQ(back.time.size(), raw.size());
  std::size_t near = 0;
  for (std::size_t i = 0; i < raw.size(); ++i)
    near += (back.points[i].xyz() - raw.points[i].xyz()).norm() < 0.01f && std::fabs(back.time[i] - raw.time[i]) < 1e-3f;
  EXPECT_GT(double(near), 0.99 * double(raw.size()));  // all but the seam's
  const SweepTiming est = removert::detail::EstimateSweepTiming({deskewed}, {motion}, 1.0, 2);
  ASSERT_TRUE(est.known);
  const SweepTiming one = removert::detail::EstimateSweepTiming({deskewed}, {motion}, 1.0, 1);  // the same on one worker
  EXPECT_TRUE(one.period_s == est.period_s && one.start_rad == est.start_rad && one.turn == est.turn &&
              one.stamp_share == est.stamp_share);
  EXPECT_EQ(est.turn, -1);
  EXPECT_NEAR(est.period_s, 0.1, 0.005);
  EXPECT_NEAR(std::fabs(std::remainder(est.start_rad, 2.0 * M_PI)), M_PI, 2.0 * M_PI / 180.0);
  EXPECT_NEAR(est.stamp_share, 0.0, 0.03);
  const RemovertConfig cfg = SensorFromTheScans();
  test::TempDir tmp;
  WorldKeyframe kf;
  kf.cloud_path = tmp / "000000.pcd";
  io::WritePcd(kf.cloud_path, deskewed);
  kf.sweep = motion;
  const RemovertConfig resolved = removert::WithSensor(cfg, {kf});
  EXPECT_TRUE(resolved.sweep_timing.known);
  const geometry::SensorModel& m = resolved.sensor_model;
  ASSERT_EQ(m.beams(), 16);
  EXPECT_EQ(removert::detail::ColumnImage::BeamsThatTell(m), 16);
  // The votes read it re-skewed, with the frames to ask its points in.
  removert::detail::SweepFrames frames;
  const auto voter = removert::detail::LoadVoterScan(kf, resolved.sweep_timing, &frames);
  EXPECT_TRUE(frames.active());
  EXPECT_EQ(voter->time.size(), deskewed.size());
}

// Real scans: KITTI's HDL-64E sweeps (kitti00_head) are raw, each column in the frame it fired
// from, but carry no per-point time, so a session with keyframe times takes them for deskewed
// ones. No timing may then be used: re-skewing a raw sweep moves its returns off their beams a
// second time. The estimate runs (the motion: 0.69 m per 0.1 s frame, as these scans register,
// and a slight turn) and its result is not kept: it makes no larger share of the beams tell.
TEST(RemovertReal, RawKittiScansTakenForDeskewedGetNoSweepTiming) {
  LTM_REQUIRE_REAL_DATA(data);
  SweepMotion motion;
  motion.known = true;
  motion.v_mps = Eigen::Vector3d(6.9, 0.0, 0.0);
  motion.w_radps = Eigen::Vector3d(0.0, 0.0, 0.1);
  std::vector<WorldKeyframe> kfs;
  for (int k = 0; k < 6; ++k) {
    WorldKeyframe kf;
    kf.index = k;
    kf.sweep = motion;
    kf.cloud_path = data + "/kitti00_head/velodyne/00000" + std::to_string(k) + ".bin";
    kfs.push_back(kf);
  }
  const RemovertConfig resolved = removert::WithSensor(UnresolvedConfig("auto"), kfs, 2);
  EXPECT_FALSE(resolved.sweep_timing.known);
  EXPECT_EQ(resolved.sensor_model.beams(), 64);
}

// The beam truth calls a point observed only where a ray of the other session passed within the
// tolerance of it. A sparse sensor's pixel between two of its beams holds what they met around the
// point, behind it too (the sky over a facade's top, a wall behind a fence), so for ND its
// see-through counts only from a keyframe a beam of which passed within the tolerance of the point
// (ColumnImage::BeamNear, kBeamNear). Here the VLP-16's +1 and -1 deg beams meet a wall 60 m away
// behind a point 40 m away: at 0 deg elevation no beam passed within 0.3 m of it (1 deg is 0.7 m
// there), at +0.9 deg the +1 deg beam passed 0.07 m from it.
TEST(RemovertVotes, NdSeeThroughCountsWhereABeamPassedThePoint) {
  RemovertConfig cfg = Vlp16Config();
  constexpr double kDeg = M_PI / 180.0;
  WorldKeyframe kf;
  kf.T_world_sensor = test::At(0, 0, 1.8);
  auto scan = std::make_shared<PointCloud>();
  for (int k = 0; k < 100; ++k)
    for (const double el : {1.0, -1.0, -15.0}) {
      const Eigen::Vector3d q = test::Direction(el * kDeg, 0.2 * k * kDeg) * (el < -10.0 ? 1.8 / std::sin(15.0 * kDeg) : 60.0);
      scan->push_back(float(q.x()), float(q.y()), float(q.z()));
    }
  kf.cloud = scan;
  auto see = [&](double el_deg, bool beam_test = true) {
    PointCloud pts;
    const Eigen::Vector3d p = test::Direction(el_deg * kDeg, 10.1 * kDeg) * 40.0;
    pts.push_back(float(p.x()), float(p.y()), float(p.z() + 1.8));
    const std::vector<Eigen::Vector3f> side = {-p.cast<float>().normalized()};  // an upright face
    removert::BeamTest beams;
    removert::VisibilityOptions opt;
    opt.normals = &side;
    opt.beams = beam_test ? &beams : nullptr;
    const removert::VisibilityVotes v = removert::CountVisibility(pts, {kf}, {1.0}, cfg, 1, opt);
    return int(v.See(0, 0));
  };
  EXPECT_EQ(see(0.0, false), 1);  // the pixel alone: seen through
  EXPECT_EQ(see(0.0), 0);
  EXPECT_EQ(see(0.9), 1);
}

// The street scene: 21 keyframes 2 m apart along x.
struct Street {
  std::vector<WorldKeyframe> kfs;
  PointCloud truth;  // world frame, object = label (>= 100: HD)
};

// Directions of a non-repetitive scanner (no rings, Livox-like forward cone): n uniform over
// azimuths -+35 deg and elevations fov_down .. fov_up, another draw each scan.
std::vector<Eigen::Vector3d> NonRepetitiveDirections(std::mt19937& rng, int n = 40000, double fov_up_deg = 2.0,
                                                     double fov_down_deg = -24.8) {
  constexpr double kDeg = M_PI / 180.0;
  std::uniform_real_distribution<double> az(-35.0 * kDeg, 35.0 * kDeg), sin_el(std::sin(fov_down_deg * kDeg), std::sin(fov_up_deg * kDeg));
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < n; ++i) dirs.push_back(test::Direction(std::asin(sin_el(rng)), az(rng)));
  return dirs;
}

// The street's movers at keyframe k: an oncoming car in the other lane and a pedestrian crossing
// at x = 8.
std::vector<test::Box> CrossingMovers(int k) {
  const double cx = 30.0 - 3.0 * k, py = -6.0 + 0.6 * k;
  return {test::MakeBox(cx - 2, 2, 0.3, cx + 2, 4, 1.8, 100), test::MakeBox(7.75, py - 0.25, 0.05, 8.25, py + 0.25, 1.8, 101)};
}

Street MakeStreet(double pose_noise = 0.0, bool non_repetitive = false,
                  const std::function<std::vector<test::Box>(int)>& movers = CrossingMovers,
                  const test::Lidar& lidar = {}) {
  std::mt19937 rng(42);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<test::Box> fixed = {
      test::MakeBox(-40, 8, 0, 40, 8.3, 4, 1),     // walls
      test::MakeBox(-40, -8.3, 0, 40, -8, 4, 2),
      test::MakeBox(-15, 5, 0, -14.7, 5.3, 3, 3),  // thin pillars
      test::MakeBox(-5, 5, 0, -4.7, 5.3, 3, 4),
      test::MakeBox(5, 5, 0, 5.3, 5.3, 3, 5),
      test::MakeBox(15, 5, 0, 15.3, 5.3, 3, 6),
      test::MakeBox(-2, -6, 0.3, 2, -4, 1.8, 7),   // parked car (static)
  };
  Street s;
  for (int k = 0; k <= 20; ++k) {
    std::vector<test::Box> boxes = fixed;
    for (const test::Box& b : movers(k)) boxes.push_back(b);
    WorldKeyframe kf;
    kf.index = k;
    kf.T_world_sensor = test::At(-20.0 + 2.0 * k, 0.0, 1.8, 0.02 * k);
    auto scan = std::make_shared<PointCloud>(
        non_repetitive ? test::CastDirections(kf.T_world_sensor, boxes, NonRepetitiveDirections(rng), test::Lidar{}.max_range)
                       : test::CastScan(kf.T_world_sensor, boxes, lidar));
    s.truth.append(test::ToWorld(*scan, kf.T_world_sensor));
    kf.cloud = scan;
    if (pose_noise > 0.0) {  // the method gets slightly wrong poses, like any SLAM output
      kf.T_world_sensor.translation() += pose_noise * Eigen::Vector3d(g(rng), g(rng), 0.3 * g(rng));
      kf.T_world_sensor.linear() =
          kf.T_world_sensor.linear() *
          Eigen::AngleAxisd(pose_noise * 0.02 * g(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    }
    s.kfs.push_back(kf);
  }
  return s;
}

struct Score {
  double sa = 0, da = 0;
};
// KTH rule: a truth point is preserved when an output point lies within `d`.
Score ScoreHd(const PointCloud& truth, const PointCloud& static_map, double d = 0.15) {
  const geometry::KdTree tree(static_map);
  std::size_t st = 0, sp = 0, dt = 0, dr = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const bool hd = truth.object[i] >= 100;
    const bool kept = tree.CountWithin(truth.points[i].xyz(), float(d), 1) >= 1;
    if (hd) {
      ++dt;
      dr += kept ? 0 : 1;
    } else {
      ++st;
      sp += kept ? 1 : 0;
    }
  }
  if (std::getenv("LTM_DEBUG_HD")) {
    std::map<int, std::pair<int, int>> by;  // label -> (total, kept)
    for (std::size_t i = 0; i < truth.size(); ++i) {
      auto& e = by[truth.object[i]];
      ++e.first;
      e.second += tree.CountWithin(truth.points[i].xyz(), float(d), 1) >= 1 ? 1 : 0;
    }
    std::map<std::string, int> where;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      if (truth.object[i] != -1) continue;
      if (tree.CountWithin(truth.points[i].xyz(), float(d), 1) >= 1) continue;
      const auto& p = truth.points[i];
      std::string w = (p.y >= 1.5 && p.y <= 4.5) ? "lane" : (std::fabs(p.x - 8) < 1.0 ? "ped" : "other");
      const double r = std::hypot(p.y, std::max(0.0, std::fabs(p.x) - 20.0));
      w += r < 8 ? "_near" : (r < 20 ? "_mid" : "_far");
      ++where[w];
    }
    for (auto& [k, v] : where) std::printf("  lost ground %s: %d\n", k.c_str(), v);
    for (auto& [k, v] : by) std::printf("  label %d: %d total, %d kept\n", k, v.first, v.second);
  }
  return {double(sp) / double(st), double(dr) / double(dt)};
}

TEST(RemovertHd, RemovesMoversKeepsStaticStreet) {
  const Street s = MakeStreet();
  RemovertConfig cfg = test::ConfigFor();
  const auto res = removert::RemoveHd(s.kfs, cfg, 2);
  EXPECT_EQ(res.static_map.size() + res.hd_map.size(), res.stats.map_points);
  const Score sc = ScoreHd(s.truth, res.static_map);
  std::printf("remove-then-revert: SA %.4f DA %.4f (candidates %zu, reverted %zu, removed %zu)\n",
              sc.sa, sc.da, res.stats.candidates, res.stats.reverted, res.stats.removed);
  EXPECT_GE(sc.sa, 0.99);
  EXPECT_GE(sc.da, 0.95);
  EXPECT_EQ(res.hd_map.size(), res.stats.removed + res.stats.dilated);

  // Dilation off: the same removal, nothing added; with 0.5 m (the movers ride 0.3 m above the
  // ground here) ground points are added, each within 0.5 m of a removed point.
  RemovertConfig plain = cfg, wide = cfg;
  plain.dilate_voxels = 0.0;
  wide.dilate_voxels = 5.0;
  const auto p = removert::RemoveHd(s.kfs, plain, 2);
  const auto w = removert::RemoveHd(s.kfs, wide, 2);
  EXPECT_EQ(p.stats.dilated, 0u);
  EXPECT_EQ(p.stats.removed, res.stats.removed);
  EXPECT_EQ(w.stats.removed, res.stats.removed);
  EXPECT_GT(w.stats.dilated, 0u);
  EXPECT_EQ(w.hd_map.size(), w.stats.removed + w.stats.dilated);
  const geometry::KdTree removed(p.hd_map);
  std::size_t far = 0;
  for (const auto& q : w.hd_map.points) {
    std::uint32_t j = 0;
    float d2 = 0.f;
    far += !(removed.Nearest(q.xyz(), &j, &d2) && d2 <= 0.25f * 1.0001f);
  }
  EXPECT_EQ(far, 0u);
}

// Poses a few tenths of a degree off (yaw, as odometry drifts) make a keyframe see past the edges
// of the thin pillars and the parked car: pose_sigma_deg widens the windows by that error, and they
// keep their points.
TEST(RemovertHd, PoseErrorMarginKeepsThinStructures) {
  Street s = MakeStreet();
  for (std::size_t k = 0; k < s.kfs.size(); ++k) {  // +-0.3 deg, alternating in blocks of three
    const double yaw = ((k / 3) % 2 ? 0.3 : -0.3) * M_PI / 180.0;
    s.kfs[k].T_world_sensor.linear() =
        s.kfs[k].T_world_sensor.linear() * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  RemovertConfig exact = test::ConfigFor(), margin = exact;
  exact.pose_sigma_deg = 0.0;
  margin.pose_sigma_deg = 0.3;
  const PointCloud ma = removert::RemoveHd(s.kfs, exact, 2).static_map;
  const PointCloud mb = removert::RemoveHd(s.kfs, margin, 2).static_map;
  auto thin_lost = [&](const PointCloud& map) {  // pillars (labels 3-6) and the parked car (7)
    const geometry::KdTree tree(map);
    std::size_t lost = 0;
    for (std::size_t i = 0; i < s.truth.size(); ++i)
      lost += s.truth.object[i] >= 3 && s.truth.object[i] <= 7 && tree.CountWithin(s.truth.points[i].xyz(), 0.15f, 1) == 0;
    return lost;
  };
  const Score a = ScoreHd(s.truth, ma), b = ScoreHd(s.truth, mb);
  const std::size_t la = thin_lost(ma), lb = thin_lost(mb);
  std::printf("yaw errors +-0.3 deg: pillar and car points lost %zu without the margin, %zu with it; SA %.4f -> %.4f, "
              "DA %.4f -> %.4f\n", la, lb, a.sa, b.sa, a.da, b.da);
  EXPECT_GT(la, 20u);
  EXPECT_LT(4 * lb, la);
  EXPECT_GE(b.sa, a.sa);
  EXPECT_GE(b.da, 0.95);
}

// The same on a scanner without rings (Livox-like): the windows at yaw -+ pose_sigma_deg may only
// withdraw a see-through where the point's own window has evidence (a return above and below
// it); read like a ring sensor's they would fill the pattern's gaps with returns no ray near the
// point made and remove more of the static map, not less.
TEST(RemovertHd, PoseErrorMarginWithoutRingsOnlyKeepsPoints) {
  Street s = MakeStreet(0.0, true);
  for (std::size_t k = 0; k < s.kfs.size(); ++k) {  // +-0.3 deg, alternating in blocks of three
    const double yaw = ((k / 3) % 2 ? 0.3 : -0.3) * M_PI / 180.0;
    s.kfs[k].T_world_sensor.linear() =
        s.kfs[k].T_world_sensor.linear() * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  RemovertConfig exact;
  exact = removert::WithSensor(exact, s.kfs);
  ASSERT_FALSE(exact.sensor_model.ring_based);
  RemovertConfig margin = exact;
  exact.pose_sigma_deg = 0.0;
  margin.pose_sigma_deg = 0.3;
  const auto a = removert::RemoveHd(s.kfs, exact, 2), b = removert::RemoveHd(s.kfs, margin, 2);
  const Score sa = ScoreHd(s.truth, a.static_map), sb = ScoreHd(s.truth, b.static_map);
  std::printf("no rings, yaw errors +-0.3 deg: removed %zu without the margin, %zu with it; SA %.4f -> %.4f, DA %.4f -> %.4f\n",
              a.hd_map.size(), b.hd_map.size(), sa.sa, sb.sa, sa.da, sb.da);
  EXPECT_LT(sa.sa, 0.999) << "the pose errors must cost static points for the test to mean anything";
  EXPECT_GT(sb.sa, sa.sa);
  EXPECT_LE(b.hd_map.size(), a.hd_map.size());
  EXPECT_GE(sb.da, 0.9);
}

// Issue #16: the session map's batches grew with --threads, and a voxel's centroid summed in
// another order changed the map's last bits (the demo's live.pcd differed between --threads 16
// and 2). The map and the HD result are now the same bytes for any thread count.
TEST(RemovertHd, SameResultForAnyThreadCount) {
  const Street s = MakeStreet();
  RemovertConfig cfg = test::ConfigFor();
  std::vector<WorldKeyframe> kfs;
  while (kfs.size() < 70) kfs.insert(kfs.end(), s.kfs.begin(), s.kfs.end());  // several batches
  const PointCloud one = removert::BuildSessionMap(kfs, cfg, 1);
  for (int threads : {2, 7, 16}) {
    const PointCloud other = removert::BuildSessionMap(kfs, cfg, threads);
    ASSERT_EQ(other.size(), one.size()) << threads << " threads";
    EXPECT_EQ(0, std::memcmp(other.points.data(), one.points.data(), one.size() * sizeof(PointXYZI)))
        << threads << " threads";
  }
  const auto a = removert::RemoveHd(s.kfs, cfg, 1), b = removert::RemoveHd(s.kfs, cfg, 16);
  ASSERT_EQ(a.static_map.size(), b.static_map.size());
  EXPECT_EQ(0, std::memcmp(a.static_map.points.data(), b.static_map.points.data(),
                           a.static_map.size() * sizeof(PointXYZI)));
}

// A pedestrian walking ahead of the sensor along its lane (x 40 -> 50 m, 0.5 m per keyframe, while
// the sensor drives x -20 -> 20 m): the later returns on the body lie along the upright "surface"
// its earlier places left in the map, seen at a grazing angle, and as surface hits they reverted
// a quarter of the trail's candidates (44 of 182; DA 0.66). An upright surface now takes surface
// hits only where the map without the candidates holds a parallel upright plane (the walls, the
// pillars): the trail goes, the street stays.
TEST(RemovertHd, AWalkersTrailAlongTheLineOfSightIsNoSurface) {
  const auto walker = [](int k) {
    const double px = 40.0 + 0.5 * k;
    return std::vector<test::Box>{test::MakeBox(px - 0.25, 2.25, 0.05, px + 0.25, 2.75, 1.8, 101)};
  };
  const Street s = MakeStreet(0.0, false, walker);
  const auto res = removert::RemoveHd(s.kfs, test::ConfigFor(), 2);
  const Score sc = ScoreHd(s.truth, res.static_map);
  std::printf("walker along the line of sight: SA %.4f DA %.4f (candidates %zu, reverted %zu, removed %zu)\n", sc.sa,
              sc.da, res.stats.candidates, res.stats.reverted, res.stats.removed);
  EXPECT_GE(sc.sa, 0.99);
  EXPECT_LE(20 * res.stats.reverted, res.stats.candidates);  // every candidate here is the walker's
  EXPECT_GE(sc.da, 0.85);  // the rest: places no later ray passed (the body hid them)
}

// A car crossing beyond the street's far end, 25-65 m out, seen by an OS1-64 (0.71 deg between beams):
// far away, removal decides a mover in pieces (its lowest row, a few decimetres above the ground,
// is never seen through: the window's beam below it returns from the ground in front of it). Say
// the votes took the car's upper part: in each scan that met it, the rest of that cluster is the
// car's too and goes (CompleteBodies). The parked car beside the street, the walls and the ground
// stay whole; a scan of which the votes took less than hd.remove_min_ratio of the car keeps the rest,
// and so does a standing car whose removal went wrong in part: its votes, pooled, say it stood. A
// scanner without rings judges no body.
TEST(RemovertHd, WhatTheVotesLeftOfAFarCarsBodyGoesWithTheRest) {
  const auto far_car = [](int k) {
    const double cy = -12.0 + 1.5 * k;
    return std::vector<test::Box>{test::MakeBox(44.1, cy - 2.25, 0.3, 45.9, cy + 2.25, 1.5, 100)};
  };
  test::Lidar lidar;
  lidar.fov_up_deg = 22.5;
  lidar.fov_down_deg = -22.5;
  lidar.cols = 1024;
  const Street s = MakeStreet(0.0, false, far_car, lidar);
  const RemovertConfig cfg = test::ConfigFor(lidar);
  const PointCloud map = removert::BuildSessionMap(s.kfs, cfg, 2);
  const geometry::KdTree truth(s.truth);
  std::vector<int> label(map.size());
  for (std::size_t i = 0; i < map.size(); ++i) {
    std::uint32_t j = 0;
    float d2 = 0.f;
    truth.Nearest(map.points[i].xyz(), &j, &d2);
    label[i] = s.truth.object[j];
  }
  const removert::VisibilityVotes votes = removert::CountVisibility(map, s.kfs, cfg.remove_resolutions_deg, cfg, 2);
  // Say removal took the points of `id` above `cut` [m]; after CompleteBodies: how many of its other
  // points are left, and how many points of anything else went.
  struct Left {
    std::size_t taken = 0, left = 0, others_lost = 0;
  };
  const auto complete = [&](int id, double cut, const RemovertConfig& with) {
    Left out;
    std::vector<std::uint8_t> state(map.size(), removert::detail::HdDecision::kStatic);
    for (std::size_t i = 0; i < map.size(); ++i)
      if (label[i] == id && map.points[i].z > cut) state[i] = removert::detail::HdDecision::kRemoved, ++out.taken;
    removert::detail::CompleteBodies(map, s.kfs, with, votes, 2, &state);
    for (std::size_t i = 0; i < map.size(); ++i) {
      const bool gone = state[i] != removert::detail::HdDecision::kStatic;
      out.left += label[i] == id && !gone;
      out.others_lost += label[i] != id && gone;
    }
    return out;
  };
  const std::size_t car = std::size_t(std::count(label.begin(), label.end(), 100));
  const std::size_t parked = std::size_t(std::count(label.begin(), label.end(), 7));
  const Left half = complete(100, 0.9, cfg), roof = complete(100, 1.35, cfg), wrong = complete(7, 1.0, cfg);
  std::printf("far car: %zu map points; removal took %zu, bodies left %zu, took %zu others; removal took the roof, "
              "%zu: left %zu, took %zu others; parked car (%zu points) above 1 m, %zu: left %zu, took %zu others\n",
              car, half.taken, half.left, half.others_lost, roof.taken, roof.left, roof.others_lost, parked, wrong.taken,
              wrong.left, wrong.others_lost);
  EXPECT_LE(10 * half.left, car - half.taken);  // nine tenths of what the votes left of the car go
  EXPECT_EQ(half.others_lost, 0u);
  EXPECT_GT(roof.left, half.left);  // scans where the roof was under remove_min_ratio of the car
  EXPECT_EQ(roof.others_lost, 0u);
  // A standing car half of which removal took by mistake: its votes, pooled, say it stood.
  EXPECT_GT(2 * wrong.taken, parked);
  EXPECT_EQ(wrong.left, parked - wrong.taken);
  EXPECT_EQ(wrong.others_lost, 0u);
  // A scanner without rings samples a place in a pattern of its own in each scan: no body is judged.
  RemovertConfig rosette = cfg;
  rosette.sensor_model.ring_based = false;
  const Left unringed = complete(100, 0.9, rosette);
  EXPECT_EQ(unringed.left, car - unringed.taken);
}

TEST(RemovertHd, RevertKeepsMoreStaticThanSingleResolution) {
  const Street s = MakeStreet(0.05);  // 5 cm, 0.06 deg pose noise
  RemovertConfig ours = test::ConfigFor();
  // The public LT-mapper code: one resolution, plain pixel test, any see-through removes, no revert.
  RemovertConfig single = test::ConfigFor();
  single.remove_resolutions_deg = {ours.remove_resolutions_deg.front()};
  single.revert = false;
  single.window_px = 0;
  single.remove_min_ratio = 0.0;
  // Multi-resolution remove-then-revert with the plain pixel test and the public code's voting:
  // the revert alone earns its place.
  RemovertConfig no_window = ours;
  no_window.window_px = 0;
  no_window.remove_min_ratio = 0.0;
  no_window.revert_hit_ratio = 1.0;
  no_window.revert_min_hits = 3;
  const auto a = removert::RemoveHd(s.kfs, ours, 2);
  const auto b = removert::RemoveHd(s.kfs, single, 2);
  const auto c = removert::RemoveHd(s.kfs, no_window, 2);
  const Score sa = ScoreHd(s.truth, a.static_map), sb = ScoreHd(s.truth, b.static_map),
              sc = ScoreHd(s.truth, c.static_map);
  std::printf("ours:            SA %.4f DA %.4f removed %zu\n", sa.sa, sa.da, a.stats.removed);
  std::printf("single, no rev.: SA %.4f DA %.4f removed %zu\n", sb.sa, sb.da, b.stats.removed);
  std::printf("ours, no window: SA %.4f DA %.4f removed %zu (reverted %zu)\n", sc.sa, sc.da,
              c.stats.removed, c.stats.reverted);
  EXPECT_GT(sa.sa, sb.sa + 0.01);
  EXPECT_GT(sc.sa, sb.sa + 0.01);
  EXPECT_GE(sa.da, 0.95);
}

TEST(RemovertHd, EmptyInputsAndBadConfig) {
  RemovertConfig cfg = test::ConfigFor();
  const auto r = removert::RemoveHdFromMap(PointCloud{}, {}, cfg, 1);
  EXPECT_TRUE(r.static_map.empty());
  cfg.remove_resolutions_deg.clear();
  EXPECT_THROW(cfg.Validate(), Error);
  RemovertConfig bad;  // a table needs at least two elevations
  bad.sensor = "table";
  bad.sensor_elevations_deg = {3.0};
  EXPECT_THROW(bad.Validate(), Error);
  RemovertConfig stray;  // elevations without sensor.model: table
  stray.sensor_elevations_deg = {3.0, 1.0};
  EXPECT_THROW(stray.Validate(), Error);
  WorldKeyframe kf;  // neither cloud nor path
  PointCloud one;
  one.push_back(1, 2, 3);
  EXPECT_THROW(removert::RemoveHdFromMap(one, {kf}, test::ConfigFor(), 1), Error);
}

}  // namespace
}  // namespace ltm
