// LT-SLAM back end on synthetic pose graphs (no clouds): factor Jacobians vs numerical ones,
// the SE(3) log, DCS loss derivatives, anchor recovery from any yaw / offset, robustness to
// injected false loops (vs plain least squares), N sessions, bad input.
#include "ltmapper/slam/factors.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"
#include "test_slam_synth.hpp"
#include "test_util.hpp"

#include <ceres/autodiff_cost_function.h>

#include <array>
#include <cmath>
#include <random>

using namespace ltm;
using namespace ltm::slam;

namespace {
constexpr double kDeg = M_PI / 180.0;

std::array<double, 7> Block(const Pose& T) {
  const Eigen::Quaterniond q(T.linear());
  return {T.translation().x(), T.translation().y(), T.translation().z(), q.x(), q.y(), q.z(), q.w()};
}

Pose RandomPose(std::mt19937& rng, double t_scale, double r_scale) {
  std::uniform_real_distribution<double> U(-1, 1);
  Pose T = Pose::Identity();
  Eigen::Vector3d w(U(rng), U(rng), U(rng));
  T.linear() = Eigen::AngleAxisd(r_scale * U(rng), w.normalized()).toRotationMatrix();
  T.translation() = t_scale * Eigen::Vector3d(U(rng), U(rng), U(rng));
  return T;
}

// Compares the autodiff Jacobian of `cost` (blocks of 7) with central differences.
void CheckJacobians(const ceres::CostFunction& cost, std::vector<std::array<double, 7>> blocks) {
  const int nb = static_cast<int>(blocks.size());
  std::vector<const double*> params;
  for (auto& b : blocks) params.push_back(b.data());
  const int nr = cost.num_residuals();  // at most 6
  std::vector<std::vector<double>> jac(nb, std::vector<double>(std::size_t(nr) * 7));
  std::vector<double*> jac_ptrs;
  for (auto& j : jac) jac_ptrs.push_back(j.data());
  double r[6];
  ASSERT_TRUE(cost.Evaluate(params.data(), r, jac_ptrs.data()));
  const double h = 1e-6;
  double worst = 0;
  for (int b = 0; b < nb; ++b) {
    for (int p = 0; p < 7; ++p) {
      auto plus = blocks, minus = blocks;
      plus[b][p] += h;
      minus[b][p] -= h;
      std::vector<const double*> pp, pm;
      for (int i = 0; i < nb; ++i) {
        pp.push_back(plus[i].data());
        pm.push_back(minus[i].data());
      }
      double rp[6], rm[6];
      ASSERT_TRUE(cost.Evaluate(pp.data(), rp, nullptr));
      ASSERT_TRUE(cost.Evaluate(pm.data(), rm, nullptr));
      for (int k = 0; k < nr; ++k) {
        const double num = (rp[k] - rm[k]) / (2 * h);
        const double ana = jac[b][k * 7 + p];  // row-major nr x 7
        worst = std::max(worst, std::abs(num - ana) / (1.0 + std::abs(ana)));
      }
    }
  }
  EXPECT_LT(worst, 1e-6);
}

// Two sessions on a circle of radius 40 m: central in the world frame, the query in its own
// frame T_world_query = A_true, both with yaw drift; loops between nearby keyframes.
struct TwoSessions {
  std::vector<Session> sessions;
  std::vector<std::vector<Pose>> truth;  // world poses
  std::vector<LoopRecord> loops;
};

Session DriftedSession(const std::string& name, const std::vector<Pose>& world, const Pose& A,
                       double yaw_drift) {
  Session s;
  s.name = name;
  std::vector<Pose> inc;
  const std::vector<Pose> est = test::DriftedOdometry(world, A, yaw_drift, &inc);
  for (std::size_t k = 0; k < world.size(); ++k) {
    if (k > 0) {
      Edge e;
      e.from = int(k) - 1;
      e.to = int(k);
      e.T_from_to = inc[k - 1];
      s.odometry.push_back(e);
    }
    Keyframe kf;
    kf.index = int(k);
    kf.T_session_sensor = est[k];
    s.keyframes.push_back(kf);
  }
  return s;
}

std::vector<Pose> Circle(int n, double phase, double radius = 40.0) {
  std::vector<Pose> p;
  for (int k = 0; k < n; ++k) {
    const double a = phase + 2 * M_PI * k / n;
    p.push_back(test::MakePose(radius * std::cos(a), radius * std::sin(a), 0.2 * std::sin(3 * a),
                               a + M_PI / 2));
  }
  return p;
}

LoopRecord TrueLoop(const std::vector<Pose>& ta, const std::vector<Pose>& tb, int sa, int i, int sb,
                    int j, std::mt19937& rng, const SlamConfig& cfg) {
  LoopRecord l;
  l.a = {sa, i};
  l.b = {sb, j};
  l.source = "given";
  l.T_a_b = ta[i].inverse() * tb[j] * RandomPose(rng, 0.02, 0.1 * kDeg);
  l.fitness = 0.03;
  l.verified = true;
  const double st = cfg.loop_sigma_t_m, sr = cfg.loop_sigma_r_deg * kDeg;
  l.information = Matrix6d::Zero();
  l.information.diagonal() << Eigen::Vector3d::Constant(1 / (st * st)),
      Eigen::Vector3d::Constant(1 / (sr * sr));
  return l;
}

TwoSessions MakeTwoSessions(const Pose& A_true, int false_loops, unsigned seed,
                            const SlamConfig& cfg) {
  std::mt19937 rng(seed);
  TwoSessions t;
  t.truth = {Circle(80, 0.0), Circle(70, 0.3)};
  // The central odometry is exact (it defines the world); the query drifts.
  t.sessions = {DriftedSession("central", t.truth[0], Pose::Identity(), 0.0),
                DriftedSession("query", t.truth[1], A_true, -0.0005)};
  for (int j = 0; j < 70; j += 2) {
    int best = 0;
    for (int i = 0; i < 80; ++i) {
      if ((t.truth[0][i].translation() - t.truth[1][j].translation()).norm() <
          (t.truth[0][best].translation() - t.truth[1][j].translation()).norm()) {
        best = i;
      }
    }
    t.loops.push_back(TrueLoop(t.truth[0], t.truth[1], 0, best, 1, j, rng, cfg));
  }
  std::uniform_real_distribution<double> U(-1, 1);
  for (int f = 0; f < false_loops; ++f) {
    LoopRecord l = t.loops[(f * 7) % t.loops.size()];
    l.T_a_b = l.T_a_b * test::MakePose(20 + 15 * U(rng), 20 * U(rng), 0, 2.0 * U(rng));
    l.a.keyframe = (l.a.keyframe + 20 + f * 3) % 80;
    t.loops.push_back(l);
  }
  return t;
}

// Alignment error where it matters: RMSE of the query's world positions against truth (the
// session frame's origin may lie 100 m away, where a 0.1 deg rotation alone moves it by 0.2 m).
double WorldRmseM(const SlamResult& r, const std::vector<Pose>& truth) {
  double sum = 0;
  const auto& poses = r.sessions[1].T_world_sensor;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    sum += (poses[k].translation() - truth[k].translation()).squaredNorm();
  }
  return std::sqrt(sum / poses.size());
}
double AnchorErrorDeg(const SlamResult& r, const Pose& A) {
  return Eigen::AngleAxisd(r.sessions[1].anchor.linear().transpose() * A.linear()).angle() / kDeg;
}
}  // namespace

