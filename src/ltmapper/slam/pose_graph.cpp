// LT-SLAM back end: anchor initialisation from verified loops, consistency gating, Ceres pose
// graph with anchor nodes and robust inter-session factors, outlier pruning.
#include "ltmapper/slam/factors.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/alignment.hpp"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <thread>
#include <tuple>

namespace ltm::slam {

namespace {
using Block = std::array<double, 7>;
constexpr double kDeg = M_PI / 180.0;

Block ToBlock(const Pose& T) {
  const Eigen::Quaterniond q(T.linear());
  const Eigen::Vector3d t = T.translation();
  return {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
}
Pose FromBlock(const Block& b) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(b[6], b[3], b[4], b[5]).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(b[0], b[1], b[2]);
  return T;
}

Matrix6d SqrtInformation(const Matrix6d& info, const std::string& what) {
  const Matrix6d sym = 0.5 * (info + info.transpose());
  Eigen::LLT<Matrix6d> llt(sym);
  if (llt.info() != Eigen::Success || !sym.allFinite()) {
    throw Error(what + ": information matrix is not positive definite");
  }
  // info = L L^T, so |L^T r|^2 = r^T info r.
  return llt.matrixL().transpose();
}

class DcsLossFunction : public ceres::LossFunction {
 public:
  explicit DcsLossFunction(double phi) : phi_(phi) {}
  void Evaluate(double s, double rho[3]) const override { detail::DcsLoss(phi_, s, rho); }

 private:
  double phi_;
};

ceres::LossFunction* MakeLoss(const SlamConfig& cfg) {
  if (cfg.robust_loss == "cauchy") return new ceres::CauchyLoss(cfg.robust_scale);
  if (cfg.robust_loss == "dcs") return new DcsLossFunction(cfg.robust_scale);
  if (cfg.robust_loss == "none") return nullptr;
  throw Error("graph.robust_loss: unknown value '" + cfg.robust_loss + "' (cauchy|dcs|none)");
}

// A session edge's information in the graph: its own (`own_information`: registered steps), or
// the file's when graph.use_g2o_information says so, else the config's odometry sigmas.
Matrix6d EdgeInformation(const Edge& e, const SlamConfig& cfg, bool own_information) {
  if ((cfg.use_g2o_information || own_information) && e.has_information) return e.information;
  return DiagInformation(cfg.odom_sigma_t_m, cfg.odom_sigma_r_deg * kDeg);
}

struct Graph {
  const std::vector<Session>& sessions;
  const SlamConfig& cfg;
  std::vector<std::vector<Pose>> poses;  // current estimate, session frame
  std::vector<Pose> anchors;
  std::vector<bool> aligned;
  LoopCycleScale heading;      // how far the loops' heading variances misstate their errors (LoopHeadingScale)
  LoopCycleScale translation;  // and their horizontal translation's (LoopTranslationScale)
};

struct SolveStats {
  bool usable = true;
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
};

// The Ceres problem over the aligned sessions' poses (blocks of 7: t, q) and their anchors.
class GraphProblem {
 public:
  explicit GraphProblem(const Graph& g)
      : g_(g),
        nodes_(g.sessions.size()),
        anchors_(g.sessions.size()),
        manifold_(new ceres::ProductManifold<ceres::EuclideanManifold<3>, ceres::EigenQuaternionManifold>()) {
    for (std::size_t s = 0; s < g.sessions.size(); ++s) {
      if (!g.aligned[s]) continue;
      for (const Pose& T : g.poses[s]) nodes_[s].push_back(ToBlock(T));
      anchors_[s] = ToBlock(g.anchors[s]);
    }
  }

  // A session's odometry and own loops. Gauge: a session's frame is only defined up to a rigid
  // motion (its anchor and all its poses can move together without changing any residual).
  // Fixing its first pose at the odometry value removes that freedom; the anchor then carries
  // the session's placement.
  void AddSession(std::size_t s) {
    for (auto& b : nodes_[s]) AddBlock(b.data());
    problem_.SetParameterBlockConstant(nodes_[s][0].data());
    AddEdges(s, g_.sessions[s].odometry, "odometry");
    AddEdges(s, g_.sessions[s].loops, "loop");
    AddEdges(s, g_.sessions[s].registered, "registered step", true);
    if (!g_.sessions[s].registered.empty()) AddGravity(s);
  }

  // An accepted inter-session loop through both sessions' anchors, with the robust loss; a loop
  // within one session (OwnLoop) between its two poses (the anchor cancels), with the same loss.
  void AddLoop(const LoopRecord& l) {
    const int sa = l.a.session, sb = l.b.session;
    const Matrix6d info = LoopGraphInformation(l);
    if (OwnLoop(l)) {
      auto* cost = new ceres::AutoDiffCostFunction<detail::BetweenFactor, 6, 7, 7>(
          new detail::BetweenFactor(l.T_a_b, SqrtInformation(info, "loop within a session")));
      problem_.AddResidualBlock(cost, MakeLoss(g_.cfg), nodes_[sa][l.a.keyframe].data(), nodes_[sb][l.b.keyframe].data());
      return;
    }
    double* A = anchors_[sa].data();
    double* B = anchors_[sb].data();
    AddBlock(A);
    AddBlock(B);
    auto* cost = new ceres::AutoDiffCostFunction<detail::AnchorLoopFactor, 6, 7, 7, 7, 7>(
        new detail::AnchorLoopFactor(l.T_a_b, SqrtInformation(info, "inter-session loop")));
    problem_.AddResidualBlock(cost, MakeLoss(g_.cfg), A, nodes_[sa][l.a.keyframe].data(), B,
                              nodes_[sb][l.b.keyframe].data());
  }

