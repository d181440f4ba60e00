// eval metrics on hand-built cases with known answers: truth-as-output is perfect, corrupted
// outputs give hand-computed numbers.
#include "ltmapper/eval/eval.hpp"
#include "ltmapper/io/io.hpp"
#include "test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

namespace ltm::eval {
namespace {

Pose MakePose(double x, double y, double z, double yaw_deg) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// A curvy trajectory of n keyframes about 1 m apart.
std::vector<Pose> Curve(int n, double x0, double y0, double yaw0) {
  std::vector<Pose> poses;
  double x = x0, y = y0, yaw = yaw0;
  for (int i = 0; i < n; ++i) {
    poses.push_back(MakePose(x, y, 0.1 * std::sin(0.1 * i), yaw));
    yaw += 3.0 * std::sin(0.05 * i);
    x += std::cos(yaw * M_PI / 180.0);
    y += std::sin(yaw * M_PI / 180.0);
  }
  return poses;
}

// --------------------------------------------------------------------------- trajectories
TEST(Traj, AlignRigidRecoversKnownTransform) {
  const Pose T = MakePose(3.0, -7.0, 1.5, 37.0) * Pose(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()));
  std::vector<Eigen::Vector3d> src, dst;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-10, 10);
  for (int i = 0; i < 20; ++i) {
    src.emplace_back(u(rng), u(rng), u(rng));
    dst.push_back(T * src.back());
  }
  const Pose A = AlignRigid(src, dst);
  EXPECT_LT((A.matrix() - T.matrix()).norm(), 1e-9);
}

TEST(Traj, TruthAsEstimateIsPerfectEvenInAnotherFrame) {
  const Pose frame = MakePose(50, -20, 3, 123);  // the estimate lives in an unknown frame
  std::vector<SessionTrajectory> s(2);
  s[0].name = "c";
  s[0].truth = Curve(60, 0, 0, 0);
  s[1].name = "q";
  s[1].truth = Curve(60, 0.5, 0.3, 5);
  for (auto& t : s)
    for (const auto& p : t.truth) t.est.push_back(frame * p);
  const auto r = EvaluateTrajectories(s, EvalConfig{});
  EXPECT_NEAR(r.ate.trans_m.rmse, 0.0, 1e-9);
  EXPECT_NEAR(r.ate.rot_deg.max, 0.0, 1e-6);
  EXPECT_NEAR(r.rpe.trans_m.max, 0.0, 1e-9);
  EXPECT_GT(r.rpe.trans_m.n, 0u);
  EXPECT_NEAR(r.consistency.trans_m.max, 0.0, 1e-9);
  EXPECT_EQ(r.consistency_sessions.at(0).pairs, 60u);
}

TEST(Traj, ShiftedSessionGivesKnownAte) {
  // Central exact; the query's estimate shifted by d along x. The joint alignment is computed
  // over both sessions; with no alignment the ATE is exact: n poses with error 0, n with d.
  const double d = 0.4;
  std::vector<SessionTrajectory> s(2);
  s[0].truth = Curve(50, 0, 0, 0);
  s[0].est = s[0].truth;
  // The query drives the same positions the other way round (same centroid, so the joint
  // least-squares fit is a pure translation by -d/2).
  for (const auto& p : s[0].truth) s[1].truth.push_back(p * MakePose(0, 0, 0, 180.0));
  for (const auto& p : s[1].truth) s[1].est.push_back(MakePose(d, 0, 0, 0) * p);
  EvalConfig cfg;
  cfg.traj_align = "none";
  auto r = EvaluateTrajectories(s, cfg);
  EXPECT_NEAR(r.ate.trans_m.rmse, d / std::sqrt(2.0), 1e-9);  // sqrt((50*0 + 50*d^2) / 100)
  EXPECT_NEAR(r.ate.trans_m.max, d, 1e-9);
  EXPECT_NEAR(r.sessions[1].ate.trans_m.rmse, d, 1e-9);
  EXPECT_NEAR(r.ate.rot_deg.max, 0.0, 1e-9);
  // A pure translation of a whole session: RPE within a session is untouched.
  EXPECT_NEAR(r.rpe.trans_m.max, 0.0, 1e-9);
  // The joint rigid alignment splits the shift: both sessions move by d/2 -> RMSE d/2.
  cfg.traj_align = "joint";
  r = EvaluateTrajectories(s, cfg);
  EXPECT_NEAR(r.ate.trans_m.rmse, d / 2.0, 1e-9);
  // Per-session alignment removes it completely.
  cfg.traj_align = "per_session";
  r = EvaluateTrajectories(s, cfg);
  EXPECT_NEAR(r.ate.trans_m.rmse, 0.0, 1e-9);
  // Consistency sees the shift expressed in the central keyframe's frame: |error| = d always.
  EXPECT_NEAR(r.consistency.trans_m.rmse, d, 1e-9);
  EXPECT_NEAR(r.consistency.rot_deg.max, 0.0, 1e-9);
}