TEST(SlamFactors, LogInvertsExp) {
  std::mt19937 rng(1);
  for (double r_scale : {1e-9, 1e-4, 0.05, 0.5, 3.0}) {
    const Pose T = RandomPose(rng, 5.0, r_scale);
    const auto b = Block(T);
    const Eigen::Matrix<double, 6, 1> xi = detail::Log(detail::Load(b.data()));
    const Eigen::Vector3d w = xi.tail<3>(), rho = xi.head<3>();
    const double th = w.norm();
    EXPECT_LT(Eigen::AngleAxisd(Eigen::AngleAxisd(th, th > 0 ? Eigen::Vector3d(w / th) : Eigen::Vector3d::UnitX())
                                    .toRotationMatrix()
                                    .transpose() *
                                T.linear())
                  .angle(),
              1e-9);
    Eigen::Matrix3d W;
    W << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
    const Eigen::Matrix3d V =
        th < 1e-6 ? Eigen::Matrix3d(Eigen::Matrix3d::Identity() + 0.5 * W)
                  : Eigen::Matrix3d(Eigen::Matrix3d::Identity() + (1 - std::cos(th)) / (th * th) * W +
                                    (th - std::sin(th)) / (th * th * th) * W * W);
    EXPECT_LT((V * rho - T.translation()).norm(), 1e-9) << "r_scale " << r_scale;
  }
}

