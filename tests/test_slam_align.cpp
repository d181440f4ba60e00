// LT-SLAM end to end on tiny synthetic sessions: unknown anchor recovered from scans alone,
// sessions without overlap reported as not aligned, bad input raises errors, the stage writes
// the documented files, the CLI validates its arguments.
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/slam.hpp"
#include "test_slam_synth.hpp"
#include "test_util.hpp"

#include <cmath>
#include <filesystem>

using namespace ltm;
using namespace ltm::slam;

namespace {
constexpr double kDeg = M_PI / 180.0;

SlamConfig FastConfig() {
  SlamConfig cfg;
  cfg.reg_submap_neighbours = 0;
  cfg.reg_voxel_m = 0.7;
  cfg.reg_max_iterations = 20;
  cfg.sc_max_loops_per_pair = 8;
  cfg.refine_rounds = 1;
  cfg.refine_stride = 3;
  return cfg;
}

double WorldRmse(const SessionAlignment& a, const std::vector<Pose>& truth) {
  double sum = 0;
  for (std::size_t k = 0; k < truth.size(); ++k) {
    sum += (a.T_world_sensor[k].translation() - truth[k].translation()).squaredNorm();
  }
  return std::sqrt(sum / truth.size());
}
}  // namespace

TEST(SlamAlign, RecoversUnknownOriginFromScans) {
  const PointCloud world = test::SynthWorld(41);
  const Pose A = test::MakePose(-63, 48, 1.5, 118 * kDeg);  // the query's unknown origin
  std::vector<Pose> t0, t1;
  std::vector<Session> s = {
      test::SynthSession(world, "c", Pose::Identity(), -36, 36, 4.0, 0.0, 1, &t0),
      test::SynthSession(world, "q", A, -34, 34, 4.0, 0.0005, 2, &t1)};
  const SlamResult r = AlignSessions(s, FastConfig(), 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  const double rmse = WorldRmse(r.sessions[1], t1);
  const double yaw_err =
      Eigen::AngleAxisd(r.sessions[1].anchor.linear().transpose() * A.linear()).angle() / kDeg;
  std::printf("synthetic 2 sessions: query world RMSE %.3f m, anchor rotation error %.3f deg, "
              "%d loops accepted, %.2f s\n",
              rmse, yaw_err, r.sessions[1].loops_accepted, r.time_total_s);
  EXPECT_LT(rmse, 0.1);
  EXPECT_LT(yaw_err, 0.3);
  EXPECT_GE(r.sessions[1].loops_accepted, FastConfig().min_loops);
  const std::vector<Pose>* truths[] = {&t0, &t1};
  int own = 0;
  for (const auto& l : r.loops) {
    if (!l.accepted) continue;
    own += OwnLoop(l) ? 1 : 0;
    const Pose truth = (*truths[l.a.session])[l.a.keyframe].inverse() * (*truths[l.b.session])[l.b.keyframe];
    EXPECT_LT((truth.inverse() * l.T_a_b).translation().norm(), 0.1) << l.source << " " << l.a.session << "-" << l.b.session;
  }
  EXPECT_EQ(own, r.sessions[0].own_loops + r.sessions[1].own_loops);
}

// The registration clouds are kept within registration.cache_mb and made again when dropped:
// a budget of almost nothing gives the same poses and loops as one that keeps every cloud.
TEST(SlamAlign, CloudCacheBudgetDoesNotChangeTheResult) {
  const PointCloud world = test::SynthWorld(41);
  std::vector<Session> s = {
      test::SynthSession(world, "c", Pose::Identity(), -36, 36, 4.0, 0.0, 1, nullptr),
      test::SynthSession(world, "q", test::MakePose(-63, 48, 1.5, 118 * kDeg), -34, 34, 4.0, 0.0005, 2, nullptr)};
  SlamConfig tiny = FastConfig(), ample = FastConfig();
  tiny.reg_cache_mb = 0.01;  // 10 kB: about one keyframe's cloud kept, the others made again
  ample.reg_cache_mb = 1e5;
  const SlamResult a = AlignSessions(s, tiny, 2), b = AlignSessions(s, ample, 2);
  ASSERT_TRUE(b.sessions[1].aligned) << b.sessions[1].reason;
  ASSERT_EQ(a.loops.size(), b.loops.size());
  for (std::size_t i = 0; i < a.loops.size(); ++i) EXPECT_EQ(a.loops[i].accepted, b.loops[i].accepted);
  for (std::size_t q = 0; q < s.size(); ++q)
    for (std::size_t k = 0; k < s[q].keyframes.size(); ++k)
      EXPECT_TRUE(a.sessions[q].T_world_sensor[k].isApprox(b.sessions[q].T_world_sensor[k], 1e-12)) << q << " " << k;
}

// One session drives a road and comes back along it (its odometry drifting 0.1 deg in yaw per
// keyframe, 7 deg in all): the two passes of a place are 36 keyframes apart along the route and
// only the drifted odometry links them. The radius search within the session registers them
// (loops within the session, OwnLoop), and the two passes agree again.
TEST(SlamAlign, ARouteThatComesBackIsClosedWithinItsSession) {
  const PointCloud world = test::SynthWorld(41);
  std::vector<Pose> truth;
  for (double x = -36; x <= 36 + 1e-9; x += 4.0) truth.push_back(test::MakePose(x, -1.5, 1.8, 0.0));
  for (double x = 36; x >= -36 - 1e-9; x -= 4.0) truth.push_back(test::MakePose(x, 1.5, 1.8, M_PI));
  const std::vector<Pose> odometry = test::DriftedOdometry(truth, Pose::Identity(), 0.1 * kDeg);
  Session s;
  s.name = "c";
  for (std::size_t k = 0; k < truth.size(); ++k) {
    Keyframe kf;
    kf.index = int(k);
    kf.T_session_sensor = odometry[k];
    kf.cloud = test::SynthScan(world, truth[k], 40.0, 7000 + unsigned(k));
    s.keyframes.push_back(kf);
    if (k > 0) {
      Edge e;
      e.from = int(k) - 1;
      e.to = int(k);
      e.T_from_to = odometry[k - 1].inverse() * odometry[k];
      s.odometry.push_back(e);
    }
  }
  // The largest yaw error [deg] between a place's two passes (keyframe k and its twin).
  const std::size_t n = truth.size(), half = n / 2;
  auto worst = [&](const std::vector<Pose>& est) {
    double w = 0;
    for (std::size_t k = 0; k < half; ++k) {
      const std::size_t t = n - 1 - k;
      const Pose e = (truth[k].inverse() * truth[t]).inverse() * (est[k].inverse() * est[t]);
      w = std::max(w, Eigen::AngleAxisd(e.linear()).angle() / kDeg);
    }
    return w;
  };
  SlamConfig off = FastConfig(), on = FastConfig();
  off.refine_rounds = 0;
  off.reg_steps = on.reg_steps = false;  // the loops alone (registered steps: the next test)
  const SlamResult without = AlignSessions({s}, off, 2), with = AlignSessions({s}, on, 2);
  const double before = worst(without.sessions[0].T_world_sensor), after = worst(with.sessions[0].T_world_sensor);
  std::printf("out and back: worst yaw between a place's two passes %.3f deg without, %.3f deg with %d loops within "
              "the session\n", before, after, with.sessions[0].own_loops);
  EXPECT_EQ(without.sessions[0].own_loops, 0);
  EXPECT_GT(with.sessions[0].own_loops, 0);
  EXPECT_GT(before, 3.0);
  EXPECT_LT(after, 0.5);
}

// One session's odometry drifts 0.2 deg in yaw per keyframe (3.6 deg over its 19 keyframes), no
// loop anywhere. Each keyframe registered onto the one before (registration.steps) holds the
// heading: the turn between the first and every later keyframe stays within a tenth of a degree.
// The same drive with an odometry that does not drift gets no steps: they are no finer than it.
TEST(SlamAlign, RegisteredStepsHoldTheHeadingTheOdometryDrifts) {
  const PointCloud world = test::SynthWorld(41);
  std::vector<Pose> truth;
  const Session s = test::SynthSession(world, "c", Pose::Identity(), -36, 36, 4.0, 0.2 * kDeg, 1, &truth);
  auto worst = [&](const SessionAlignment& a) {
    double w = 0;
    for (std::size_t k = 1; k < truth.size(); ++k) {
      const Pose e = (truth[0].inverse() * truth[k]).inverse() * (a.T_world_sensor[0].inverse() * a.T_world_sensor[k]);
      w = std::max(w, Eigen::AngleAxisd(e.linear()).angle() / kDeg);
    }
    return w;
  };
  SlamConfig off = FastConfig(), on = FastConfig();
  off.refine_rounds = on.refine_rounds = 0;
  off.reg_steps = false;
  on.reg_steps = true;
  const SlamResult without = AlignSessions({s}, off, 2), with = AlignSessions({s}, on, 2);
  const double before = worst(without.sessions[0]), after = worst(with.sessions[0]);
  std::printf("odometry drifting 0.2 deg a keyframe: worst heading from the first keyframe %.3f deg, %.3f deg with %zu "
              "registered steps\n", before, after, with.sessions[0].registered.size());
  EXPECT_TRUE(without.sessions[0].registered.empty());
  EXPECT_EQ(with.sessions[0].registered.size(), truth.size() - 1);
  EXPECT_GT(before, 3.0);
  EXPECT_LT(after, 0.1);
  // An odometry that does not drift is as fine as the steps: they are left out.
  const Session exact = test::SynthSession(world, "c", Pose::Identity(), -36, 36, 4.0, 0.0, 1, nullptr);
  EXPECT_TRUE(AlignSessions({exact}, on, 2).sessions[0].registered.empty());
}

TEST(SlamAlign, SessionsWithoutOverlapAreNotAligned) {
  // Two different worlds: whatever Scan Context proposes, nothing may be accepted.
  const PointCloud w1 = test::SynthWorld(51), w2 = test::SynthWorld(52);
  std::vector<Session> s = {
      test::SynthSession(w1, "c", Pose::Identity(), -20, 20, 5.0, 0.0, 1),
      test::SynthSession(w2, "q", test::MakePose(10, 20, 0, 1.0), -20, 20, 5.0, 0.0, 2)};
  SlamConfig cfg = FastConfig();
  cfg.sc_per_query = 5;  // invite candidates: verification has to reject them
  cfg.sc_close_ratio = 1.0;
  const SlamResult r = AlignSessions(s, cfg, 2);
  EXPECT_TRUE(r.sessions[0].aligned);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_FALSE(r.sessions[1].reason.empty());
  EXPECT_TRUE(r.sessions[1].T_world_sensor.empty());
  for (const auto& l : r.loops) EXPECT_FALSE(l.accepted && !OwnLoop(l));  // the central's own loops may be
}

TEST(SlamAlign, BadInputIsAnError) {
  const PointCloud world = test::SynthWorld(61);
  std::vector<Session> s = {test::SynthSession(world, "c", Pose::Identity(), -10, 10, 5.0, 0, 1),
                            test::SynthSession(world, "q", Pose::Identity(), -10, 10, 5.0, 0, 2)};
  auto empty_scan = s;
  empty_scan[1].keyframes[2].cloud = std::make_shared<PointCloud>();
  try {
    AlignSessions(empty_scan, FastConfig(), 1);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("empty scan"), std::string::npos) << e.what();
  }
  auto broken = s;
  broken[0].odometry[1].from = 77;
  EXPECT_THROW(AlignSessions(broken, FastConfig(), 1), Error);
  EXPECT_THROW(AlignSessions({}, FastConfig(), 1), Error);
}