TEST(Traj, RotatedEstimateGivesKnownRotationError) {
  // One session, every estimated orientation turned by 2 deg about its own z (positions exact):
  // ATE rotation = 2 deg for every pose; RPE rotation = 0 (the same local offset cancels).
  std::vector<SessionTrajectory> s(1);
  s[0].truth = Curve(40, 0, 0, 0);
  for (const auto& p : s[0].truth) s[0].est.push_back(p * MakePose(0, 0, 0, 2.0));
  const auto r = EvaluateTrajectories(s, EvalConfig{});
  EXPECT_NEAR(r.ate.rot_deg.rmse, 2.0, 1e-6);
  EXPECT_NEAR(r.ate.trans_m.max, 0.0, 1e-9);
  EXPECT_NEAR(r.rpe.rot_deg.max, 0.0, 1e-6);
  EXPECT_TRUE(r.consistency_sessions.empty());
}

TEST(Traj, RpeFramesStepAndScaleDrift) {
  // Estimated steps 10% too long along a straight line: RPE over 1 frame = 0.1 m per pair.
  std::vector<SessionTrajectory> s(1);
  for (int i = 0; i < 11; ++i) {
    s[0].truth.push_back(MakePose(i, 0, 0, 0));
    s[0].est.push_back(MakePose(1.1 * i, 0, 0, 0));
  }
  EvalConfig cfg;
  cfg.rpe_unit = "frames";
  cfg.rpe_delta = 1;
  auto r = EvaluateTrajectories(s, cfg);
  EXPECT_EQ(r.rpe.trans_m.n, 10u);
  EXPECT_NEAR(r.rpe.trans_m.rmse, 0.1, 1e-9);
  cfg.rpe_unit = "m";
  cfg.rpe_delta = 5.0;  // pairs (0,5) ... (5,10): 6 pairs, error 0.5 m each
  r = EvaluateTrajectories(s, cfg);
  EXPECT_EQ(r.rpe.trans_m.n, 6u);
  EXPECT_NEAR(r.rpe.trans_m.max, 0.5, 1e-9);
}

TEST(Traj, MismatchedCountsThrow) {
  std::vector<SessionTrajectory> s(1);
  s[0].truth = Curve(5, 0, 0, 0);
  s[0].est = Curve(4, 0, 0, 0);
  EXPECT_THROW(EvaluateTrajectories(s, EvalConfig{}), Error);
}

// ------------------------------------------------------------------------------------ HD
PointCloud Labelled(int n_static, int n_hd, double x0 = 0.0) {
  PointCloud c;
  for (int i = 0; i < n_static; ++i) {
    c.push_back(float(x0 + i), 0.f, 0.f);
    c.cls.push_back(PointClass::kStatic);
    c.object.push_back(-1);
  }
  for (int i = 0; i < n_hd; ++i) {
    c.push_back(float(x0 + i), 5.f, 0.f);
    c.cls.push_back(PointClass::kHD);
    c.object.push_back(100 + i);
  }
  return c;
}

PointCloud Unlabelled(const PointCloud& c, const std::vector<std::size_t>& keep) {
  PointCloud out;
  for (auto i : keep) out.push_back(c.points[i].x, c.points[i].y, c.points[i].z);
  return out;
}

TEST(Hd, TruthAsOutputIsPerfect) {
  const PointCloud truth = Labelled(10, 4);
  // Perfect output: all static kept, all HD removed.
  std::vector<std::size_t> keep;
  for (std::size_t i = 0; i < 10; ++i) keep.push_back(i);
  const auto r = EvaluateHd(truth, Unlabelled(truth, keep), EvalConfig{});
  EXPECT_DOUBLE_EQ(r.sa, 1.0);
  EXPECT_DOUBLE_EQ(r.da, 1.0);
  EXPECT_DOUBLE_EQ(r.aa, 1.0);
}