TEST(SlamFactors, AnchorLoopJacobianMatchesNumerical) {
  std::mt19937 rng(2);
  for (int trial = 0; trial < 6; ++trial) {
    const Pose Aa = RandomPose(rng, 50, 3.0), xa = RandomPose(rng, 20, 3.0);
    const Pose Ab = RandomPose(rng, 50, 3.0), xb = RandomPose(rng, 20, 3.0);
    // Half the trials near the solution (residual ~ 0, small-angle branch), half far from it.
    const Pose z = trial % 2 ? RandomPose(rng, 5, 2.0)
                             : (Aa * xa).inverse() * (Ab * xb) * RandomPose(rng, 1e-3, 1e-4);
    Matrix6d L = Matrix6d::Identity() * 3.0;
    L(0, 4) = 0.5;
    ceres::AutoDiffCostFunction<detail::AnchorLoopFactor, 6, 7, 7, 7, 7> cost(
        new detail::AnchorLoopFactor(z, L));
    CheckJacobians(cost, {Block(Aa), Block(xa), Block(Ab), Block(xb)});
  }
}

TEST(SlamFactors, BetweenJacobianMatchesNumerical) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 4; ++trial) {
    const Pose xa = RandomPose(rng, 20, 3.0), xb = RandomPose(rng, 20, 3.0);
    const Pose z = trial % 2 ? RandomPose(rng, 5, 2.0) : xa.inverse() * xb;
    ceres::AutoDiffCostFunction<detail::BetweenFactor, 6, 7, 7> cost(
        new detail::BetweenFactor(z, Matrix6d::Identity()));
    CheckJacobians(cost, {Block(xa), Block(xb)});
  }
}

TEST(SlamFactors, ResidualIsZeroAtTruthAndMatchesDefinition) {
  std::mt19937 rng(4);
  const Pose Aa = RandomPose(rng, 50, 3.0), xa = RandomPose(rng, 20, 3.0);
  const Pose Ab = RandomPose(rng, 50, 3.0), xb = RandomPose(rng, 20, 3.0);
  const Pose z = (Aa * xa).inverse() * (Ab * xb);
  detail::AnchorLoopFactor f(z, Matrix6d::Identity());
  auto ba = Block(Aa), bxa = Block(xa), bb = Block(Ab), bxb = Block(xb);
  double r[6];
  f(ba.data(), bxa.data(), bb.data(), bxb.data(), r);
  const Eigen::Map<Eigen::Matrix<double, 6, 1>> rv(r);
  EXPECT_LT(rv.norm(), 1e-9);
  // A pure rotation error about z of 0.1 rad shows up as omega_z = 0.1.
  detail::AnchorLoopFactor g(z * test::MakePose(0, 0, 0, -0.1), Matrix6d::Identity());
  g(ba.data(), bxa.data(), bb.data(), bxb.data(), r);
  EXPECT_NEAR(r[5], 0.1, 1e-9);
  EXPECT_NEAR(Eigen::Vector3d(r[0], r[1], r[2]).norm(), 0.0, 1e-9);
}

