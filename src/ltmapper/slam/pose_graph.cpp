// LT-SLAM back end: anchor initialisation from verified loops, consistency gating, Ceres pose
// graph with anchor nodes and robust inter-session factors, outlier pruning.
#include "ltmapper/slam/factors.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

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

Matrix6d DiagInformation(double sigma_t, double sigma_r) {
  Matrix6d info = Matrix6d::Zero();
  info.diagonal() << Eigen::Vector3d::Constant(1.0 / (sigma_t * sigma_t)),
      Eigen::Vector3d::Constant(1.0 / (sigma_r * sigma_r));
  return info;
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

double AngleDeg(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle() / kDeg;
}

// Cumulative path length along each session's keyframes (for drift-aware tolerances).
std::vector<double> PathLength(const std::vector<Pose>& poses) {
  std::vector<double> cum(poses.size(), 0.0);
  for (std::size_t i = 1; i < poses.size(); ++i) {
    cum[i] = cum[i - 1] + (poses[i].translation() - poses[i - 1].translation()).norm();
  }
  return cum;
}

struct Graph {
  const std::vector<Session>& sessions;
  const SlamConfig& cfg;
  std::vector<std::vector<Pose>> poses;  // current estimate, session frame
  std::vector<Pose> anchors;
  std::vector<bool> aligned;
};

struct SolveStats {
  bool usable = true;
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
};

SolveStats Solve(Graph& g, const std::vector<LoopRecord>& loops, int threads) {
  const std::size_t n = g.sessions.size();
  std::vector<std::vector<Block>> nodes(n);
  std::vector<Block> anchors(n);
  for (std::size_t s = 0; s < n; ++s) {
    if (!g.aligned[s]) continue;
    for (const Pose& T : g.poses[s]) nodes[s].push_back(ToBlock(T));
    anchors[s] = ToBlock(g.anchors[s]);
  }
  ceres::Problem problem;
  auto* manifold =
      new ceres::ProductManifold<ceres::EuclideanManifold<3>, ceres::EigenQuaternionManifold>();
  auto add_block = [&](double* b) {
    if (!problem.HasParameterBlock(b)) problem.AddParameterBlock(b, 7, manifold);
  };
  for (std::size_t s = 0; s < n; ++s) {
    if (!g.aligned[s]) continue;
    const Session& ses = g.sessions[s];
    for (auto& b : nodes[s]) add_block(b.data());
    // Gauge: a session's frame is only defined up to a rigid motion (its anchor and all its
    // poses can move together without changing any residual). Fixing its first pose at the
    // odometry value removes that freedom; the anchor then carries the session's placement.
    problem.SetParameterBlockConstant(nodes[s][0].data());
    auto add_edges = [&](const std::vector<Edge>& edges, const char* kind) {
      for (const Edge& e : edges) {
        const int a = ses.Find(e.from), b = ses.Find(e.to);
        const std::string what = "session " + ses.name + " " + kind + " edge " +
                                 std::to_string(e.from) + "-" + std::to_string(e.to);
        const Matrix6d info = (g.cfg.use_g2o_information && e.has_information)
                                  ? e.information
                                  : DiagInformation(g.cfg.odom_sigma_t_m,
                                                    g.cfg.odom_sigma_r_deg * kDeg);
        auto* cost = new ceres::AutoDiffCostFunction<detail::BetweenFactor, 6, 7, 7>(
            new detail::BetweenFactor(e.T_from_to, SqrtInformation(info, what)));
        problem.AddResidualBlock(cost, nullptr, nodes[s][a].data(), nodes[s][b].data());
      }
    };
    add_edges(ses.odometry, "odometry");
    add_edges(ses.loops, "loop");
  }
  for (const LoopRecord& l : loops) {
    if (!l.accepted) continue;
    const int sa = l.a.session, sb = l.b.session;
    double* A = anchors[sa].data();
    double* B = anchors[sb].data();
    add_block(A);
    add_block(B);
    auto* cost = new ceres::AutoDiffCostFunction<detail::AnchorLoopFactor, 6, 7, 7, 7, 7>(
        new detail::AnchorLoopFactor(l.T_a_b, SqrtInformation(l.information, "inter-session loop")));
    problem.AddResidualBlock(cost, MakeLoss(g.cfg), A, nodes[sa][l.a.keyframe].data(), B,
                             nodes[sb][l.b.keyframe].data());
  }
  // The central session's anchor is the world frame: constant (the paper gives it a tiny
  // covariance; constant is the limit). Query anchors are free.
  if (problem.HasParameterBlock(anchors[0].data())) {
    problem.SetParameterBlockConstant(anchors[0].data());
  }

  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  opt.max_num_iterations = g.cfg.solver_max_iterations;
  opt.num_threads = threads > 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  opt.minimizer_progress_to_stdout = false;
  opt.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(opt, &problem, &summary);
  SolveStats st;
  st.usable = summary.IsSolutionUsable();
  st.initial_cost = summary.initial_cost;
  st.final_cost = summary.final_cost;
  st.iterations = static_cast<int>(summary.iterations.size());
  if (!st.usable) {
    throw Error("pose graph optimisation failed: " + summary.message);
  }
  for (std::size_t s = 0; s < n; ++s) {
    if (!g.aligned[s]) continue;
    for (std::size_t k = 0; k < nodes[s].size(); ++k) g.poses[s][k] = FromBlock(nodes[s][k]);
    g.anchors[s] = FromBlock(anchors[s]);
  }
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

void ValidateSessionGraphs(const std::vector<Session>& sessions) {
  if (sessions.empty()) throw Error("slam: no sessions given");
  for (const Session& s : sessions) {
    const std::string where = s.dir.empty() ? "session " + s.name : s.dir;
    if (s.keyframes.empty()) throw Error(where + ": session has no keyframes");
    for (const auto* edges : {&s.odometry, &s.loops}) {
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

Matrix6d LoopInformation(double fitness, const SlamConfig& cfg) {
  // Paper: the ICP fitness score gives an adaptive covariance. Sigma is the configured value at
  // (or below) the fitness floor and grows with sqrt(fitness / floor) above it.
  const double scale = std::sqrt(std::max(fitness, cfg.reg_fitness_floor) / cfg.reg_fitness_floor);
  return DiagInformation(cfg.loop_sigma_t_m * scale, cfg.loop_sigma_r_deg * kDeg * scale);
}

SlamResult OptimizeSessions(const std::vector<Session>& sessions, std::vector<LoopRecord>& loops,
                            const SlamConfig& cfg, int threads) {
  ValidateConfig(cfg, "slam config");
  ValidateSessionGraphs(sessions);
  const std::size_t n = sessions.size();
  Graph g{sessions, cfg, std::vector<std::vector<Pose>>(n), std::vector<Pose>(n, Pose::Identity()),
          std::vector<bool>(n, false)};
  std::vector<std::vector<double>> path(n);
  for (std::size_t s = 0; s < n; ++s) {
    for (const Keyframe& kf : sessions[s].keyframes) g.poses[s].push_back(kf.T_session_sensor);
    path[s] = PathLength(g.poses[s]);
  }
  for (auto& l : loops) {
    if (l.a.session < 0 || l.b.session < 0 || l.a.session >= int(n) || l.b.session >= int(n) ||
        l.a.session == l.b.session || l.a.keyframe < 0 || l.b.keyframe < 0 ||
        l.a.keyframe >= int(sessions[l.a.session].keyframes.size()) ||
        l.b.keyframe >= int(sessions[l.b.session].keyframes.size())) {
      throw Error("slam: inter-session loop refers to a missing session or keyframe");
    }
    l.accepted = false;
    if (l.verified) l.status = "pending";
  }

  SlamResult res;
  res.sessions.resize(n);
  std::vector<std::string> reason(n);
  g.aligned[0] = true;

  // ---- 1. Anchor initialisation: the anchor of a query is unknown (any yaw, any offset), so it
  // is taken from the loops themselves. Each verified loop to an already-anchored session t
  // implies A_s; the loop whose implied anchor agrees with the most others (within a tolerance
  // growing with the path between the loops, since odometry drifts) seeds A_s. Sessions reachable
  // only through other queries are anchored in later passes.
  for (bool progress = true; progress;) {
    progress = false;
    for (std::size_t s = 1; s < n; ++s) {
      if (g.aligned[s]) continue;
      struct Implied {
        std::size_t loop;
        Pose A;
        double pos_s, pos_t;  // path position of the loop's keyframes in s and in t
        int t;
      };
      std::vector<Implied> cand;
      for (std::size_t i = 0; i < loops.size(); ++i) {
        const LoopRecord& l = loops[i];
        if (!l.verified) continue;
        const Pose& z = l.T_a_b;
        if (l.b.session == int(s) && g.aligned[l.a.session]) {
          const Pose& xa = g.poses[l.a.session][l.a.keyframe];
          const Pose& xb = g.poses[s][l.b.keyframe];
          cand.push_back({i, g.anchors[l.a.session] * xa * z * xb.inverse(),
                          path[s][l.b.keyframe], path[l.a.session][l.a.keyframe], l.a.session});
        } else if (l.a.session == int(s) && g.aligned[l.b.session]) {
          const Pose& xa = g.poses[s][l.a.keyframe];
          const Pose& xb = g.poses[l.b.session][l.b.keyframe];
          cand.push_back({i, g.anchors[l.b.session] * xb * z.inverse() * xa.inverse(),
                          path[s][l.a.keyframe], path[l.b.session][l.b.keyframe], l.b.session});
        }
      }
      if (cand.empty()) {
        reason[s] = "no verified inter-session loop to an aligned session";
        continue;
      }
      auto consistent = [&](const Implied& x, const Implied& y) {
        const double travelled =
            std::abs(x.pos_s - y.pos_s) + (x.t == y.t ? std::abs(x.pos_t - y.pos_t) : 0.0);
        const double tol_t = cfg.consensus_t_m + cfg.consensus_drift_ratio * travelled;
        const double tol_r = cfg.consensus_r_deg;
        return (x.A.translation() - y.A.translation()).norm() <= tol_t &&
               AngleDeg(x.A.linear().transpose() * y.A.linear()) <= tol_r;
      };
      std::size_t best = 0;
      std::vector<std::size_t> best_inliers;
      double best_fit = 1e300;
      for (std::size_t i = 0; i < cand.size(); ++i) {
        std::vector<std::size_t> in;
        double fit = 0;
        for (std::size_t j = 0; j < cand.size(); ++j) {
          if (consistent(cand[i], cand[j])) {
            in.push_back(j);
            fit += loops[cand[j].loop].fitness;
          }
        }
        if (in.size() > best_inliers.size() || (in.size() == best_inliers.size() && fit < best_fit)) {
          best = i;
          best_inliers = in;
          best_fit = fit;
        }
      }
      if (int(best_inliers.size()) < cfg.min_loops) {
        std::ostringstream os;
        os << "only " << best_inliers.size() << " mutually consistent verified loop(s) of "
           << cand.size() << " (need graph.min_loops = " << cfg.min_loops << ")";
        reason[s] = os.str();
        continue;
      }
      // Ambiguity (repetitive places): the largest group of loops that disagrees with the chosen
      // anchor is a rival placement. The chosen one must lead it by graph.min_loops loops, the
      // evidence asked of any placement at all; otherwise wait for more loops (retry).
      const std::size_t rival = RivalSupport(cand, best, best_inliers, consistent);
      if (int(best_inliers.size()) < int(rival) + cfg.min_loops) {
        std::ostringstream os;
        os << "ambiguous: " << best_inliers.size()
           << " consistent verified loop(s) against a rival placement with " << rival
           << " (need a lead of graph.min_loops = " << cfg.min_loops << ")";
        reason[s] = os.str();
        continue;
      }
      g.aligned[s] = true;
      g.anchors[s] = cand[best].A;
      std::vector<bool> in(cand.size(), false);
      for (std::size_t j : best_inliers) in[j] = true;
      for (std::size_t j = 0; j < cand.size(); ++j) {
        LoopRecord& l = loops[cand[j].loop];
        if (in[j] || !cfg.gate_inconsistent_loops) {
          l.accepted = true;
          l.status = "accepted";
        } else {
          l.status = "rejected: implied anchor inconsistent with the consensus";
        }
      }
      progress = true;
    }
  }
  // Loops between two aligned sessions that were not part of any consensus (e.g. query-query
  // loops once both are anchored) are checked against the initial anchors.
  for (auto& l : loops) {
    if (!l.verified || l.status != "pending") continue;
    if (!g.aligned[l.a.session] || !g.aligned[l.b.session]) {
      l.status = "rejected: session not aligned";
      continue;
    }
    LoopResidual(g, l);
    if (!cfg.gate_inconsistent_loops ||
        (l.residual_t_m <= cfg.consensus_t_m && l.residual_r_deg <= cfg.consensus_r_deg)) {
      l.accepted = true;
      l.status = "accepted";
    } else {
      l.status = "rejected: inconsistent with the initial anchors";
    }
  }

  // ---- 2. Optimise; prune loops the optimum disagrees with, re-admit gated loops it agrees
  // with, until the accepted set is stable.
  SolveStats st;
  for (int pass = 0; pass < 5; ++pass) {
    st = Solve(g, loops, threads);
    bool changed = false;
    for (auto& l : loops) {
      if (!l.verified) continue;
      if (!g.aligned[l.a.session] || !g.aligned[l.b.session]) {
        if (l.accepted) changed = true;
        l.accepted = false;
        l.status = "rejected: session not aligned";
        continue;
      }
      LoopResidual(g, l);
      const bool fits = l.residual_t_m <= cfg.outlier_t_m && l.residual_r_deg <= cfg.outlier_r_deg;
      if (l.accepted && !fits) {
        l.accepted = false;
        std::ostringstream os;
        os.precision(3);
        os << "rejected: outlier after optimisation (residual " << l.residual_t_m << " m, "
           << l.residual_r_deg << " deg)";
        l.status = os.str();
        changed = true;
      } else if (!l.accepted && fits && cfg.gate_inconsistent_loops) {
        l.accepted = true;
        l.status = "accepted";
        changed = true;
      }
    }
    // A query left with too few accepted loops is no longer aligned.
    for (std::size_t s = 1; s < n; ++s) {
      if (!g.aligned[s]) continue;
      int count = 0;
      for (const auto& l : loops) {
        if (l.accepted && (l.a.session == int(s) || l.b.session == int(s))) ++count;
      }
      if (count < cfg.min_loops) {
        g.aligned[s] = false;
        reason[s] = "only " + std::to_string(count) +
                    " loop(s) left after outlier rejection (need graph.min_loops = " +
                    std::to_string(cfg.min_loops) + ")";
        changed = true;
      }
    }
    if (!changed) break;
  }

  res.solution_usable = st.usable;
  res.initial_cost = st.initial_cost;
  res.final_cost = st.final_cost;
  res.solver_iterations = st.iterations;
  for (std::size_t s = 0; s < n; ++s) {
    SessionAlignment& a = res.sessions[s];
    a.name = sessions[s].name;
    a.aligned = g.aligned[s];
    a.reason = g.aligned[s] ? "" : reason[s];
    a.T_session_sensor = g.poses[s];
    if (a.aligned) {
      a.anchor = g.anchors[s];
      for (const Pose& T : g.poses[s]) a.T_world_sensor.push_back(g.anchors[s] * T);
    } else {
      a.anchor = Pose::Identity();
    }
  }
  for (const auto& l : loops) {
    for (int s : {l.a.session, l.b.session}) {
      SessionAlignment& a = res.sessions[s];
      if (l.source == "sc") ++a.sc_candidates;
      if (l.verified) ++a.loops_verified;
      if (l.accepted) ++a.loops_accepted;
      if (l.accepted && l.source == "radius") ++a.radius_loops;
    }
  }
  res.loops = loops;
  return res;
}

}  // namespace ltm::slam