TEST(Hd, HandComputedCorruption) {
  // Remove 3 of 10 static points and keep 1 of 4 HD points: SA = 0.7, DA = 0.75.
  const PointCloud truth = Labelled(10, 4);
  std::vector<std::size_t> keep = {0, 1, 2, 3, 4, 5, 6, /*HD*/ 11};
  PointCloud out = Unlabelled(truth, keep);
  // Jitter the kept points below the match distance: still preserved.
  for (auto& p : out.points) p.x += 0.05f;
  const auto r = EvaluateHd(truth, out, EvalConfig{});
  EXPECT_EQ(r.static_total, 10u);
  EXPECT_EQ(r.static_preserved, 7u);
  EXPECT_EQ(r.dynamic_total, 4u);
  EXPECT_EQ(r.dynamic_removed, 3u);
  EXPECT_NEAR(r.sa, 0.7, 1e-12);
  EXPECT_NEAR(r.da, 0.75, 1e-12);
  EXPECT_NEAR(r.aa, std::sqrt(0.7 * 0.75), 1e-12);
  // Beyond the match distance nothing is preserved.
  for (auto& p : out.points) p.x += 0.2f;
  const auto far = EvaluateHd(truth, out, EvalConfig{});
  EXPECT_DOUBLE_EQ(far.sa, 0.0);
  EXPECT_DOUBLE_EQ(far.da, 1.0);
}

TEST(Hd, PerClassRowsAndStreamingEqualsOneCloud) {
  PointCloud truth = Labelled(6, 2);
  // Two points of LD object 7 ("car"), one kept.
  for (int i = 0; i < 2; ++i) {
    truth.push_back(float(i), -5.f, 0.f);
    truth.cls.push_back(PointClass::kStatic);
    truth.object.push_back(7);
  }
  PointCloud out = Unlabelled(truth, {0, 1, 2, 3, 4, 5, 8});
  const std::map<int, std::string> classes = {{7, "car"}};
  const auto r = EvaluateHd(truth, out, EvalConfig{}, classes, 2);
  ASSERT_EQ(r.classes.size(), 3u);
  EXPECT_EQ(r.classes[0].name, "static");
  EXPECT_EQ(r.classes[0].preserved, 6u);
  EXPECT_EQ(r.classes[1].name, "ld:car");
  EXPECT_EQ(r.classes[1].total, 2u);
  EXPECT_EQ(r.classes[1].preserved, 1u);
  EXPECT_EQ(r.classes[2].name, "hd");
  EXPECT_EQ(r.classes[2].total, 2u);
  EXPECT_NEAR(r.sa, 7.0 / 8.0, 1e-12);

  HdEvaluator ev(out, EvalConfig{}, classes);
  ev.Add(truth.select(std::vector<std::uint32_t>{0, 1, 2, 6}));
  ev.Add(truth.select(std::vector<std::uint32_t>{3, 4, 5, 7, 8, 9}));
  const auto s = ev.Result();
  EXPECT_EQ(s.static_preserved, r.static_preserved);
  EXPECT_EQ(s.dynamic_removed, r.dynamic_removed);
}

TEST(Hd, MaxRangeIgnoresFarPoints) {
  const PointCloud truth = Labelled(10, 0);  // x = 0..9
  EvalConfig cfg;
  cfg.hd_truth_max_range_m = 4.5;  // only x = 0..4 count
  HdEvaluator ev(Unlabelled(truth, {0, 1}), cfg);
  ev.Add(truth, Eigen::Vector3d::Zero());
  const auto r = ev.Result();
  EXPECT_EQ(r.static_total, 5u);
  EXPECT_EQ(r.ignored, 5u);
  EXPECT_NEAR(r.sa, 0.4, 1e-12);
}

TEST(Hd, NearStaticSplit) {
  // 4 static points on x = 0..3 (y = 0); HD points: two 0.05 m above static points 0 and 1 (a
  // foot on the ground), two far away (y = 5). Output keeps every static point only.
  PointCloud truth = Labelled(4, 0);
  const float hd_xy[4][2] = {{0.f, 0.f}, {1.f, 0.f}, {0.f, 5.f}, {1.f, 5.f}};
  for (const auto& p : hd_xy) {
    truth.push_back(p[0], p[1], p[1] == 0.f ? 0.05f : 0.f);
    truth.cls.push_back(PointClass::kHD);
    truth.object.push_back(100);
  }
  EvalConfig cfg;  // match 0.1 m, near static 0.1 m
  HdEvaluator ev(Unlabelled(truth, {0, 1, 2, 3}), cfg);
  ev.SetStaticReference(Unlabelled(truth, {0, 1, 2, 3}));
  ev.Add(truth);
  const auto r = ev.Result();
  EXPECT_EQ(r.dynamic_total, 4u);
  EXPECT_EQ(r.dynamic_removed, 2u);  // the near-static pair is "preserved" by the ground points
  EXPECT_TRUE(r.separable_given);
  EXPECT_EQ(r.separable_total, 2u);
  EXPECT_EQ(r.separable_removed, 2u);
  EXPECT_DOUBLE_EQ(r.da_separable, 1.0);
  ASSERT_EQ(r.classes.size(), 3u);
  EXPECT_EQ(r.classes[2].name, "hd near static");
  EXPECT_EQ(r.classes[2].total, 2u);
}