TEST(SlamFactors, DcsLossDerivatives) {
  const double phi = 1.5;
  for (double s : {0.1, 1.0, 1.5, 2.0, 10.0, 1000.0}) {
    double rho[3], rp[3], rm[3];
    const double h = 1e-5;
    detail::DcsLoss(phi, s, rho);
    detail::DcsLoss(phi, s + h, rp);
    detail::DcsLoss(phi, s - h, rm);
    EXPECT_NEAR(rho[1], (rp[0] - rm[0]) / (2 * h), 1e-5) << s;
    if (std::abs(s - phi) > 1e-3) {
      EXPECT_NEAR(rho[2], (rp[1] - rm[1]) / (2 * h), 1e-5) << s;
    }
    // The weight equals the DCS scaling squared, min(1, 2 phi / (phi + s))^2.
    const double w = std::min(1.0, 2 * phi / (phi + s));
    EXPECT_NEAR(rho[1], w * w, 1e-12);
  }
}

TEST(SlamGraph, RecoversAnchorFromArbitraryYawAndOffset) {
  SlamConfig cfg;
  for (const Pose& A : {test::MakePose(-80, 65, 3, 137 * kDeg, 2 * kDeg, -1 * kDeg),
                        test::MakePose(95, -10, -2, -170 * kDeg), test::MakePose(0, 0, 0, 0)}) {
    TwoSessions t = MakeTwoSessions(A, 0, 7, cfg);
    const SlamResult r = OptimizeSessions(t.sessions, t.loops, cfg, 1);
    ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
    EXPECT_TRUE(r.solution_usable);
    EXPECT_LT(WorldRmseM(r, t.truth[1]), 0.1);
    EXPECT_LT(AnchorErrorDeg(r, A), 0.2);
    // Drift is corrected: world poses of both sessions near truth.
    double worst = 0;
    for (int s = 0; s < 2; ++s) {
      for (std::size_t k = 0; k < t.truth[s].size(); ++k) {
        worst = std::max(worst, (r.sessions[s].T_world_sensor[k].translation() -
                                 t.truth[s][k].translation())
                                    .norm());
      }
    }
    EXPECT_LT(worst, 0.3);
    for (const auto& l : r.loops) EXPECT_TRUE(l.accepted) << l.status;
  }
}

TEST(SlamGraph, RobustLossSurvivesFalseLoopsWhereLeastSquaresDoesNot) {
  const Pose A = test::MakePose(40, -70, 1, 75 * kDeg);
  for (const std::string loss : {"cauchy", "dcs", "none"}) {
    SlamConfig cfg;
    cfg.robust_loss = loss;
    cfg.gate_inconsistent_loops = false;  // the loss alone has to cope
    cfg.outlier_t_m = 1e6;                // no pruning after the optimisation either
    cfg.outlier_r_deg = 360;
    TwoSessions t = MakeTwoSessions(A, 6, 9, cfg);
    const SlamResult r = OptimizeSessions(t.sessions, t.loops, cfg, 1);
    ASSERT_TRUE(r.sessions[1].aligned);
    const double et = WorldRmseM(r, t.truth[1]), er = AnchorErrorDeg(r, A);
    std::printf("loss %-6s: query world RMSE %.3f m, anchor %.3f deg (6 false loops of %zu)\n",
                loss.c_str(),
                et, er, t.loops.size());
    if (loss == "none") {
      EXPECT_GT(et, 0.5);  // plain least squares is pulled off by the false loops
    } else {
      EXPECT_LT(et, 0.15);
      EXPECT_LT(er, 0.3);
    }
  }
}

TEST(SlamGraph, DefaultPipelineRejectsFalseLoops) {
  SlamConfig cfg;
  const Pose A = test::MakePose(-30, 20, 0, -60 * kDeg);
  TwoSessions t = MakeTwoSessions(A, 6, 10, cfg);
  const SlamResult r = OptimizeSessions(t.sessions, t.loops, cfg, 1);
  ASSERT_TRUE(r.sessions[1].aligned);
  EXPECT_LT(WorldRmseM(r, t.truth[1]), 0.1);
  const std::size_t n_true = t.loops.size() - 6;
  for (std::size_t i = 0; i < r.loops.size(); ++i) {
    EXPECT_EQ(r.loops[i].accepted, i < n_true) << i << ": " << r.loops[i].status;
  }
}

