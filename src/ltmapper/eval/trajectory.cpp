// Trajectory metrics: ATE after one rigid alignment, RPE, inter-session consistency.
#include "ltmapper/eval/trajectory.hpp"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>

namespace ltm::eval {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

double AngleDeg(const Eigen::Matrix3d& R) {
  // Angle of a rotation through its quaternion: accurate for small angles too.
  return Eigen::AngleAxisd(Eigen::Quaterniond(R).normalized()).angle() * kRadToDeg;
}

// Error of an estimated relative (or absolute) pose against the truth: E = T_truth^-1 T_est.
void AddError(const Pose& truth, const Pose& est, std::vector<double>* trans,
              std::vector<double>* rot) {
  const Pose E = truth.inverse() * est;
  trans->push_back(E.translation().norm());
  rot->push_back(AngleDeg(E.linear()));
}

PoseErrors MakeErrors(std::vector<double> trans, std::vector<double> rot) {
  PoseErrors e;
  e.trans_m = Stats(std::move(trans));
  e.rot_deg = Stats(std::move(rot));
  return e;
}

void Append(std::vector<double>& dst, const std::vector<double>& src) {
  dst.insert(dst.end(), src.begin(), src.end());
}

}  // namespace

ErrorStats Stats(std::vector<double> values) {
  ErrorStats s;
  s.n = values.size();
  if (values.empty()) return s;
  double sum = 0.0, sq = 0.0, mx = 0.0;
  for (double v : values) {
    sum += v;
    sq += v * v;
    mx = std::max(mx, v);
  }
  s.mean = sum / double(s.n);
  s.rmse = std::sqrt(sq / double(s.n));
  s.max = mx;
  const std::size_t mid = s.n / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double upper = values[mid];
  if (s.n % 2 == 1) {
    s.median = upper;
  } else {
    const double lower = *std::max_element(values.begin(), values.begin() + mid);
    s.median = 0.5 * (lower + upper);
  }
  return s;
}

Pose AlignRigid(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst) {
  if (src.size() != dst.size() || src.empty())
    throw Error("AlignRigid: need the same non-zero number of points (got " +
                std::to_string(src.size()) + " and " + std::to_string(dst.size()) + ")");
  const double n = double(src.size());
  Eigen::Vector3d mu_s = Eigen::Vector3d::Zero(), mu_d = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < src.size(); ++i) {
    mu_s += src[i];
    mu_d += dst[i];
  }
  mu_s /= n;
  mu_d /= n;
  // Cross-covariance H = sum (d_i - mu_d)(s_i - mu_s)^T; R = U diag(1,1,det(UV^T)) V^T maximises
  // trace(R^T H), i.e. minimises the squared residuals (Umeyama 1991 without scale).
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < src.size(); ++i) H += (dst[i] - mu_d) * (src[i] - mu_s).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d S = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) S(2, 2) = -1.0;
  Pose T = Pose::Identity();
  T.linear() = svd.matrixU() * S * svd.matrixV().transpose();
  T.translation() = mu_d - T.linear() * mu_s;
  return T;
}

