// Truth placement per keyframe (exact for points next to their keyframe, errors on bad input)
// and the live / meta map check of new and removed cars on a tiny hand-built simulator layout.
#include "ltmapper/eval/eval.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace ltm::eval {
namespace {

namespace fs = std::filesystem;
using test::RunCli;
using test::TempDir;

Pose MakePose(double x, double y, double z, double yaw_deg, double roll_deg = 0.0) {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(roll_deg * M_PI / 180.0, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// A curved drive: keyframes 10 m apart; the estimate drifts differently at every keyframe
// (growing translation and yaw error, plus a frame change) so no single rigid transform fits.
void Drive(std::size_t n, std::vector<Pose>* truth, std::vector<Pose>* est) {
  const Pose frame = MakePose(-30.0, 12.0, 0.5, 40.0);  // estimated world vs true world
  for (std::size_t k = 0; k < n; ++k) {
    const double s = double(k);
    truth->push_back(MakePose(10.0 * s, 3.0 * s * s / double(n), 0.2 * std::sin(s), 8.0 * s));
    const Pose drift = MakePose(0.07 * s * s, -0.3 * s, 0.05 * s, 0.9 * s * std::cos(s), 0.3 * s);
    est->push_back(frame * truth->back() * drift);
  }
}

TEST(TruthMapping, KeyframeMappingIsExactNextToEachKeyframe) {
  std::vector<Pose> truth, est;
  Drive(8, &truth, &est);
  // Points generated in each keyframe's local frame, within 2.5 m of it (keyframes 10 m apart,
  // so every point's nearest keyframe is its own).
  PointCloud world, expected;
  for (std::size_t k = 0; k < truth.size(); ++k)
    for (int i = 0; i < 40; ++i) {
      const Eigen::Vector3d local(1.4 * std::cos(0.7 * i), 1.4 * std::sin(1.3 * i), 0.1 * (i % 11) - 0.5);
      const Eigen::Vector3d w = truth[k] * local, e = est[k] * local;
      world.push_back(float(w.x()), float(w.y()), float(w.z()), float(i));
      world.object.push_back(int(k));
      world.cls.push_back(PointClass::kStatic);
      expected.push_back(float(e.x()), float(e.y()), float(e.z()));
    }
  const PointCloud got = MapTruthByKeyframes(world, truth, est, 2);
  ASSERT_EQ(got.size(), world.size());
  ASSERT_EQ(got.object, world.object);  // optional arrays kept
  ASSERT_EQ(got.cls.size(), world.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    worst = std::max(worst, double((got.points[i].xyz() - expected.points[i].xyz()).norm()));
    EXPECT_EQ(got.points[i].intensity, world.points[i].intensity);
  }
  EXPECT_LT(worst, 1e-4);  // float coordinates of ~100 m

  // One rigid transform cannot do that: the joint alignment leaves decimetres.
  std::vector<Eigen::Vector3d> src, dst;
  for (std::size_t k = 0; k < truth.size(); ++k) {
    src.push_back(truth[k].translation());
    dst.push_back(est[k].translation());
  }
  const PointCloud global = geometry::Transform(world, AlignRigid(src, dst));
  double worst_global = 0.0;
  for (std::size_t i = 0; i < got.size(); ++i)
    worst_global = std::max(worst_global, double((global.points[i].xyz() - expected.points[i].xyz()).norm()));
  EXPECT_GT(worst_global, 0.5);

  // The struct form does the same, by sim session index.
  TruthMapping m;
  m.mode = "keyframe";
  m.sessions.resize(2);
  m.sessions[1].truth = truth;
  m.sessions[1].est = est;
  m.sessions[0].name = "session_00";
  m.sessions[0].truth = truth;  // not aligned: est empty
  EXPECT_LT((m.Map(world, 1).points[5].xyz() - got.points[5].xyz()).norm(), 1e-6);
  EXPECT_TRUE(m.ScanPose(1, 3, truth[3]).isApprox(est[3]));
  test::ExpectError([&] { m.Map(world, 0); }, {"session_00", "not aligned"});
  EXPECT_THROW(m.ScanPose(0, 1, truth[1]), Error);
  EXPECT_THROW(m.ScanPose(1, 8, truth[1]), Error);
  EXPECT_THROW(m.Map(world, 2), Error);
  const TruthMapping g = GlobalTruthMapping(MakePose(1, 2, 3, 4), "test");
  EXPECT_TRUE(g.ScanPose(7, 9, truth[2]).isApprox(MakePose(1, 2, 3, 4) * truth[2]));
}

TEST(TruthMapping, ChangesFromLabelledScansPlaceEachScanWithItsEstimatedPose) {
  TempDir dir;
  const std::string sim = dir / "sim";
  const std::string sdir = sim + "/truth/session_00";
  std::vector<Pose> truth, est;
  Drive(4, &truth, &est);
  // Per keyframe a 1 m x 1 m patch of points 0.25 m apart (sensor frame), one HD point on it.
  // The points of keyframes 1 and 3 are the change; the static world is the scans in the true world.
  PointCloud world, change;
  std::vector<PointCloud> expected_est(1);
  for (std::size_t k = 0; k < truth.size(); ++k) {
    PointCloud scan;
    for (int i = 0; i < 5; ++i)
      for (int j = 0; j < 5; ++j) {
        scan.push_back(2.f + 0.25f * float(i), 0.25f * float(j), -1.f);
        scan.cls.push_back(PointClass::kStatic);
      }
    scan.push_back(2.5f, 0.5f, -0.5f);
    scan.cls.push_back(PointClass::kHD);
    io::WritePly(sdir + "/labels/00000" + std::to_string(k) + ".ply", scan);
    std::vector<bool> st(scan.size(), true);
    st.back() = false;
    const PointCloud w = geometry::Transform(scan.select(st), truth[k]);
    world.append(w);
    if (k % 2 == 1) {
      change.append(w);
      expected_est[0].append(geometry::Transform(scan.select(st), est[k]));
    }
  }
  world.cls.clear();
  change.cls.clear();
  io::WritePcd(sdir + "/static_world.pcd", world);
  io::WriteKittiPoses(sdir + "/poses_world.txt", truth);
  TruthMapping m;
  m.mode = "keyframe";
  m.sessions.resize(1);
  m.sessions[0].name = "session_00";
  m.sessions[0].truth = truth;
  m.sessions[0].est = est;
  const PointCloud none;
  const auto got = ChangesFromLabelledScans(sim, 0, {&change, &none}, m, 0.1, 2);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_TRUE(got[1].empty());
  ASSERT_EQ(got[0].size(), expected_est[0].size());  // 0.1 m voxels keep the 0.25 m grid, HD dropped
  const geometry::KdTree tree(expected_est[0]);
  for (const PointXYZI& p : got[0].points) {
    std::uint32_t j = 0;
    float d2 = 1.f;
    ASSERT_TRUE(tree.Nearest(p.xyz(), &j, &d2));
    EXPECT_LT(d2, 1e-8f);
  }
  test::ExpectError([&] { ChangesFromLabelledScans(sim, 3, {&change}, m, 0.1); }, {"no sim session"});
  // Overlapping clouds (a pair's changes and its objects' part): each point goes into every cloud
  // that marks it, from one pass over the scans.
  PointCloud half;
  for (std::size_t i = 0; i < change.size(); i += 2) half.points.push_back(change.points[i]);
  const auto both = ChangesFromLabelledScans(sim, 0, {&change, &half}, m, 0.1, 2);
  ASSERT_EQ(both.size(), 2u);
  EXPECT_EQ(both[0].size(), got[0].size());
  EXPECT_GT(both[1].size(), 0u);
  EXPECT_LT(both[1].size(), both[0].size());
  const std::vector<const PointCloud*> nine(9, &change);
  test::ExpectError([&] { ChangesFromLabelledScans(sim, 0, nine, m, 0.1); }, {"at most 8"});

  // Labelled scan folders: missing, wrong count, a scan without classes.
  test::ExpectError([&] { LabelledScanPaths(sim + "/truth/none", 4); }, {"none/labels", "no labelled scans"});
  test::ExpectError([&] { LabelledScanPaths(sdir, 5); }, {"labels", "4 labelled scans but 5 poses"});
  EXPECT_EQ(LabelledScanPaths(sdir, 4).size(), 4u);
  PointCloud plain;
  plain.push_back(1.f, 2.f, 3.f);
  io::WritePly(dir / "plain.ply", plain);
  test::ExpectError([&] { ReadLabelledScan(dir / "plain.ply"); }, {"plain.ply", "no 'class' field"});
}

TEST(TruthMapping, PoseCountMismatchAndNoPosesAreErrors) {
  std::vector<Pose> truth, est;
  Drive(5, &truth, &est);
  PointCloud c;
  c.push_back(1.f, 2.f, 3.f);
  est.pop_back();
  test::ExpectError([&] { MapTruthByKeyframes(c, truth, est); }, {"5 true keyframe poses", "4 estimated"});
  test::ExpectError([&] { MapTruthByKeyframes(c, {}, {}); }, {"no keyframe poses"});
}

// ---------------------------------------------------------------------------- live / meta
// A car: a 4 x 2 x 1.5 m box surface sampled every 0.1 m, around `c` in a keyframe's local frame.
std::vector<Eigen::Vector3d> CarLocal(const Eigen::Vector3d& c) {
  std::vector<Eigen::Vector3d> out;
  for (double x = -2.0; x <= 2.0; x += 0.1)
    for (double z = 0.0; z <= 1.5; z += 0.1) {
      out.push_back(c + Eigen::Vector3d(x, -1.0, z));
      out.push_back(c + Eigen::Vector3d(x, 1.0, z));
    }
  return out;
}

// Three sessions of 4 keyframes (20 m apart); each session's static_world.ply holds the cars
// present in it, placed with the true poses. Cars (objects.csv):
//   1 car  "2"      new since session 0 (present in the last session only)   near keyframe 1
//   2 car  "0"      removed since session 0                                    near keyframe 2
//   3 car  "0;1;2"  permanent                                                  near keyframe 0
//   4 car  "1"      came and went (not scored)                                 near keyframe 3
//   5 tree "2"      other class (not scored)                                   near keyframe 3
//   6 car  "1;2"    new since session 0, the live map holds session 1's copy   near keyframe 2
// The estimates drift per keyframe (different for every keyframe and session).
struct LiveMetaSim {
  std::string sim, aligned;
  // Car points in the estimated world as the method's map of each session holds them:
  // (id, session) -> cloud.
  std::map<std::pair<int, int>, PointCloud> est_cars;
};

LiveMetaSim MakeLiveMetaSim(const TempDir& dir) {
  LiveMetaSim f;
  f.sim = dir / "sim";
  f.aligned = dir / "aligned";
  struct Car {
    int id;
    std::vector<int> sessions;
    std::size_t kf;
    double side;  // [m] lateral offset from the keyframe
  };
  const Car cars[] = {{1, {2}, 1, 6.0}, {2, {0}, 2, 6.0}, {3, {0, 1, 2}, 0, 6.0},
                      {4, {1}, 3, 6.0}, {5, {2}, 3, 6.0}, {6, {1, 2}, 2, -6.0}};
  const Pose frame = MakePose(-5.0, 7.0, 0.0, 25.0);
  for (int s = 0; s < 3; ++s) {
    const std::string name = "session_0" + std::to_string(s);
    std::vector<Pose> truth, est;
    for (int k = 0; k < 4; ++k) {
      truth.push_back(MakePose(20.0 * k, 1.5 * s, 0.0, 3.0 * k + s));
      est.push_back(frame * truth.back() * MakePose(0.4 * ((k + s) % 3) - 0.4, 0.35 * (k % 2 ? 1 : -1), 0.1 * s, 1.5 * k - 2.0 * s));
    }
    PointCloud world;
    for (const auto& car : cars) {
      if (std::count(car.sessions.begin(), car.sessions.end(), s) == 0) continue;
      for (const auto& p : CarLocal(Eigen::Vector3d(0.0, car.side, 0.0))) {
        const Eigen::Vector3d w = truth[car.kf] * p, e = est[car.kf] * p;
        world.push_back(float(w.x()), float(w.y()), float(w.z()));
        world.cls.push_back(PointClass::kStatic);
        world.session.push_back(std::uint16_t(s));
        world.object.push_back(car.id);
        f.est_cars[{car.id, s}].push_back(float(e.x()), float(e.y()), float(e.z()));
      }
    }
    fs::create_directories(fs::path(f.sim) / "truth" / name);
    fs::create_directories(fs::path(f.aligned) / name);
    io::WritePly(f.sim + "/truth/" + name + "/static_world.ply", world);
    io::WriteKittiPoses(f.sim + "/truth/" + name + "/poses_world.txt", truth);
    io::WriteKittiPoses(f.aligned + "/" + name + "/poses_world.txt", est);
  }
  test::WriteText(f.sim + "/truth/objects.csv",
                  "id,class,present_in,placement,centroid_x\n1,car,2,open,0\n2,car,0,open,0\n3,car,\"0;1;2\",open,0\n"
                  "4,car,1,open,0\n5,tree,2,open,0\n6,car,\"1;2\",open,0\n");
  return f;
}

TEST(LiveMeta, NewCarsInLiveNotInMetaRemovedInNeither) {
  TempDir dir;
  const LiveMetaSim f = MakeLiveMetaSim(dir);
  const TruthMapping m = KeyframeTruthMapping(f.sim, f.aligned);
  const auto truth = LoadSimLiveMetaTruth(f.sim, {"car"}, m);
  ASSERT_EQ(truth.size(), 3u);
  EXPECT_EQ(truth[0].id, 1);
  EXPECT_TRUE(truth[0].added);
  EXPECT_EQ(truth[1].id, 2);
  EXPECT_FALSE(truth[1].added);
  EXPECT_EQ(truth[2].id, 6);
  ASSERT_EQ(truth[0].views.size(), 1u);
  EXPECT_EQ(truth[0].views[0].size(), f.est_cars.at({1, 2}).size());
  ASSERT_EQ(truth[2].views.size(), 2u);  // sessions 1 and 2
  EXPECT_EQ(LoadSimLiveMetaTruth(f.sim, {}, m).size(), 4u);  // + the new tree

  // Live: the latest state (new car 1 and permanent car 3 as session 2 saw them, new car 6 as
  // session 1 added it); meta: car 3 and 30 % of car 1 (below the 0.5 fraction). A second live
  // map wrongly keeps the removed car 2.
  PointCloud live, meta, live_bad;
  live.append(f.est_cars.at({1, 2}));
  live.append(f.est_cars.at({3, 2}));
  live.append(f.est_cars.at({6, 1}));
  meta.append(f.est_cars.at({3, 2}));
  const PointCloud& c1 = f.est_cars.at({1, 2});
  for (std::size_t i = 0; i < c1.size() * 3 / 10; ++i) meta.push_back(c1.points[i].x, c1.points[i].y, c1.points[i].z);
  live_bad = live;
  live_bad.append(f.est_cars.at({2, 0}));
  EvalConfig cfg;
  LiveMetaResult r = EvaluateLiveMeta(truth, live, meta, cfg);
  EXPECT_EQ(r.added, 2u);
  EXPECT_EQ(r.added_in_live, 2u);
  EXPECT_EQ(r.added_in_meta, 0u);
  EXPECT_EQ(r.removed, 1u);
  EXPECT_EQ(r.removed_in_live, 0u);
  EXPECT_EQ(r.removed_in_meta, 0u);
  ASSERT_EQ(r.objects.size(), 3u);
  EXPECT_DOUBLE_EQ(r.objects[0].live_fraction, 1.0);
  EXPECT_DOUBLE_EQ(r.objects[2].live_fraction, 1.0);
  // Session 2's view of car 6 alone is decimetres off the copy session 1 put in the map.
  auto last_view_only = truth;
  last_view_only[2].views.erase(last_view_only[2].views.begin());
  EXPECT_LT(EvaluateLiveMeta(last_view_only, live, meta, cfg).objects[2].live_fraction, 0.5);
  EXPECT_GE(r.objects[0].meta_fraction, 0.3);  // + neighbours of the subset within 0.2 m
  EXPECT_LT(r.objects[0].meta_fraction, 0.4);
  r = EvaluateLiveMeta(truth, live_bad, meta, cfg);
  EXPECT_EQ(r.removed_in_live, 1u);
  cfg.livemeta_min_fraction = 0.25;  // 30 % of car 1 now counts
  EXPECT_EQ(EvaluateLiveMeta(truth, live, meta, cfg).added_in_meta, 1u);
  cfg.obj_min_truth_points = 100000;  // nothing scored
  r = EvaluateLiveMeta(truth, live, meta, cfg);
  EXPECT_EQ(r.added + r.removed, 0u);
  EXPECT_FALSE(r.objects[0].scored);

  // Command line, per-keyframe mapping (default) and the global one for comparison: the drift
  // moves the truth by decimetres, more than the 0.2 m match distance.
  io::WritePcd(dir / "live.pcd", live);
  io::WritePcd(dir / "meta.pcd", meta);
  std::string out;
  ASSERT_EQ(RunCli("eval livemeta --sim " + f.sim + " --aligned " + f.aligned + " --live " + (dir / "live.pcd") +
                       " --meta " + (dir / "meta.pcd") + " --json " + (dir / "k.json") + " --md " + (dir / "k.md"),
                   &out),
            0)
      << out;
  std::string js = test::ReadText(dir / "k.json");
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.added"), 2.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.added_in_live"), 2.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.added_in_meta"), 0.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.removed_in_live"), 0.0);
  EXPECT_NE(js.find("\"truth mapping\": \"keyframe"), std::string::npos) << js;
  EXPECT_NE(test::ReadText(dir / "k.md").find("new since session 0 | 2 | 2 / 2 | 0 / 2"), std::string::npos)
      << test::ReadText(dir / "k.md");
  ASSERT_EQ(RunCli("eval livemeta --sim " + f.sim + " --aligned " + f.aligned + " --live " + (dir / "live.pcd") +
                       " --meta " + (dir / "meta.pcd") + " --truth-mapping global --json " + (dir / "g.json"),
                   &out),
            0)
      << out;
  js = test::ReadText(dir / "g.json");
  EXPECT_NE(js.find("\"truth mapping\": \"global"), std::string::npos) << js;
  EXPECT_LT(*JsonNumber(js, "livemeta.objects.0.live_fraction"), 0.9);
  // Every class: the new tree (not in the live map) joins the new objects.
  ASSERT_EQ(RunCli("eval livemeta --sim " + f.sim + " --aligned " + f.aligned + " --live " + (dir / "live.pcd") +
                       " --meta " + (dir / "meta.pcd") + " --class all --json " + (dir / "a.json"),
                   &out),
            0)
      << out;
  js = test::ReadText(dir / "a.json");
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.added"), 3.0);
  EXPECT_DOUBLE_EQ(*JsonNumber(js, "livemeta.added_in_live"), 2.0);
  // A session without estimated poses cannot be mapped per keyframe.
  fs::remove_all(fs::path(f.aligned) / "session_02");
  EXPECT_EQ(RunCli("eval livemeta --sim " + f.sim + " --aligned " + f.aligned + " --live " + (dir / "live.pcd") +
                       " --meta " + (dir / "meta.pcd"),
                   &out),
            1)
      << out;
  EXPECT_NE(out.find("not aligned"), std::string::npos) << out;
}

}  // namespace
}  // namespace ltm::eval