TEST(SlamGraph, QueryAnchoredThroughAnotherQuery) {
  SlamConfig cfg;
  std::mt19937 rng(5);
  const Pose A1 = test::MakePose(50, 50, 0, 1.0), A2 = test::MakePose(-60, 10, 0, -2.5);
  const std::vector<std::vector<Pose>> truth = {Circle(60, 0.0), Circle(60, 0.1),
                                                Circle(60, 0.2, 60.0)};
  std::vector<Session> s = {DriftedSession("c", truth[0], Pose::Identity(), 0),
                            DriftedSession("q1", truth[1], A1, 0.0003),
                            DriftedSession("q2", truth[2], A2, 0.0003)};
  // Session 2 drives a larger circle: it overlaps... only session 1 by construction of the
  // loops given here (no loop to the central).
  std::vector<LoopRecord> loops;
  for (int j = 0; j < 60; j += 3) {
    loops.push_back(TrueLoop(truth[0], truth[1], 0, j, 1, j, rng, cfg));
    loops.push_back(TrueLoop(truth[1], truth[2], 1, j, 2, j, rng, cfg));
  }
  const SlamResult r = OptimizeSessions(s, loops, cfg, 1);
  for (int q : {1, 2}) {
    ASSERT_TRUE(r.sessions[q].aligned) << r.sessions[q].reason;
    const Pose& A = q == 1 ? A1 : A2;
    EXPECT_LT((r.sessions[q].anchor.translation() - A.translation()).norm(), 0.15);
  }
}

TEST(SlamGraph, RepetitivePlacesDoNotDecideByACoinToss) {
  // Repetitive world: besides true loops, a group of loops agrees on a placement shifted by one
  // "block" (all measurements offset alike). With the rival as strong as the truth the query is
  // not aligned; once the truth leads by graph.min_loops loops it is aligned at the truth.
  SlamConfig cfg;
  const Pose A = test::MakePose(-30, 20, 0, -60 * kDeg);
  TwoSessions t = MakeTwoSessions(A, 0, 12, cfg);
  const Pose block = test::MakePose(25, 0, 0, 0);  // the period of the repetition
  std::vector<LoopRecord> tied;
  for (int i = 0; i < 4; ++i) tied.push_back(t.loops[i]);
  for (int i = 4; i < 8; ++i) {
    LoopRecord l = t.loops[i];
    l.T_a_b = block * l.T_a_b;
    tied.push_back(l);
  }
  SlamResult r = OptimizeSessions(t.sessions, tied, cfg, 1);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_NE(r.sessions[1].reason.find("ambiguous"), std::string::npos) << r.sessions[1].reason;
  std::vector<LoopRecord> lead = tied;
  for (int i = 8; i < 8 + cfg.min_loops; ++i) lead.push_back(t.loops[i]);
  r = OptimizeSessions(t.sessions, lead, cfg, 1);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  for (std::size_t i = 0; i < r.loops.size(); ++i) {
    const bool rival = i >= 4 && i < 8;
    EXPECT_EQ(r.loops[i].accepted, !rival) << i << ": " << r.loops[i].status;
  }
}

TEST(SlamGraph, NoOverlapIsReportedNotAligned) {
  SlamConfig cfg;
  TwoSessions t = MakeTwoSessions(test::MakePose(10, 0, 0, 1), 0, 11, cfg);
  std::vector<LoopRecord> none;
  SlamResult r = OptimizeSessions(t.sessions, none, cfg, 1);
  EXPECT_TRUE(r.sessions[0].aligned);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_NE(r.sessions[1].reason.find("no verified"), std::string::npos) << r.sessions[1].reason;
  EXPECT_TRUE(r.sessions[1].T_world_sensor.empty());
  // Two loops that disagree with each other are not enough either.
  std::vector<LoopRecord> two = {t.loops[0], t.loops[5]};
  two[1].T_a_b = two[1].T_a_b * test::MakePose(30, 0, 0, 1.0);
  r = OptimizeSessions(t.sessions, two, cfg, 1);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_NE(r.sessions[1].reason.find("consistent"), std::string::npos) << r.sessions[1].reason;
}