TEST(Hd, UnlabelledTruthThrows) {
  PointCloud truth;
  truth.push_back(0, 0, 0);
  EXPECT_THROW(EvaluateHd(truth, truth, EvalConfig{}), Error);
}

// ------------------------------------------------------------------------------------ LD
PointCloud Row(int n, float y, float x0 = 0.f) {
  PointCloud c;
  for (int i = 0; i < n; ++i) c.push_back(x0 + float(i), y, 0.f);
  return c;
}

ChangeClouds TruthChanges() {
  ChangeClouds t;
  t.pd_strong = Row(10, 0.f);
  t.pd_weak = Row(5, 10.f);
  t.nd_strong = Row(8, 20.f);
  t.nd_weak = Row(4, 30.f);
  return t;
}

TEST(Ld, TruthAsPredictionIsPerfect) {
  const ChangeClouds t = TruthChanges();
  PointCloud kept = t.nd_weak;
  const auto r = EvaluateLd(t, t, &kept, EvalConfig{});
  for (const PrfStats* s : {&r.pd_strong, &r.pd_weak, &r.pd, &r.nd_strong, &r.nd_weak, &r.nd}) {
    EXPECT_DOUBLE_EQ(s->precision, 1.0);
    EXPECT_DOUBLE_EQ(s->recall, 1.0);
    EXPECT_DOUBLE_EQ(s->f1, 1.0);
  }
  EXPECT_DOUBLE_EQ(r.weak_nd_preserved, 1.0);
  EXPECT_DOUBLE_EQ(r.pd_strength_accuracy, 1.0);
  EXPECT_DOUBLE_EQ(r.nd_strength_accuracy, 1.0);
}

TEST(Ld, DistanceBandsSplitByTheObservingTrajectory) {
  ChangeClouds t;
  t.pd_strong = Row(10, 0.f);  // x = 0..9: distance to the central keyframe (0, -5) is sqrt(x^2 + 25)
  t.nd_strong = Row(8, 20.f);  // ~80 m from the query keyframe (0, 100)
  ChangeClouds p;
  p.pd_strong = Row(5, 0.f);         // x = 0..4: all within 8 m, all true
  p.pd_strong.append(Row(2, 0.f, 50.f));  // two false positives ~50 m away
  p.nd_strong = t.nd_strong;
  LdTrajectories traj;
  traj.central.push_back(0.f, -5.f, 0.f);
  traj.query.push_back(0.f, 100.f, 0.f);
  EvalConfig cfg;
  cfg.ld_bands_m = {8.0};
  const auto r = EvaluateLd(t, p, nullptr, cfg, 0, &traj);
  ASSERT_EQ(r.bands.size(), 2u);
  EXPECT_DOUBLE_EQ(r.bands[0].min_m, 0.0);
  EXPECT_DOUBLE_EQ(r.bands[0].max_m, 8.0);
  EXPECT_DOUBLE_EQ(r.bands[1].min_m, 8.0);
  EXPECT_TRUE(std::isinf(r.bands[1].max_m));
  // Band [0, 8): truth x = 0..6 (sqrt(36 + 25) < 8), 5 of them found; every prediction true.
  EXPECT_EQ(r.bands[0].pd.truth, 7u);
  EXPECT_EQ(r.bands[0].pd.predicted, 5u);
  EXPECT_DOUBLE_EQ(r.bands[0].pd.precision, 1.0);
  EXPECT_NEAR(r.bands[0].pd.recall, 5.0 / 7.0, 1e-12);
  // Band [8, inf): truth x = 7..9 missed; the two far predictions false.
  EXPECT_EQ(r.bands[1].pd.truth, 3u);
  EXPECT_DOUBLE_EQ(r.bands[1].pd.recall, 0.0);
  EXPECT_EQ(r.bands[1].pd.predicted, 2u);
  EXPECT_DOUBLE_EQ(r.bands[1].pd.precision, 0.0);
  // ND lies by the query trajectory: all far, all found.
  EXPECT_EQ(r.bands[0].nd.truth, 0u);
  EXPECT_EQ(r.bands[1].nd.truth, 8u);
  EXPECT_DOUBLE_EQ(r.bands[1].nd.recall, 1.0);
  // The pooled figures do not depend on the bands; without trajectories there are none.
  const auto pooled = EvaluateLd(t, p, nullptr, cfg);
  EXPECT_TRUE(pooled.bands.empty());
  EXPECT_DOUBLE_EQ(pooled.pd.precision, r.pd.precision);
  EXPECT_DOUBLE_EQ(pooled.pd.recall, r.pd.recall);
  // Band edges out of order or repeated are a config error, not silently reordered.
  cfg.ld_bands_m = {40.0, 20.0};
  EXPECT_THROW(EvaluateLd(t, p, nullptr, cfg, 0, &traj), Error);
  cfg.ld_bands_m = {20.0, 20.0};
  EXPECT_THROW(EvaluateLd(t, p, nullptr, cfg, 0, &traj), Error);
  // ... whether or not bands are asked for: the config itself is wrong.
  EXPECT_THROW(EvaluateLd(t, p, nullptr, cfg), Error);
  EXPECT_THROW(cfg.Validate(), Error);
}