  // The central session's anchor is the world frame: constant (the paper gives it a tiny
  // covariance; constant is the limit). Query anchors are free. Throws when unusable.
  SolveStats Solve(int threads) {
    if (problem_.HasParameterBlock(anchors_[0].data())) problem_.SetParameterBlockConstant(anchors_[0].data());
    ceres::Solver::Options opt;
    opt.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    opt.max_num_iterations = g_.cfg.solver_max_iterations;
    opt.num_threads = threads > 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
    opt.minimizer_progress_to_stdout = false;
    opt.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, &problem_, &summary);
    SolveStats st;
    st.usable = summary.IsSolutionUsable();
    st.initial_cost = summary.initial_cost;
    st.final_cost = summary.final_cost;
    st.iterations = static_cast<int>(summary.iterations.size());
    if (!st.usable) throw Error("pose graph optimisation failed: " + summary.message);
    return st;
  }

  void WriteBack(Graph& g) const {
    for (std::size_t s = 0; s < g.sessions.size(); ++s) {
      if (!g.aligned[s]) continue;
      for (std::size_t k = 0; k < nodes_[s].size(); ++k) g.poses[s][k] = FromBlock(nodes_[s][k]);
      g.anchors[s] = FromBlock(anchors_[s]);
    }
  }

 private:
  void AddBlock(double* b) {
    if (!problem_.HasParameterBlock(b)) problem_.AddParameterBlock(b, 7, manifold_);
  }

  // A loop's information: the paper's, plus its registration's on the heading and on the horizontal
  // translation, each scaled as the loops' cycles show, where they measured it (registration.steps:
  // steps that hold a session's heading and translation need loops that tie the sessions as finely,
  // else the steps' shares that no closure sees bend the sessions apart; docs/RESULTS.md: "The loops
  // hold the horizontal translation as finely as their cycles show").
  Matrix6d LoopGraphInformation(const LoopRecord& l) const {
    Matrix6d info = l.information;
    const Eigen::Vector3d up = Up(g_.sessions[std::size_t(l.b.session)].keyframes[std::size_t(l.b.keyframe)]);
    if (l.heading_variance > 0.0 && g_.heading.cycles > 0)
      info += HeadingInformation(l.heading_variance * g_.heading.scale, up, g_.cfg);
    if (!l.translation_covariance.isZero() && g_.translation.cycles > 0) {
      const Eigen::Matrix<double, 3, 2> H = Horizontal(up);
      info += HorizontalInformation(H.transpose() * l.translation_covariance * H * g_.translation.scale, up);
    }
    return info;
  }

  // Edges of session s; `own_information`: each edge's information, else the file's only when
  // graph.use_g2o_information says so (else the config's odometry sigmas).
  void AddEdges(std::size_t s, const std::vector<Edge>& edges, const char* kind, bool own_information = false) {
    const Session& ses = g_.sessions[s];
    for (const Edge& e : edges) {
      const int a = ses.Find(e.from), b = ses.Find(e.to);
      const std::string what =
          "session " + ses.name + " " + kind + " edge " + std::to_string(e.from) + "-" + std::to_string(e.to);
      const Matrix6d info = EdgeInformation(e, g_.cfg, own_information);
      auto* cost = new ceres::AutoDiffCostFunction<detail::BetweenFactor, 6, 7, 7>(
          new detail::BetweenFactor(e.T_from_to, SqrtInformation(info, what)));
      problem_.AddResidualBlock(cost, nullptr, nodes_[s][a].data(), nodes_[s][b].data());
    }
  }

  // Registered steps hold the heading far more stiffly than the odometry's per-step information
  // holds roll and pitch: a few hundredths of a degree that steps and loops disagree in heading
  // then escape into tilt, where roll and pitch of ~2 deg along a stretch turn the heading by their
  // product (the demo's sessions tilted 3.6 deg, key off 0.02). Each keyframe's vertical is held
  // where the inertial odometry put it (GravityFactor), at the tilt sigma its edges state
  // (TiltVariances), which for a tilt held to gravity does not add up along the session.
  void AddGravity(std::size_t s) {
    const Session& ses = g_.sessions[s];
    const std::vector<double> tilt = TiltVariances(ses);
    for (std::size_t k = 0; k < ses.keyframes.size(); ++k) {
      auto* cost = new ceres::AutoDiffCostFunction<detail::GravityFactor, 3, 7>(
          new detail::GravityFactor{Up(ses.keyframes[k]), 1.0 / std::sqrt(tilt[k])});
      problem_.AddResidualBlock(cost, nullptr, nodes_[s][k].data());
    }
  }

  // Per keyframe, the variance of roll or pitch (the coarser) that the odometry states of the edge
  // into it (into keyframe 1 for keyframe 0), as the graph reads its information (EdgeInformation).
  std::vector<double> TiltVariances(const Session& ses) const {
    const std::size_t n = ses.keyframes.size();
    const auto tilt = [&](const Edge& e, const Keyframe& kf) {
      const Eigen::Vector3d up = Up(kf).normalized();
      const Eigen::Vector3d x = up.unitOrthogonal(), y = up.cross(x);
      return std::max(TurnVariance(e, x, g_.cfg, false), TurnVariance(e, y, g_.cfg, false));
    };
    std::vector<double> var(n, tilt(Edge{}, n > 0 ? ses.keyframes[0] : Keyframe{}));
    ForEachStep(ses, ses.odometry, [&](std::size_t a, const Edge& e) {
      var[a + 1] = tilt(e, ses.keyframes[a + 1]);
      if (a == 0) var[0] = var[1];
    });
    return var;
  }