// Three loops agree within the consensus gates (one 2.5 m off the others), so the query is
// anchored; after the solve the off one lies beyond graph.outlier_t_m and is pruned, leaving two of
// graph.min_loops = 3: the query is no longer aligned. The next solve must hold none of its loops
// (a loop still accepted there reached into the query's absent poses: a crash, found on a 3-session
// rosette).
TEST(SlamGraph, AQueryLeftWithTooFewLoopsIsDroppedWithItsLoops) {
  SlamConfig cfg;
  TwoSessions t = MakeTwoSessions(test::MakePose(10, 0, 0, 1), 0, 12, cfg);
  std::vector<LoopRecord> three = {t.loops[0], t.loops[2], t.loops[4]};
  three[2].T_a_b = three[2].T_a_b * test::MakePose(2.5, 0, 0, 0);
  const SlamResult r = OptimizeSessions(t.sessions, three, cfg, 1);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_NE(r.sessions[1].reason.find("left after outlier rejection"), std::string::npos) << r.sessions[1].reason;
  for (const LoopRecord& l : r.loops) EXPECT_FALSE(l.accepted) << l.status;
}

TEST(SlamGraph, BrokenInputIsAnError) {
  SlamConfig cfg;
  TwoSessions t = MakeTwoSessions(Pose::Identity(), 0, 12, cfg);
  auto broken = t.sessions;
  broken[1].odometry[3].to = 999;
  try {
    OptimizeSessions(broken, t.loops, cfg, 1);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("broken pose graph"), std::string::npos) << e.what();
  }
  auto empty = t.sessions;
  empty[1].keyframes.clear();
  EXPECT_THROW(OptimizeSessions(empty, t.loops, cfg, 1), Error);
  auto bad_loop = t.loops;
  bad_loop[0].b.keyframe = 500;
  EXPECT_THROW(OptimizeSessions(t.sessions, bad_loop, cfg, 1), Error);
  auto bad_info = t.sessions;
  bad_info[0].odometry[0].has_information = true;
  bad_info[0].odometry[0].information = -Matrix6d::Identity();
  EXPECT_THROW(OptimizeSessions(bad_info, t.loops, cfg, 1), Error);
  SlamConfig bad_cfg;
  bad_cfg.robust_loss = "huber";
  EXPECT_THROW(OptimizeSessions(t.sessions, t.loops, bad_cfg, 1), Error);
}

// GravityFactor: zero for any turn about the vertical, the tilt over sigma for a tilt (0.1 deg of
// roll: 0.1 deg / sigma), and autodiff's Jacobian matches the numerical one.
TEST(SlamFactors, GravityIsTheTiltAndIgnoresTheHeading) {
  const double sigma = 0.2 * kDeg;
  const Pose level = test::MakePose(3, -4, 1, 1.3);  // a yaw of 1.3 rad
  const Eigen::Vector3d up = level.linear().transpose() * Eigen::Vector3d::UnitZ();
  const detail::GravityFactor f{up, 1.0 / sigma};
  double r[3];
  const Pose yawed = level * test::MakePose(0, 0, 0, 0.4);
  auto b = Block(yawed);
  f(b.data(), r);
  EXPECT_LT(Eigen::Vector3d(r[0], r[1], r[2]).norm(), 1e-9);
  const Pose rolled = level * Pose(Eigen::AngleAxisd(0.1 * kDeg, Eigen::Vector3d::UnitX()));
  b = Block(rolled);
  f(b.data(), r);
  EXPECT_NEAR(Eigen::Vector3d(r[0], r[1], r[2]).norm(), 0.1 * kDeg / sigma, 1e-6);
  std::mt19937 rng(6);
  for (int trial = 0; trial < 4; ++trial) {
    ceres::AutoDiffCostFunction<detail::GravityFactor, 3, 7> cost(new detail::GravityFactor{up, 1.0 / sigma});
    CheckJacobians(cost, {Block(RandomPose(rng, 20, 0.5))});
  }
}