// Recall over the changed objects' points alone: the truth's objects_*.pcd (a subset of its
// clouds) read from the pair folder, matched against every predicted point of the kind.
TEST(Ld, RecallOverChangedObjectsApartFromCoverage) {
  const ltm::test::TempDir tmp;
  const std::string dir = tmp.str();
  std::filesystem::create_directories(dir + "/truth");
  std::filesystem::create_directories(dir + "/pred");
  const ChangeClouds t = TruthChanges();  // rows 1 m apart: PD strong 10, PD weak 5, ND strong 8, ND weak 4
  ChangeClouds objects;
  objects.pd_strong = Row(4, 0.f);   // 4 of PD strong: an appeared object; the rest of PD is coverage
  objects.nd_strong = Row(8, 20.f);  // the disappeared object: all of ND strong; ND weak is coverage
  const std::pair<const char*, const PointCloud*> files[] = {
      {"pd_strong", &t.pd_strong}, {"pd_weak", &t.pd_weak}, {"nd_strong", &t.nd_strong}, {"nd_weak", &t.nd_weak},
      {"objects_pd_strong", &objects.pd_strong}, {"objects_pd_weak", &objects.pd_weak},
      {"objects_nd_strong", &objects.nd_strong}};
  for (const auto& [name, cloud] : files) io::WritePcd(dir + "/truth/" + name + ".pcd", *cloud);
  ChangeClouds p;
  p.pd_strong = Row(2, 0.f);        // half of the object, none of the coverage
  p.nd_weak = Row(8, 20.f);         // the whole object, as weak: recall pools both strengths
  for (const auto& [name, cloud] : {std::pair<const char*, const PointCloud*>{"pd_strong", &p.pd_strong},
                                    {"pd_weak", &p.pd_weak}, {"nd_strong", &p.nd_strong}, {"nd_weak", &p.nd_weak}})
    io::WritePcd(dir + "/pred/" + std::string(name) + ".pcd", *cloud);
  // Three of four object files: the truth does not name its objects, no split.
  EXPECT_FALSE(LoadLdCase(dir + "/truth", dir + "/pred", "").truth_objects.has_value());
  io::WritePcd(dir + "/truth/objects_nd_weak.pcd", objects.nd_weak);
  const LdCase c = LoadLdCase(dir + "/truth", dir + "/pred", "");
  ASSERT_TRUE(c.truth_objects.has_value());
  std::vector<std::pair<std::string, std::string>> inputs;
  const LdResult r = ScoreLdCase(c, "", "", "", EvalConfig{}, 0, &inputs);
  ASSERT_TRUE(r.objects_given);
  EXPECT_EQ(r.pd_objects.truth, 4u);
  EXPECT_DOUBLE_EQ(r.pd_objects.recall, 0.5);
  EXPECT_NEAR(r.pd.recall, 2.0 / 15.0, 1e-12);
  EXPECT_EQ(r.nd_objects.truth, 8u);
  EXPECT_DOUBLE_EQ(r.nd_objects.recall, 1.0);
  EXPECT_NEAR(r.nd.recall, 8.0 / 12.0, 1e-12);
  EXPECT_TRUE(std::isnan(r.nd_objects.precision));
  // Without the subset there is nothing to split.
  EXPECT_FALSE(EvaluateLd(t, p, nullptr, EvalConfig{}).objects_given);
}