  const Graph& g_;
  std::vector<std::vector<Block>> nodes_;
  std::vector<Block> anchors_;
  ceres::Manifold* manifold_;  // owned by problem_ once a block uses it
  ceres::Problem problem_;
};

SolveStats Solve(Graph& g, const std::vector<LoopRecord>& loops, int threads) {
  GraphProblem problem(g);
  for (std::size_t s = 0; s < g.sessions.size(); ++s)
    if (g.aligned[s]) problem.AddSession(s);
  for (const LoopRecord& l : loops)
    if (l.accepted) problem.AddLoop(l);
  const SolveStats st = problem.Solve(threads);
  problem.WriteBack(g);
  return st;
}

// Residual of a loop under the current estimate: E = z^-1 (A_a x_a)^-1 (A_b x_b).
void LoopResidual(const Graph& g, LoopRecord& l) {
  const Pose wa = g.anchors[l.a.session] * g.poses[l.a.session][l.a.keyframe];
  const Pose wb = g.anchors[l.b.session] * g.poses[l.b.session][l.b.keyframe];
  const Pose E = l.T_a_b.inverse() * wa.inverse() * wb;
  l.residual_t_m = E.translation().norm();
  l.residual_r_deg = AngleDeg(E.linear());
}

// Support of the strongest rival placement: among the candidates that disagree with the chosen
// one (`best`, supported by `inliers`), the most that agree with one of them.
template <class C, class F>
std::size_t RivalSupport(const std::vector<C>& cand, std::size_t best,
                         const std::vector<std::size_t>& inliers, const F& consistent) {
  std::vector<bool> agrees(cand.size(), false);
  for (std::size_t j : inliers) agrees[j] = true;
  std::size_t rival = 0;
  for (std::size_t i = 0; i < cand.size(); ++i) {
    if (agrees[i] || consistent(cand[best], cand[i])) continue;
    std::size_t support = 0;
    for (std::size_t j = 0; j < cand.size(); ++j) {
      support += (!agrees[j] && consistent(cand[i], cand[j])) ? 1 : 0;
    }
    rival = std::max(rival, support);
  }
  return rival;
}

}  // namespace

double AngleDeg(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle() / kDeg; }

bool PlacementsAgree(const Pose& A, const Pose& B, double travelled_m, const SlamConfig& cfg) {
  const double tol_t = cfg.consensus_t_m + cfg.consensus_drift_ratio * travelled_m;
  return (A.translation() - B.translation()).norm() <= tol_t && AngleDeg(A.linear().transpose() * B.linear()) <= cfg.consensus_r_deg;
}

void ValidateSessionGraphs(const std::vector<Session>& sessions) {
  if (sessions.empty()) throw Error("slam: no sessions given");
  for (const Session& s : sessions) {
    const std::string where = s.dir.empty() ? "session " + s.name : s.dir;
    if (s.keyframes.empty()) throw Error(where + ": session has no keyframes");
    for (const auto* edges : {&s.odometry, &s.loops, &s.registered}) {
      for (const Edge& e : *edges) {
        if (s.Find(e.from) < 0 || s.Find(e.to) < 0) {
          throw Error(where + ": broken pose graph: edge " + std::to_string(e.from) + " -> " +
                      std::to_string(e.to) + " refers to a keyframe that does not exist");
        }
        if (!e.T_from_to.matrix().allFinite() || !e.information.allFinite()) {
          throw Error(where + ": broken pose graph: edge " + std::to_string(e.from) + " -> " +
                      std::to_string(e.to) + " has non-finite values");
        }
      }
    }
    for (const Keyframe& kf : s.keyframes) {
      if (!kf.T_session_sensor.matrix().allFinite()) {
        throw Error(where + ": keyframe " + std::to_string(kf.index) + " has a non-finite pose");
      }
    }
  }
}

std::vector<double> PathLength(const std::vector<Pose>& poses) {
  std::vector<double> cum(poses.size(), 0.0);
  for (std::size_t i = 1; i < poses.size(); ++i) {
    cum[i] = cum[i - 1] + (poses[i].translation() - poses[i - 1].translation()).norm();
  }
  return cum;
}

std::vector<double> PathLength(const Session& session) {
  std::vector<Pose> poses;
  for (const Keyframe& kf : session.keyframes) poses.push_back(kf.T_session_sensor);
  return PathLength(poses);
}

Matrix6d DiagInformation(double sigma_t, double sigma_r) {
  Matrix6d info = Matrix6d::Zero();
  info.diagonal() << Eigen::Vector3d::Constant(1.0 / (sigma_t * sigma_t)),
      Eigen::Vector3d::Constant(1.0 / (sigma_r * sigma_r));
  return info;
}