namespace {
void CheckTrajectories(const std::vector<SessionTrajectory>& sessions) {
  if (sessions.empty()) throw Error("trajectory evaluation: no sessions given");
  for (const auto& s : sessions) {
    if (s.truth.size() != s.est.size())
      throw Error("session " + s.name + ": " + std::to_string(s.truth.size()) + " true poses but " +
                  std::to_string(s.est.size()) + " estimated poses");
    if (s.truth.empty()) throw Error("session " + s.name + ": no poses");
  }
}

void AppendPositions(const std::vector<Pose>& poses, std::vector<Eigen::Vector3d>& out) {
  for (const auto& p : poses) out.push_back(p.translation());
}

// T_truth_est per session: one rigid transform for all (joint), one each, or identity.
std::vector<Pose> Alignments(const std::vector<SessionTrajectory>& sessions, const std::string& mode) {
  std::vector<Pose> align(sessions.size(), Pose::Identity());
  if (mode == "joint") {
    std::vector<Eigen::Vector3d> est, truth;
    for (const auto& s : sessions) {
      AppendPositions(s.est, est);
      AppendPositions(s.truth, truth);
    }
    std::fill(align.begin(), align.end(), AlignRigid(est, truth));
  } else if (mode == "per_session") {
    for (std::size_t k = 0; k < sessions.size(); ++k) {
      std::vector<Eigen::Vector3d> est, truth;
      AppendPositions(sessions[k].est, est);
      AppendPositions(sessions[k].truth, truth);
      align[k] = AlignRigid(est, truth);
    }
  }
  return align;
}

// Relative pose errors of the pairs (i, j(i)): j = i + delta keyframes, or the first keyframe at
// least delta metres of true path after i.
void RelativeErrors(const SessionTrajectory& s, const EvalConfig& cfg, std::vector<double>* rt,
                    std::vector<double>* rr) {
  const std::size_t n = s.truth.size();
  if (cfg.rpe_unit == "frames") {
    const auto step = std::size_t(std::max(1.0, std::round(cfg.rpe_delta)));
    for (std::size_t i = 0; i + step < n; ++i)
      AddError(s.truth[i].inverse() * s.truth[i + step], s.est[i].inverse() * s.est[i + step], rt, rr);
    return;
  }
  std::vector<double> dist(n, 0.0);  // true path length from keyframe 0
  for (std::size_t i = 1; i < n; ++i) dist[i] = dist[i - 1] + (s.truth[i].translation() - s.truth[i - 1].translation()).norm();
  std::size_t j = 0;
  for (std::size_t i = 0; i < n; ++i) {
    j = std::max(j, i + 1);
    while (j < n && dist[j] - dist[i] < cfg.rpe_delta) ++j;
    if (j >= n) break;
    AddError(s.truth[i].inverse() * s.truth[j], s.est[i].inverse() * s.est[j], rt, rr);
  }
}

// Query keyframe vs its nearest central keyframe (true positions, within max_sq): the error of
// their relative pose.
ConsistencySessionResult Consistency(const SessionTrajectory& central, const SessionTrajectory& q, double max_sq,
                                     std::vector<double>* t_all, std::vector<double>* r_all) {
  ConsistencySessionResult cr;
  cr.name = q.name;
  std::vector<double> t, rot;
  for (std::size_t i = 0; i < q.truth.size(); ++i) {
    const Eigen::Vector3d p = q.truth[i].translation();
    std::size_t best = 0;
    double best_sq = std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < central.truth.size(); ++c) {
      const double d = (central.truth[c].translation() - p).squaredNorm();
      if (d < best_sq) best_sq = d, best = c;
    }
    if (best_sq > max_sq) {
      ++cr.skipped;
      continue;
    }
    AddError(central.truth[best].inverse() * q.truth[i], central.est[best].inverse() * q.est[i], &t, &rot);
  }
  cr.pairs = t.size();
  Append(*t_all, t);
  Append(*r_all, rot);
  cr.error = MakeErrors(std::move(t), std::move(rot));
  return cr;
}
}  // namespace

TrajResult EvaluateTrajectories(const std::vector<SessionTrajectory>& sessions, const EvalConfig& cfg) {
  cfg.Validate();
  CheckTrajectories(sessions);
  TrajResult r;
  r.align = cfg.traj_align;
  r.rpe_unit = cfg.rpe_unit;
  r.rpe_delta = cfg.rpe_delta;
  const std::vector<Pose> align = Alignments(sessions, cfg.traj_align);
  std::vector<double> ate_t, ate_r, rpe_t, rpe_r;
  for (std::size_t k = 0; k < sessions.size(); ++k) {
    const auto& s = sessions[k];
    TrajSessionResult sr;
    sr.name = s.name;
    sr.poses = s.truth.size();
    sr.T_truth_est = align[k];
    std::vector<double> t, rot, rt, rr;
    for (std::size_t i = 0; i < s.truth.size(); ++i) AddError(s.truth[i], align[k] * s.est[i], &t, &rot);
    Append(ate_t, t);
    Append(ate_r, rot);
    sr.ate = MakeErrors(std::move(t), std::move(rot));
    RelativeErrors(s, cfg, &rt, &rr);
    Append(rpe_t, rt);
    Append(rpe_r, rr);
    sr.rpe = MakeErrors(std::move(rt), std::move(rr));
    r.sessions.push_back(std::move(sr));
  }
  r.ate = MakeErrors(std::move(ate_t), std::move(ate_r));
  r.rpe = MakeErrors(std::move(rpe_t), std::move(rpe_r));
  // Inter-session consistency against the central session (index 0).
  std::vector<double> ct_all, cr_all;
  const double max_sq = cfg.consistency_max_dist_m * cfg.consistency_max_dist_m;
  for (std::size_t k = 1; k < sessions.size(); ++k)
    r.consistency_sessions.push_back(Consistency(sessions.front(), sessions[k], max_sq, &ct_all, &cr_all));
  r.consistency = MakeErrors(std::move(ct_all), std::move(cr_all));
  return r;
}

}  // namespace ltm::eval