// A change within the match distance of a surface the other session sampled cannot be told from it
// (a new hoarding's foot 0.1 m above the ground the central saw): the separable truth leaves it
// out, PD against the central's surfaces, ND against the query's, and the separable recall counts
// the rest only.
TEST(Ld, SeparableTruthLeavesOutChangesOnTheOtherSessionsSurfaces) {
  ChangeClouds t;
  t.pd_weak = Row(4, 0.f);       // x = 0..3 at y = 0.f
  t.nd_strong = Row(3, 20.f);    // x = 0..2 at y = 20
  PointCloud central_ground = Row(2, 0.f);  // under the first two PD points ...
  for (auto& p : central_ground.points) p.z -= 0.1f;  // ... 0.1 m below them
  PointCloud query_surface = Row(1, 20.f);  // on the first ND point
  for (auto& p : query_surface.points) p.y += 0.5f;  // ... 0.5 m off: separable
  const EvalConfig cfg;
  const ChangeClouds s = SeparableTruth(t, central_ground, query_surface, cfg);
  EXPECT_EQ(s.pd_weak.size(), 2u);
  EXPECT_EQ(s.nd_strong.size(), 3u);
  // Swapped: the query's surface says nothing of PD, the central's nothing of ND.
  const ChangeClouds w = SeparableTruth(t, query_surface, central_ground, cfg);
  EXPECT_EQ(w.pd_weak.size(), 4u);
  EXPECT_EQ(w.nd_strong.size(), 3u);
  ChangeClouds p;
  p.pd_weak = Row(4, 0.f);
  p.pd_weak.points.erase(p.pd_weak.points.begin(), p.pd_weak.points.begin() + 2);  // misses the two on the ground
  const LdResult r = EvaluateLd(t, p, nullptr, cfg, 0, nullptr, nullptr, &s);
  ASSERT_TRUE(r.separable_given);
  EXPECT_DOUBLE_EQ(r.pd.recall, 0.5);
  EXPECT_EQ(r.pd_separable.truth, 2u);
  EXPECT_DOUBLE_EQ(r.pd_separable.recall, 1.0);
  EXPECT_EQ(r.nd_separable.truth, 3u);
  EXPECT_DOUBLE_EQ(r.nd_separable.recall, 0.0);
  EXPECT_FALSE(EvaluateLd(t, p, nullptr, cfg).separable_given);
}

TEST(Ld, HandComputedCorruption) {
  const ChangeClouds t = TruthChanges();
  ChangeClouds p;
  // PD strong: 6 of the 10 truth points + 2 false positives far away -> P = 6/8, R = 6/10.
  p.pd_strong = Row(6, 0.f);
  p.pd_strong.append(Row(2, 50.f));
  // PD weak: predicted as strong-labelled elsewhere? Here: 2 truth weak points labelled STRONG
  // (appended to pd_strong) and none as weak.
  p.pd_strong.append(Row(2, 10.f));
  // ND: all strong found; the 4 weak ND are (wrongly) predicted as strong ND too.
  p.nd_strong = t.nd_strong;
  p.nd_strong.append(t.nd_weak);
  const auto r = EvaluateLd(t, p, nullptr, EvalConfig{});
  // pd_strong: predicted 10 (6 true strong + 2 far + 2 weak) -> matched to strong truth: 6.
  EXPECT_EQ(r.pd_strong.predicted, 10u);
  EXPECT_EQ(r.pd_strong.predicted_matched, 6u);
  EXPECT_NEAR(r.pd_strong.precision, 0.6, 1e-12);
  EXPECT_NEAR(r.pd_strong.recall, 0.6, 1e-12);
  EXPECT_NEAR(r.pd_strong.f1, 0.6, 1e-12);
  // pd_weak: nothing predicted -> precision undefined, recall 0.
  EXPECT_TRUE(std::isnan(r.pd_weak.precision));
  EXPECT_DOUBLE_EQ(r.pd_weak.recall, 0.0);
  EXPECT_TRUE(std::isnan(r.pd_weak.f1));
  // PD pooled: 8 of 10 predicted near truth PD; 8 of 15 truth PD found.
  EXPECT_NEAR(r.pd.precision, 0.8, 1e-12);
  EXPECT_NEAR(r.pd.recall, 8.0 / 15.0, 1e-12);
  // Strength: of 8 matched predicted PD, 6 have the right strength.
  EXPECT_EQ(r.pd_matched, 8u);
  EXPECT_EQ(r.pd_strength_correct, 6u);
  EXPECT_NEAR(r.pd_strength_accuracy, 0.75, 1e-12);
  // ND strong: P = 8/12, R = 1; pooled ND perfect; strength 8/12.
  EXPECT_NEAR(r.nd_strong.precision, 8.0 / 12.0, 1e-12);
  EXPECT_DOUBLE_EQ(r.nd_strong.recall, 1.0);
  EXPECT_DOUBLE_EQ(r.nd.precision, 1.0);
  EXPECT_DOUBLE_EQ(r.nd.recall, 1.0);
  EXPECT_NEAR(r.nd_strength_accuracy, 8.0 / 12.0, 1e-12);
  EXPECT_FALSE(r.kept_map_given);
  EXPECT_TRUE(std::isnan(r.weak_nd_preserved));
}