namespace {
// A prior this far below the odometry's information keeps a heading's information invertible.
constexpr double kNegligiblePrior = 1e-6;
Matrix6d NegligiblePrior(const SlamConfig& cfg) {
  return kNegligiblePrior * DiagInformation(cfg.odom_sigma_t_m, cfg.odom_sigma_r_deg * kDeg);
}
// The turn about `up` as a direction of the pose graph's residual (x y z rx ry rz).
Eigen::Matrix<double, 6, 1> TurnDirection(const Eigen::Vector3d& up) {
  Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
  g.tail<3>() = up.normalized();
  return g;
}
}  // namespace

// The variance of the turn about `up` (g^T r, g = (0, up)) that a registration's Fisher information
// `fisher` implies (pose graph order x y z rx ry rz, source frame): g^T F^-1 g, F the Fisher
// information plus a prior far below the odometry's (kNegligiblePrior of it), so that it inverts
// where the surfaces leave a direction unconstrained.
double HeadingVariance(const Matrix6d& fisher, const Eigen::Vector3d& up, const SlamConfig& cfg) {
  const Matrix6d F = 0.5 * (fisher + fisher.transpose()) + NegligiblePrior(cfg);
  const Eigen::Matrix<double, 6, 1> g = TurnDirection(up);
  return g.dot(F.ldlt().solve(g));
}

Eigen::Matrix3d TranslationCovariance(const Matrix6d& fisher, const SlamConfig& cfg) {
  const Matrix6d F = 0.5 * (fisher + fisher.transpose()) + NegligiblePrior(cfg);
  Eigen::Matrix<double, 6, 3> P = Eigen::Matrix<double, 6, 3>::Zero();
  P.topRows<3>().setIdentity();
  return P.transpose() * F.ldlt().solve(P);
}

Eigen::Matrix<double, 3, 2> Horizontal(const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = up.normalized(), x = z.unitOrthogonal();
  Eigen::Matrix<double, 3, 2> H;
  H << x, z.cross(x);
  return H;
}

Matrix6d HorizontalInformation(const Eigen::Matrix2d& horizontal, const Eigen::Vector3d& up) {
  Eigen::Matrix<double, 6, 2> G = Eigen::Matrix<double, 6, 2>::Zero();
  G.topRows<3>() = Horizontal(up);
  return G * horizontal.inverse() * G.transpose();
}

// The information of a registered step or loop on the turn about the vertical alone: g g^T /
// variance, plus the same negligible prior so that it inverts. A step measures the heading change
// far better than an odometry integrates it (the heading is what drifts; inertial odometry holds
// roll and pitch to gravity). Registered with the ground, the ground's rings, which move with the
// sensor, biased its other directions (on the default scene -0.24 and -0.37 % of the step along
// the road, -0.003 deg of pitch a step); registered off it (OffTheGround), nothing holds height,
// roll and pitch, while its horizontal translation may join (HorizontalInformation, docs/RESULTS.md:
// "Registered steps hold the horizontal translation").
Matrix6d HeadingInformation(double variance, const Eigen::Vector3d& up, const SlamConfig& cfg) {
  const Eigen::Matrix<double, 6, 1> g = TurnDirection(up);
  return g * g.transpose() / variance + NegligiblePrior(cfg);
}

Eigen::Vector3d Up(const Keyframe& kf) { return kf.T_session_sensor.linear().transpose() * Eigen::Vector3d::UnitZ(); }

double TurnAbout(const Pose& a, const Pose& b, const Eigen::Vector3d& up) {
  const Eigen::AngleAxisd e(a.linear().transpose() * b.linear());
  return e.angle() * e.axis().dot(up.normalized());
}

double TurnVariance(const Edge& e, const Eigen::Vector3d& up, const SlamConfig& cfg, bool own_information) {
  const Eigen::Matrix<double, 6, 1> g = TurnDirection(up);
  return 1.0 / g.dot(EdgeInformation(e, cfg, own_information) * g);
}

double StatedHorizontalVariance(const Edge& e, const Eigen::Vector3d& up, const SlamConfig& cfg, bool own_information) {
  const Matrix6d info = EdgeInformation(e, cfg, own_information);
  const Eigen::Matrix3d C = info.ldlt().solve(Matrix6d::Identity()).topLeftCorner<3, 3>();
  const Eigen::Matrix<double, 3, 2> H = Horizontal(up);
  return 0.5 * (H.transpose() * C * H).trace();
}

bool SquaresWithin(double sum_sq, std::size_t n, double variance) {
  constexpr double kZ = 3.09;  // the standard normal's 0.999 quantile
  if (n == 0) return true;
  const double dof = double(n), a = 2.0 / (9.0 * dof);
  return sum_sq <= variance * dof * std::pow(1.0 - a + kZ * std::sqrt(a), 3);  // Wilson-Hilferty
}

double VarianceScale(std::vector<double> ratio) {
  if (ratio.empty()) return 1.0;
  const double median = UpperMedian(ratio);
  return median > 0.0 ? median / kChiSquare1Median : 1.0;
}