// Registered steps hold the heading stiffly (0.0025 deg a step) and carry a bias their closures
// missed (0.03 deg a step), so steps and loops disagree in heading by hundredths of a degree. Roll
// and pitch, which the odometry holds only at 0.2 deg a step, must not take it up (a tilt along a
// stretch turns the heading by its product): each keyframe stays level within 0.02 deg (0.008
// with GravityFactor, 0.038 without), with the loops' heading measured (cycles) and the query
// aligned.
TEST(SlamGraph, StiffHeadingDoesNotEscapeIntoTilt) {
  SlamConfig cfg;
  const Pose A = test::MakePose(30, -20, 1, 60 * kDeg);
  TwoSessions t = MakeTwoSessions(A, 0, 9, cfg);
  const double step_sigma = 0.0025 * kDeg, bias = 0.03 * kDeg;
  std::mt19937 rng(10);
  std::normal_distribution<double> N(0.0, step_sigma);
  for (std::size_t s = 0; s < 2; ++s)
    for (std::size_t k = 0; k + 1 < t.truth[s].size(); ++k) {
      Edge e;
      e.from = int(k);
      e.to = int(k + 1);
      e.T_from_to = t.truth[s][k].inverse() * t.truth[s][k + 1] *
                    Pose(Eigen::AngleAxisd(bias + N(rng), Eigen::Vector3d::UnitZ()));
      e.information = HeadingInformation(step_sigma * step_sigma, Eigen::Vector3d::UnitZ(), cfg);
      e.has_information = true;
      t.sessions[s].registered.push_back(e);
    }
  for (LoopRecord& l : t.loops) l.heading_variance = std::pow(0.01 * kDeg, 2);
  const SlamResult r = OptimizeSessions(t.sessions, t.loops, cfg, 1);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  EXPECT_GT(r.heading_cycles, 0);
  double worst = 0.0;
  for (std::size_t s = 0; s < 2; ++s)
    for (const Pose& T : r.sessions[s].T_world_sensor) {
      const Eigen::Vector3d up = T.linear().transpose() * Eigen::Vector3d::UnitZ();
      worst = std::max(worst, std::acos(std::min(1.0, up.z())) / kDeg);
    }
  std::printf("worst tilt %.4f deg\n", worst);
  EXPECT_LT(worst, 0.02);
}

// Registered steps hold the horizontal translation too (HorizontalInformation): a query whose
// odometry is 3 % long (a scale error, as the simulator's drift.scale) keeps its steps within a few
// millimetres of the truth where the steps' horizontal translation (2 mm) joins the graph; with
// the heading alone the odometry's scale shows in every step, loops or not.
TEST(SlamGraph, RegisteredStepsHoldTheHorizontalTranslation) {
  SlamConfig cfg;
  const Pose A = test::MakePose(30, -20, 1, 60 * kDeg);
  const auto step_error = [&](bool horizontal) {
    TwoSessions t = MakeTwoSessions(A, 0, 9, cfg);
    Session& q = t.sessions[1];
    for (Edge& e : q.odometry) e.T_from_to.translation() *= 1.03;
    for (std::size_t k = 1; k < q.keyframes.size(); ++k)
      q.keyframes[k].T_session_sensor = q.keyframes[k - 1].T_session_sensor * q.odometry[k - 1].T_from_to;
    const double sigma = 0.002;
    std::mt19937 rng(4);
    std::normal_distribution<double> N(0.0, sigma);
    for (std::size_t k = 0; k + 1 < t.truth[1].size(); ++k) {
      Edge e;
      e.from = int(k);
      e.to = int(k + 1);
      e.T_from_to = t.truth[1][k].inverse() * t.truth[1][k + 1] * Pose(Eigen::Translation3d(N(rng), N(rng), 0.0));
      e.information = HeadingInformation(std::pow(0.0025 * kDeg, 2), Eigen::Vector3d::UnitZ(), cfg);
      if (horizontal)
        e.information += HorizontalInformation(Eigen::Matrix2d::Identity() * sigma * sigma, Eigen::Vector3d::UnitZ());
      e.has_information = true;
      q.registered.push_back(e);
    }
    const SlamResult r = OptimizeSessions(t.sessions, t.loops, cfg, 1);
    EXPECT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
    const auto& est = r.sessions[1].T_world_sensor;
    double sum = 0.0;
    for (std::size_t k = 0; k + 1 < est.size(); ++k) {
      const Pose e = (t.truth[1][k].inverse() * t.truth[1][k + 1]).inverse() * (est[k].inverse() * est[k + 1]);
      sum += e.translation().head<2>().squaredNorm();
    }
    return std::sqrt(sum / double(est.size() - 1));
  };
  const double with = step_error(true), without = step_error(false);
  std::printf("step error RMS: %.4f m with the horizontal translation, %.4f m with the heading alone\n", with, without);
  EXPECT_LT(with, 0.005);
  EXPECT_GT(without, 0.02);
}