TEST(Ld, ErrorCloudsCountsMatchPrecisionAndRecall) {
  const ChangeClouds t = TruthChanges();
  ChangeClouds p;
  p.pd_strong = Row(6, 0.f);
  p.pd_strong.append(Row(2, 50.f));  // 2 false positives
  p.nd_weak = t.nd_weak;             // ND: 8 strong truth points missed
  const auto r = EvaluateLd(t, p, nullptr, EvalConfig{});
  const LdErrors e = LdErrorClouds(t, p, EvalConfig{});
  EXPECT_EQ(e.false_positives.size(), (r.pd.predicted - r.pd.predicted_matched) + (r.nd.predicted - r.nd.predicted_matched));
  EXPECT_EQ(e.false_negatives.size(), (r.pd.truth - r.pd.truth_matched) + (r.nd.truth - r.nd.truth_matched));
  ASSERT_EQ(e.false_positives.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(e.false_positives.cls[i], PointClass::kPDStrong);
    EXPECT_FLOAT_EQ(e.false_positives.points[i].x, p.pd_strong.points[6 + i].x);
  }
  std::size_t missed_nd_strong = 0, missed_pd = 0;
  for (const PointClass c : e.false_negatives.cls) {
    missed_nd_strong += c == PointClass::kNDStrong;
    missed_pd += c == PointClass::kPDStrong || c == PointClass::kPDWeak;
  }
  EXPECT_EQ(missed_nd_strong, 8u);
  EXPECT_EQ(missed_pd, 9u);  // 4 strong beyond the 6 found, 5 weak
}

TEST(Ld, WeakNdKeptDerivedFromChanges) {
  // Central map = static row + strong ND + weak ND. The method predicts 2 of the 4 weak ND as
  // strong (so removes them): kept fraction 2/4.
  const ChangeClouds t = TruthChanges();
  PointCloud central = Row(20, -10.f);
  central.append(t.nd_strong);
  central.append(t.nd_weak);
  ChangeClouds p = t;
  p.nd_strong.append(t.nd_weak.select(std::vector<std::uint32_t>{0, 1}));
  p.nd_weak = t.nd_weak.select(std::vector<std::uint32_t>{2, 3});
  const PointCloud kept = KeptMapFromChanges(central, p.nd_strong, EvalConfig{});
  EXPECT_EQ(kept.size(), 20u + 2u);
  const auto r = EvaluateLd(t, p, &kept, EvalConfig{});
  EXPECT_EQ(r.weak_nd_truth, 4u);
  EXPECT_EQ(r.weak_nd_kept, 2u);
  EXPECT_NEAR(r.weak_nd_preserved, 0.5, 1e-12);
}

// ------------------------------------------------------------------------------- restore
// n points on a 5x5 grid inside the patch with lower corner (cx, cy, cz), spacing 0.5 m,
// offset (ox, oy, oz) from the corner.
PointCloud Grid(int nx, int ny, double cx, double cy, double cz, double ox, double oy, double oz) {
  PointCloud c;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) c.push_back(float(cx + ox + 0.5 * i), float(cy + oy + 0.5 * j), float(cz + oz));
  return c;
}

TEST(Restore, IdenticalMapsHaveZeroChamfer) {
  PointCloud a = Grid(6, 6, 0, 0, 0, 0.2, 0.2, 1.0);
  a.append(Grid(6, 6, 5, 0, 0, 0.2, 0.2, 1.0));
  const auto r = EvaluateRestore(a, a, EvalConfig{});
  EXPECT_EQ(r.np_valid, 2u);
  EXPECT_DOUBLE_EQ(r.max, 0.0);
  EXPECT_DOUBLE_EQ(r.mean, 0.0);
  EXPECT_DOUBLE_EQ(r.variance, 0.0);
  EXPECT_EQ(r.np_above, (std::vector<std::size_t>{0, 0, 0}));
}