namespace {

// The edges a loops' cycle runs through in one session: per keyframe position k, the edge from k to
// k + 1 (the finer in heading of its registered step and its odometry edge), the variance of its
// turn about the vertical [rad^2] (infinite without an edge), and whether it is a registered step
// that holds the horizontal translation (finer than the config's odometry).
struct CycleEdges {
  std::vector<Pose> T;
  std::vector<double> var;
  std::vector<bool> holds;
};
CycleEdges EdgesOf(const Session& s, const SlamConfig& cfg) {
  const std::size_t n = s.keyframes.empty() ? 0 : s.keyframes.size() - 1;
  CycleEdges c{std::vector<Pose>(n, Pose::Identity()), std::vector<double>(n, std::numeric_limits<double>::infinity()),
               std::vector<bool>(n, false)};
  const double odometry = StatedHorizontalVariance(Edge{}, Eigen::Vector3d::UnitZ(), cfg);
  const auto put = [&](const std::vector<Edge>& edges, bool own_information) {
    ForEachStep(s, edges, [&](std::size_t a, const Edge& e) {
      const Eigen::Vector3d up = Up(s.keyframes[a + 1]);
      const double var = TurnVariance(e, up, cfg, own_information);
      if (var >= c.var[a]) return;
      c.T[a] = e.T_from_to, c.var[a] = var;
      c.holds[a] = own_information && StatedHorizontalVariance(e, up, cfg, true) < odometry;
    });
  };
  put(s.odometry, false);
  put(s.registered, true);
  return c;
}

// The pose of keyframe position j in the frame of position i through the edges, the variance of
// its turn (their sum), and whether every edge holds the translation; false where an edge is missing.
struct Path {
  Pose T = Pose::Identity();
  double var = 0.0;
  bool holds = true;
};
bool Through(const CycleEdges& c, int i, int j, Path* p) {
  *p = Path{};
  for (int k = std::min(i, j); k < std::max(i, j); ++k) {
    if (!std::isfinite(c.var[std::size_t(k)])) return false;
    p->T = p->T * c.T[std::size_t(k)];
    p->var += c.var[std::size_t(k)];
    p->holds = p->holds && c.holds[std::size_t(k)];
  }
  if (j < i) p->T = p->T.inverse();
  return true;
}

// Calls f(l1, l2, A, B) for each two verified loops between the same sessions next to each other
// along the first session's route that `use` takes, A and B the paths between their keyframes
// in the first and the second session. Two loops between the same two keyframes (a place cloud's
// and a scan's) close no cycle: their gap is two registrations of one pair, not the loops' error.
void ForEachCycle(const std::vector<Session>& sessions, const std::vector<LoopRecord>& loops, const SlamConfig& cfg,
                  const std::function<bool(const LoopRecord&)>& use,
                  const std::function<void(const LoopRecord&, const LoopRecord&, const Path&, const Path&)>& f) {
  std::vector<const LoopRecord*> ls;
  for (const LoopRecord& l : loops)
    if (l.verified && !OwnLoop(l) && use(l)) ls.push_back(&l);
  const auto key = [](const LoopRecord* l) { return std::tie(l->a.session, l->b.session, l->a.keyframe, l->b.keyframe); };
  std::sort(ls.begin(), ls.end(), [&](const LoopRecord* x, const LoopRecord* y) { return key(x) < key(y); });
  std::vector<CycleEdges> edges;
  for (const Session& s : sessions) edges.push_back(EdgesOf(s, cfg));
  for (std::size_t i = 1; i < ls.size(); ++i) {
    const LoopRecord &l1 = *ls[i - 1], &l2 = *ls[i];
    if (l1.a.session != l2.a.session || l1.b.session != l2.b.session) continue;
    if (l1.a.keyframe == l2.a.keyframe && l1.b.keyframe == l2.b.keyframe) continue;
    Path A, B;
    if (Through(edges[std::size_t(l1.a.session)], l1.a.keyframe, l2.a.keyframe, &A) &&
        Through(edges[std::size_t(l1.b.session)], l1.b.keyframe, l2.b.keyframe, &B))
      f(l1, l2, A, B);
  }
}

// The scale from the cycles' ratios: the median ratio is positive where more than half are; else
// the loops' errors lie within what the edges' variance hides (the odometry's, where a session has
// no steps), and the cycles do not measure them: none, as without a cycle.
LoopCycleScale ScaleOf(std::vector<double> ratio, int cycles) {
  LoopCycleScale out;
  const auto positive = std::count_if(ratio.begin(), ratio.end(), [](double r) { return r > 0.0; });
  if (2 * std::size_t(positive) <= ratio.size()) return out;
  out.cycles = cycles;
  out.scale = VarianceScale(std::move(ratio));
  return out;
}

// The horizontal variance per axis of a translation covariance C (3 x 3) in the frame of `up`.
double PerAxis(const Eigen::Matrix3d& C, const Eigen::Vector3d& up) {
  const Eigen::Matrix<double, 3, 2> H = Horizontal(up);
  return 0.5 * (H.transpose() * C * H).trace();
}
}  // namespace

LoopCycleScale LoopHeadingScale(const std::vector<Session>& sessions, const std::vector<LoopRecord>& loops,
                                const SlamConfig& cfg) {
  std::vector<double> ratio;
  ForEachCycle(
      sessions, loops, cfg, [](const LoopRecord& l) { return l.heading_variance > 0.0; },
      [&](const LoopRecord& l1, const LoopRecord& l2, const Path& A, const Path& B) {
        const double v = l1.heading_variance + l2.heading_variance;
        if (A.var + B.var >= v) return;  // the cycle would measure the edges, not the loops
        // Both T1 B and A T2 map keyframe b2 into keyframe a1.
        const Keyframe& b2 = sessions[std::size_t(l2.b.session)].keyframes[std::size_t(l2.b.keyframe)];
        const double c = TurnAbout(A.T * l2.T_a_b, l1.T_a_b * B.T, Up(b2));
        ratio.push_back((c * c - A.var - B.var) / v);
      });
  const int cycles = int(ratio.size());
  return ScaleOf(std::move(ratio), cycles);
}