// Steps whose registrations state 9 mm a step (their Fisher information; the matrix rows' steps
// err 0.05-0.11 x that variance) but drift sideways along the way (5 mm a step, a swing of 40 steps:
// no closure of a step and a two-step sees it, nor one scale or turn of the session) bend the
// query away from the central where the loops hold only the paper's 0.1 m. Loops along a street
// hold its cross direction far finer than its axis (3 mm against 2 cm, as their errors here): their
// registrations' translation covariance, scaled as their cycles measure (LoopTranslationScale),
// holds the sessions together.
TEST(SlamGraph, LoopsHoldTheTranslationAsFinelyAsTheirCyclesShow) {
  SlamConfig cfg;
  const Pose A = test::MakePose(30, -20, 1, 60 * kDeg);
  TwoSessions t = MakeTwoSessions(A, 0, 9, cfg);
  const double sigma = 0.009, along = 0.02, across = 0.003;
  for (std::size_t s = 0; s < 2; ++s)
    for (std::size_t k = 0; k + 1 < t.truth[s].size(); ++k) {
      Edge e;
      e.from = int(k);
      e.to = int(k + 1);
      const double side = s == 1 ? 0.005 * std::sin(2.0 * M_PI * double(k) / 40.0) : 0.0;
      e.T_from_to = t.truth[s][k].inverse() * t.truth[s][k + 1] * Pose(Eigen::Translation3d(0.0, side, 0.0));
      e.information = HeadingInformation(std::pow(0.0025 * kDeg, 2), Eigen::Vector3d::UnitZ(), cfg) +
                      HorizontalInformation(Eigen::Matrix2d::Identity() * sigma * sigma, Eigen::Vector3d::UnitZ());
      e.has_information = true;
      t.sessions[s].registered.push_back(e);
    }
  std::mt19937 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  for (LoopRecord& l : t.loops)
    l.T_a_b = t.truth[0][std::size_t(l.a.keyframe)].inverse() * t.truth[1][std::size_t(l.b.keyframe)] *
              Pose(Eigen::Translation3d(along * N(rng), across * N(rng), 0.0));
  const auto rmse = [&](bool loops_translation) {
    std::vector<LoopRecord> loops = t.loops;
    for (LoopRecord& l : loops)
      l.translation_covariance = loops_translation ? Eigen::Vector3d(along * along, across * across, across * across)
                                                         .asDiagonal()
                                                         .toDenseMatrix()
                                                   : Eigen::Matrix3d::Zero();
    const SlamResult r = OptimizeSessions(t.sessions, loops, cfg, 1);
    EXPECT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
    EXPECT_EQ(r.translation_cycles > 0, loops_translation);
    return WorldRmseM(r, t.truth[1]);
  };
  const double with = rmse(true), without = rmse(false);
  std::printf("query world RMSE: %.4f m with the loops' translation, %.4f m with the paper's alone\n", with, without);
  EXPECT_LT(with, 0.8 * without);
}