TEST(Restore, KnownPatchesAndExcludedSmallPatch) {
  // Patch 1 (cell 0,0,0): B = A shifted up by 1.5 m -> every NN distance 1.5 -> CD 1.5.
  // Patch 2 (cell 1,0,0): B = A shifted up by 2.5 m -> CD 2.5.
  // Patch 3 (cell 2,0,0): 36 A points but only 24 B points -> excluded.
  // Patch 4 (cell 3,0,0): only in A.
  PointCloud a = Grid(6, 6, 0, 0, 0, 0.2, 0.2, 0.5);
  PointCloud b = Grid(6, 6, 0, 0, 0, 0.2, 0.2, 2.0);
  a.append(Grid(6, 6, 5, 0, 0, 0.2, 0.2, 0.5));
  b.append(Grid(6, 6, 5, 0, 0, 0.2, 0.2, 3.0));
  a.append(Grid(6, 6, 10, 0, 0, 0.2, 0.2, 0.5));
  b.append(Grid(6, 4, 10, 0, 0, 0.2, 0.2, 4.5));
  a.append(Grid(6, 6, 15, 0, 0, 0.2, 0.2, 0.5));
  const auto r = EvaluateRestore(a, b, EvalConfig{});
  EXPECT_EQ(r.patches_a, 4u);
  EXPECT_EQ(r.patches_b, 3u);
  EXPECT_EQ(r.patches_both, 3u);
  EXPECT_EQ(r.np_valid, 2u);
  EXPECT_NEAR(r.max, 2.5, 1e-5);
  EXPECT_NEAR(r.mean, 2.0, 1e-5);
  EXPECT_NEAR(r.variance, 0.25, 1e-5);  // ((1.5-2)^2 + (2.5-2)^2) / 2
  EXPECT_EQ(r.np_above, (std::vector<std::size_t>{2, 1, 0}));

  EvalConfig cfg;
  cfg.chamfer = "fan_squared";  // 2 * 1.5^2 = 4.5 and 2 * 2.5^2 = 12.5
  const auto f = EvaluateRestore(a, b, cfg);
  EXPECT_NEAR(f.max, 12.5, 1e-4);
  EXPECT_NEAR(f.mean, 8.5, 1e-4);
  cfg.chamfer = "mean";
  cfg.patch_min_points = 24;  // now patch 3 counts: B->A 4.0 each; A->B 4.0 for the 24 points
  // under B and sqrt(4^2 + 0.5^2), sqrt(4^2 + 1^2) for the two extra rows of 6.
  const auto g = EvaluateRestore(a, b, cfg);
  EXPECT_EQ(g.np_valid, 3u);
  const double ab = (24 * 4.0 + 6 * std::sqrt(16.25) + 6 * std::sqrt(17.0)) / 36.0;
  EXPECT_NEAR(g.max, 0.5 * (ab + 4.0), 1e-5);
}

TEST(Restore, AsymmetricDirectedMeans) {
  // A: 25 points at z=1; B: the same 25 points plus 25 points 2 m above them (z=3).
  // d(A->B) = 0; d(B->A) = (25*0 + 25*2) / 50 = 1; CD = (0 + 1) / 2 = 0.5.
  const PointCloud a = Grid(5, 5, 0, 0, 0, 0.5, 0.5, 1.0);
  PointCloud b = a;
  b.append(Grid(5, 5, 0, 0, 0, 0.5, 0.5, 3.0));
  const auto r = EvaluateRestore(a, b, EvalConfig{});
  EXPECT_EQ(r.np_valid, 1u);
  EXPECT_NEAR(r.mean, 0.5, 1e-6);
  EXPECT_TRUE(std::isnan(r.same_class_a));  // unlabelled maps: no class agreement
}

// Class agreement of two labelled maps (live maps of two runs): B = A with a quarter of its
// points given another class and a tenth moved 1 m away.
TEST(Restore, SameClassShareBothWays) {
  PointCloud a = Grid(20, 20, 0, 0, 0, 0.2, 0.2, 1.0);
  a.cls.assign(a.size(), PointClass::kStatic);
  PointCloud b = a;
  for (std::size_t i = 0; i < b.size(); i += 4) b.cls[i] = PointClass::kPDStrong;
  for (std::size_t i = 1; i < b.size(); i += 10) b.points[i].z += 1.0f;  // odd i: kept class
  // Points 0.5 m apart: with a 0.3 m radius a point only sees its own copy.
  const auto r = EvaluateRestore(a, b, EvalConfig{});
  EXPECT_NEAR(r.same_class_a, 1.0 - 0.25 - 0.1, 1e-9);
  EXPECT_NEAR(r.same_class_b, 1.0 - 0.25 - 0.1, 1e-9);
  EXPECT_DOUBLE_EQ(SameClassFraction(a, a, 0.3), 1.0);
  PointCloud unlabelled = a;
  unlabelled.cls.clear();
  EXPECT_THROW(SameClassFraction(a, unlabelled, 0.3), Error);
}

}  // namespace
}  // namespace ltm::eval