LoopCycleScale LoopTranslationScale(const std::vector<Session>& sessions, const std::vector<LoopRecord>& loops,
                                    const SlamConfig& cfg) {
  std::vector<double> ratio;
  int cycles = 0;
  ForEachCycle(
      sessions, loops, cfg, [](const LoopRecord& l) { return !l.translation_covariance.isZero(); },
      [&](const LoopRecord& l1, const LoopRecord& l2, const Path& A, const Path& B) {
        // A cycle through the odometry measures the odometry. Both T1 B and A T2 map keyframe b2
        // into keyframe a1; each loop's covariance (its source frame, keyframe b) turned into a1's.
        // The whole gap is laid on the loops: the steps' Fisher variance overstates their error
        // (their closures show 0.05-0.11 x of it), and whatever share is theirs makes the loops
        // looser, never finer, than they are.
        if (!A.holds || !B.holds) return;
        const Pose one = l1.T_a_b * B.T, two = A.T * l2.T_a_b;
        const Eigen::Vector3d up = Up(sessions[std::size_t(l1.a.session)].keyframes[std::size_t(l1.a.keyframe)]);
        const Eigen::Matrix3d R1 = l1.T_a_b.linear(), R2 = two.linear();
        const double v = PerAxis(R1 * l1.translation_covariance * R1.transpose(), up) +
                         PerAxis(R2 * l2.translation_covariance * R2.transpose(), up);
        const Eigen::Vector2d d = Horizontal(up).transpose() * (one.translation() - two.translation());
        for (int i = 0; i < 2; ++i) ratio.push_back(d[i] * d[i] / v);
        ++cycles;
      });
  return ScaleOf(std::move(ratio), cycles);
}

Matrix6d LoopInformation(double fitness, const Matrix6d& fisher, const SlamConfig& cfg) {
  // Paper: the ICP fitness score gives an adaptive covariance. Sigma is the configured value at
  // (or below) the fitness floor and grows with sqrt(fitness / floor) above it.
  const double scale = std::sqrt(std::max(fitness, cfg.reg_fitness_floor) / cfg.reg_fitness_floor);
  const Matrix6d D = DiagInformation(cfg.loop_sigma_t_m * scale, cfg.loop_sigma_r_deg * kDeg * scale);
  if (fisher.isZero()) return D;
  // The registration's own uncertainty adds to it: covariance D^-1 + F^-1, whose inverse is
  // D - D (D + F)^-1 D (Woodbury; defined for a singular F too). Where the surfaces constrain the
  // pose, F^-1 is far below D^-1 and the fitness term rules; along an unconstrained direction
  // (a straight street's axis) F is small and so is the loop's information.
  const Matrix6d info = D - D * (D + fisher).ldlt().solve(D);
  return 0.5 * (info + info.transpose());
}