TEST(SlamAlign, StageWritesTheDocumentedFiles) {
  test::TempDir tmp;
  const PointCloud world = test::SynthWorld(71);
  const Pose A = test::MakePose(25, -40, 0, -75 * kDeg);
  const PointCloud other = test::SynthWorld(72);
  io::WriteSession(tmp / "s0", test::SynthSession(world, "s0", Pose::Identity(), -24, 24, 4.0, 0, 1));
  io::WriteSession(tmp / "s1", test::SynthSession(world, "s1", A, -22, 22, 4.0, 0.0005, 2));
  io::WriteSession(tmp / "s2", test::SynthSession(other, "s2", A, -10, 10, 5.0, 0, 3));
  const std::string out = tmp / "aligned";
  // A stale world pose file from an earlier run must not survive for a session not aligned now
  // (nor anything else of an earlier run: the stage replaces its whole folder).
  test::WriteText(out + "/report.json", "{}\n");
  test::WriteText(out + "/s2/poses_world.txt", "stale\n");
  test::WriteText(out + "/gone/poses_world.txt", "stale\n");
  const SlamResult r =
      RunSlamStage(FastConfig(), {tmp / "s0", tmp / "s1", tmp / "s2"}, out, 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  ASSERT_FALSE(r.sessions[2].aligned);
  namespace fs = std::filesystem;
  for (const char* f : {"joint.g2o", "loops.csv", "report.json", "report.md",
                        "s0/poses_world.txt", "s0/poses_world_tum.txt", "s0/anchor.txt",
                        "s1/poses_world.txt", "s1/poses_world_tum.txt", "s1/anchor.txt",
                        "s2/NOT_ALIGNED.txt"}) {
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f;
  }
  EXPECT_FALSE(fs::exists(out + "/s2/poses_world.txt"));
  EXPECT_FALSE(fs::exists(out + "/gone"));
  const io::RunManifest m = io::ReadRunManifest(out);
  ASSERT_EQ(m.sessions.size(), 3u);
  EXPECT_EQ(m.sessions[2].name, "s2");
  EXPECT_FALSE(m.sessions[2].aligned);
  EXPECT_FALSE(m.sessions[2].reason.empty());
  EXPECT_EQ(m.Aligned().size(), 2u);
  EXPECT_EQ(io::ReadKittiPoses(out + "/s1/poses_world.txt").size(), r.sessions[1].T_world_sensor.size());
  const Pose anchor = io::ReadTransform(out + "/s1/anchor.txt");
  EXPECT_LT((anchor.translation() - r.sessions[1].anchor.translation()).norm(), 1e-4);
  const io::G2oGraph g = io::ReadG2o(out + "/joint.g2o");
  EXPECT_EQ(g.vertices.size(), r.sessions[0].T_world_sensor.size() + r.sessions[1].T_world_sensor.size());
  const std::string report = test::ReadText(out + "/report.md");
  EXPECT_NE(report.find("NOT ALIGNED"), std::string::npos);
  EXPECT_NE(test::ReadText(out + "/report.json").find("\"all_aligned\": false"), std::string::npos);
}

TEST(SlamAlign, CliValidatesArguments) {
  std::string out;
  EXPECT_NE(test::RunCli("slam --out /tmp/ltm_slam_cli_none", &out), 0);
  EXPECT_NE(out.find("central"), std::string::npos) << out;
  EXPECT_NE(test::RunCli("slam --central /nonexistent_dir --query /nonexistent_2 --out /tmp/x", &out), 0);
  test::TempDir tmp;
  test::WriteText(tmp / "bad.yaml", "graph:\n  robust_loss: huber\n");
  EXPECT_NE(test::RunCli("slam --config " + (tmp / "bad.yaml") + " --sessions a b --out " + (tmp / "o"), &out), 0);
  EXPECT_NE(out.find("robust_loss"), std::string::npos) << out;
  test::WriteText(tmp / "unknown.yaml", "graph:\n  no_such_key: 1\n");
  EXPECT_NE(test::RunCli("slam --config " + (tmp / "unknown.yaml") + " --sessions a b --out " + (tmp / "o"), &out), 0);
  // The shipped params file loads.
  EXPECT_NE(test::RunCli(std::string("slam --config ") + LTM_SOURCE_DIR +
                             "/config/params_ltslam.yaml --sessions /nonexistent_a /nonexistent_b --out " +
                             (tmp / "o"), &out), 0);
  EXPECT_EQ(out.find("params_ltslam.yaml"), std::string::npos) << out;
}

TEST(SlamAlign, RetryAlignsAChainOnATinyBudget) {
  // c and q2 never see the same place (100 m apart, 40 m scans); q1 drives across both. With one
  // Scan Context registration per pair and round, q1 aligns only through retry rounds, and q2
  // then through q1 (a chain), its retries offered against every aligned session.
  constexpr double kHalf = 110.0;  // world half size [m]
  constexpr int kBoxes = 130;
  const PointCloud world = test::SynthWorld(43, kHalf, kBoxes);
  const Pose A1 = test::MakePose(-40, 35, 1.0, 100 * kDeg);
  const Pose A2 = test::MakePose(55, -20, -1.0, -140 * kDeg);
  std::vector<Pose> t2;
  std::vector<Session> s = {
      test::SynthSession(world, "c", Pose::Identity(), -100, -50, 4.0, 0.0, 1),
      // No drift on q1: nothing corrects it between its two overlaps, 120 m apart.
      test::SynthSession(world, "q1", A1, -70, 70, 4.0, 0.0, 2),
      test::SynthSession(world, "q2", A2, 50, 100, 4.0, 0.0005, 3, &t2)};
  SlamConfig cfg = FastConfig();
  cfg.sc_max_loops_per_pair = 1;
  cfg.sc_retry_rounds = 12;
  const SlamResult r = AlignSessions(s, cfg, 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  ASSERT_TRUE(r.sessions[2].aligned) << r.sessions[2].reason;
  EXPECT_LT(WorldRmse(r.sessions[2], t2), 0.1);
  int chain = 0;
  for (const auto& l : r.loops) {
    if (!l.accepted) continue;
    EXPECT_FALSE(l.a.session == 0 && l.b.session == 2) << "c and q2 never overlap";
    chain += l.a.session == 1 && l.b.session == 2;
  }
  EXPECT_GE(chain, cfg.min_loops);
  EXPECT_GT(r.registrations, 3) << "3 pairs x 1 in the first round: more means retries ran";
  std::printf("chain c - q1 - q2: q2 world RMSE %.3f m, %d q1-q2 loops, %d GICP, %.2f s\n",
              WorldRmse(r.sessions[2], t2), chain, r.registrations, r.time_total_s);
}