namespace {
void CheckLoops(const std::vector<Session>& sessions, std::vector<LoopRecord>& loops) {
  const std::size_t n = sessions.size();
  for (auto& l : loops) {
    if (l.a.session < 0 || l.b.session < 0 || l.a.session >= int(n) || l.b.session >= int(n) ||
        (OwnLoop(l) && l.a.keyframe == l.b.keyframe) || l.a.keyframe < 0 || l.b.keyframe < 0 ||
        l.a.keyframe >= int(sessions[l.a.session].keyframes.size()) ||
        l.b.keyframe >= int(sessions[l.b.session].keyframes.size())) {
      throw Error("slam: loop refers to a missing session or keyframe");
    }
    l.accepted = false;
    if (l.verified) l.status = "pending";
  }
}

// The anchor of session s a verified loop to an already-anchored session t implies, with the
// path positions of the loop's keyframes in s and in t.
struct Implied {
  std::size_t loop;
  Pose A;
  double pos_s, pos_t;
  int t;
};

std::vector<Implied> ImpliedAnchors(const Graph& g, const std::vector<LoopRecord>& loops,
                                    const std::vector<std::vector<double>>& path, std::size_t s) {
  std::vector<Implied> cand;
  for (std::size_t i = 0; i < loops.size(); ++i) {
    const LoopRecord& l = loops[i];
    if (!l.verified || OwnLoop(l)) continue;  // a loop within a session implies no anchor
    const Pose& z = l.T_a_b;
    if (l.b.session == int(s) && g.aligned[l.a.session]) {
      const Pose& xa = g.poses[l.a.session][l.a.keyframe];
      const Pose& xb = g.poses[s][l.b.keyframe];
      cand.push_back({i, g.anchors[l.a.session] * xa * z * xb.inverse(), path[s][l.b.keyframe],
                      path[l.a.session][l.a.keyframe], l.a.session});
    } else if (l.a.session == int(s) && g.aligned[l.b.session]) {
      const Pose& xa = g.poses[s][l.a.keyframe];
      const Pose& xb = g.poses[l.b.session][l.b.keyframe];
      cand.push_back({i, g.anchors[l.b.session] * xb * z.inverse() * xa.inverse(), path[s][l.a.keyframe],
                      path[l.b.session][l.b.keyframe], l.b.session});
    }
  }
  return cand;
}

// The implied anchor that agrees with the most others (within a tolerance growing with the
// path between the loops, since odometry drifts; ties: the lowest summed fitness) and its group.
std::size_t Consensus(const std::vector<Implied>& cand, const std::vector<LoopRecord>& loops,
                      const std::function<bool(const Implied&, const Implied&)>& consistent,
                      std::vector<std::size_t>* best_inliers) {
  std::size_t best = 0;
  double best_fit = 1e300;
  for (std::size_t i = 0; i < cand.size(); ++i) {
    std::vector<std::size_t> in;
    double fit = 0;
    for (std::size_t j = 0; j < cand.size(); ++j) {
      if (!consistent(cand[i], cand[j])) continue;
      in.push_back(j);
      fit += loops[cand[j].loop].fitness;
    }
    if (in.size() > best_inliers->size() || (in.size() == best_inliers->size() && fit < best_fit)) {
      best = i;
      *best_inliers = in;
      best_fit = fit;
    }
  }
  return best;
}

// Anchors query s from its loops to anchored sessions (false with the reason when the evidence
// is short or ambiguous); its loops in the consensus are accepted, the others gated.
bool AnchorSession(Graph& g, std::vector<LoopRecord>& loops, const std::vector<std::vector<double>>& path,
                   std::size_t s, std::string* reason) {
  const SlamConfig& cfg = g.cfg;
  const std::vector<Implied> cand = ImpliedAnchors(g, loops, path, s);
  if (cand.empty()) {
    *reason = "no verified inter-session loop to an aligned session";
    return false;
  }
  const std::function<bool(const Implied&, const Implied&)> consistent = [&](const Implied& x, const Implied& y) {
    const double travelled = std::abs(x.pos_s - y.pos_s) + (x.t == y.t ? std::abs(x.pos_t - y.pos_t) : 0.0);
    return PlacementsAgree(x.A, y.A, travelled, cfg);
  };
  std::vector<std::size_t> inliers;
  const std::size_t best = Consensus(cand, loops, consistent, &inliers);
  std::ostringstream os;
  if (int(inliers.size()) < cfg.min_loops) {
    os << "only " << inliers.size() << " mutually consistent verified loop(s) of " << cand.size()
       << " (need graph.min_loops = " << cfg.min_loops << ")";
    *reason = os.str();
    return false;
  }
  // Ambiguity (repetitive places): the largest group of loops that disagrees with the chosen
  // anchor is a rival placement. The chosen one must lead it by graph.min_loops loops, the
  // evidence asked of any placement at all; otherwise wait for more loops (retry).
  const std::size_t rival = RivalSupport(cand, best, inliers, consistent);
  if (int(inliers.size()) < int(rival) + cfg.min_loops) {
    os << "ambiguous: " << inliers.size() << " consistent verified loop(s) against a rival placement with " << rival
       << " (need a lead of graph.min_loops = " << cfg.min_loops << ")";
    *reason = os.str();
    return false;
  }
  g.aligned[s] = true;
  g.anchors[s] = cand[best].A;
  std::vector<bool> in(cand.size(), false);
  for (std::size_t j : inliers) in[j] = true;
  for (std::size_t j = 0; j < cand.size(); ++j) {
    LoopRecord& l = loops[cand[j].loop];
    l.accepted = in[j] || !cfg.gate_inconsistent_loops;
    l.status = l.accepted ? "accepted" : "rejected: implied anchor inconsistent with the consensus";
  }
  return true;
}

// Anchor initialisation: the anchor of a query is unknown (any yaw, any offset), so it is taken
// from the loops themselves; sessions reachable only through other queries are anchored in
// later passes. Loops between two aligned sessions that were not part of any consensus (e.g.
// query-query loops once both are anchored) are then checked against the initial anchors.
void InitialiseAnchors(Graph& g, std::vector<LoopRecord>& loops, const std::vector<std::vector<double>>& path,
                       std::vector<std::string>& reason) {
  for (bool progress = true; progress;) {
    progress = false;
    for (std::size_t s = 1; s < g.sessions.size(); ++s)
      if (!g.aligned[s] && AnchorSession(g, loops, path, s, &reason[s])) progress = true;
  }
  for (auto& l : loops) {
    if (!l.verified || l.status != "pending") continue;
    if (!g.aligned[l.a.session] || !g.aligned[l.b.session]) {
      l.status = "rejected: session not aligned";
      continue;
    }
    LoopResidual(g, l);
    if (!g.cfg.gate_inconsistent_loops ||
        (l.residual_t_m <= g.cfg.consensus_t_m && l.residual_r_deg <= g.cfg.consensus_r_deg)) {
      l.accepted = true;
      l.status = "accepted";
    } else {
      l.status = "rejected: inconsistent with the initial anchors";
    }
  }
}

// After a solve: loops the optimum disagrees with are pruned, gated loops it agrees with
// re-admitted; true when the accepted set changed.
bool PruneLoops(const Graph& g, std::vector<LoopRecord>& loops) {
  bool changed = false;
  for (auto& l : loops) {
    if (!l.verified) continue;
    if (!g.aligned[l.a.session] || !g.aligned[l.b.session]) {
      changed |= l.accepted;
      l.accepted = false;
      l.status = "rejected: session not aligned";
      continue;
    }
    LoopResidual(g, l);
    const bool fits = l.residual_t_m <= g.cfg.outlier_t_m && l.residual_r_deg <= g.cfg.outlier_r_deg;
    if (l.accepted && !fits) {
      l.accepted = false;
      std::ostringstream os;
      os.precision(3);
      os << "rejected: outlier after optimisation (residual " << l.residual_t_m << " m, " << l.residual_r_deg
         << " deg)";
      l.status = os.str();
      changed = true;
    } else if (!l.accepted && fits && g.cfg.gate_inconsistent_loops) {
      l.accepted = true;
      l.status = "accepted";
      changed = true;
    }
  }
  return changed;
}

// A query left with too few accepted loops is no longer aligned, and its loops (its own ones too)
// no longer accepted: the next solve holds no poses of it; true when one was dropped.
bool DropUnderconstrained(Graph& g, std::vector<LoopRecord>& loops, std::vector<std::string>& reason) {
  bool changed = false;
  for (std::size_t s = 1; s < g.sessions.size(); ++s) {
    if (!g.aligned[s]) continue;
    int count = 0;
    for (const auto& l : loops)
      if (l.accepted && !OwnLoop(l) && (l.a.session == int(s) || l.b.session == int(s))) ++count;
    if (count >= g.cfg.min_loops) continue;
    g.aligned[s] = false;
    reason[s] = "only " + std::to_string(count) + " loop(s) left after outlier rejection (need graph.min_loops = " +
                std::to_string(g.cfg.min_loops) + ")";
    for (auto& l : loops)
      if (l.accepted && (l.a.session == int(s) || l.b.session == int(s)))
        l.accepted = false, l.status = "rejected: session not aligned";
    changed = true;
  }
  return changed;
}

SlamResult MakeResult(const Graph& g, const std::vector<LoopRecord>& loops, const std::vector<std::string>& reason,
                      const SolveStats& st) {
  SlamResult res;
  res.sessions.resize(g.sessions.size());
  res.solution_usable = st.usable;
  res.initial_cost = st.initial_cost;
  res.final_cost = st.final_cost;
  res.solver_iterations = st.iterations;
  for (std::size_t s = 0; s < g.sessions.size(); ++s) {
    SessionAlignment& a = res.sessions[s];
    a.name = g.sessions[s].name;
    a.aligned = g.aligned[s];
    a.reason = g.aligned[s] ? "" : reason[s];
    a.T_session_sensor = g.poses[s];
    a.anchor = a.aligned ? g.anchors[s] : Pose::Identity();
    if (a.aligned)
      for (const Pose& T : g.poses[s]) a.T_world_sensor.push_back(g.anchors[s] * T);
  }
  // Per session also the RMS residual rotation of the accepted loops whose later side it is.
  std::vector<double> sum_sq(res.sessions.size(), 0.0);
  std::vector<std::size_t> n(res.sessions.size(), 0);
  for (const auto& l : loops) {
    if (OwnLoop(l)) {  // no part of the sessions' alignment nor of their rotation uncertainty
      if (l.accepted) ++res.sessions[std::size_t(l.a.session)].own_loops;
      continue;
    }
    for (int s : {l.a.session, l.b.session}) {
      SessionAlignment& a = res.sessions[s];
      if (l.source == "sc") ++a.sc_candidates;
      if (l.verified) ++a.loops_verified;
      if (l.accepted) ++a.loops_accepted;
      if (l.accepted && l.source == "radius") ++a.radius_loops;
    }
    if (l.accepted && l.residual_r_deg >= 0.0) {
      sum_sq[std::size_t(l.b.session)] += l.residual_r_deg * l.residual_r_deg;
      ++n[std::size_t(l.b.session)];
    }
  }
  for (std::size_t s = 0; s < n.size(); ++s)
    if (n[s]) res.sessions[s].rotation_sigma_deg = std::sqrt(sum_sq[s] / double(n[s]));
  res.loops = loops;
  res.heading_cycles = g.heading.cycles;
  res.loop_heading_scale = g.heading.scale;
  res.translation_cycles = g.translation.cycles;
  res.loop_translation_scale = g.translation.scale;
  return res;
}
}  // namespace

SlamResult OptimizeSessions(const std::vector<Session>& sessions, std::vector<LoopRecord>& loops,
                            const SlamConfig& cfg, int threads) {
  ValidateConfig(cfg, "slam config");
  ValidateSessionGraphs(sessions);
  const std::size_t n = sessions.size();
  Graph g{sessions, cfg, std::vector<std::vector<Pose>>(n), std::vector<Pose>(n, Pose::Identity()),
          std::vector<bool>(n, false), LoopCycleScale{}, LoopCycleScale{}};
  std::vector<std::vector<double>> path(n);
  for (std::size_t s = 0; s < n; ++s) {
    for (const Keyframe& kf : sessions[s].keyframes) g.poses[s].push_back(kf.T_session_sensor);
    path[s] = PathLength(g.poses[s]);
  }
  CheckLoops(sessions, loops);
  g.heading = LoopHeadingScale(sessions, loops, cfg);
  g.translation = LoopTranslationScale(sessions, loops, cfg);
  std::vector<std::string> reason(n);
  g.aligned[0] = true;
  InitialiseAnchors(g, loops, path, reason);
  // Optimise; prune and re-admit loops until the accepted set is stable.
  SolveStats st;
  for (int pass = 0; pass < 5; ++pass) {
    st = Solve(g, loops, threads);
    const bool pruned = PruneLoops(g, loops);
    if (!DropUnderconstrained(g, loops, reason) && !pruned) break;
  }
  return MakeResult(g, loops, reason, st);
}

}  // namespace ltm::slam
