// Generalized-ICP (Segal, Haehnel, Thrun 2009), plane-to-plane, solved by Gauss-Newton on SE(3):
//   1. Prepare each cloud once: a kd-tree and, per point, the local plane of its k nearest
//      neighbours: their covariance with the eigenvalues replaced by (1, 1, eps) (a disc along the
//      local surface), the normal and the spread along it (for the verification's plane test),
//      computed the first time the point takes part in a pair (most of the cost: points that
//      never meet the other cloud need none).
//   2. Iterate: pair each transformed source point with its nearest target point within the
//      correspondence distance, weight the residual by (C_t + R C_s R^T)^-1, take one GN step
//      (left perturbation exp(xi) * T), stop when the step is below the convergence bounds.
// Single-threaded on purpose: loop verification runs many registrations in parallel, and a
// fixed summation order makes the result identical for any thread count.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/internal.hpp"

#include <Eigen/Eigenvalues>

#include <cmath>

namespace ltm::slam {

namespace {
// Segal et al.: the smallest eigenvalue of a point's regularised covariance (normal direction)
// relative to the two in-plane ones.
constexpr double kPlaneEpsilon = 1e-3;
// Fewer neighbours than this give no plane: the point keeps an isotropic covariance.
constexpr std::size_t kMinPlaneNeighbours = 5;

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

// exp of a twist (rotation first, then translation) as a pose, SO(3) x R^3 (left perturbation).
Pose ExpTwist(const Vector6d& xi) {
  Pose T = Pose::Identity();
  const Eigen::Vector3d w = xi.head<3>();
  const double angle = w.norm();
  if (angle > 0.0) T.linear() = Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
  T.translation() = xi.tail<3>();
  return T;
}

GicpCloud::Plane LocalPlane(const geometry::KdTree& tree, const Eigen::Vector3f& p, int k) {
  GicpCloud::Plane plane;
  const auto nn = tree.Knn(p, std::size_t(k));
  if (nn.size() < kMinPlaneNeighbours) return plane;  // isotropic, no normal
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  const PointCloud& c = tree.cloud();
  for (const auto& [i, d2] : nn) mean += c.points[i].xyz().cast<double>();
  mean /= double(nn.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const auto& [i, d2] : nn) {
    const Eigen::Vector3d d = c.points[i].xyz().cast<double>() - mean;
    C += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(C / double(nn.size()));
  const Eigen::Matrix3d V = es.eigenvectors();  // ascending eigenvalues: column 0 = normal
  plane.cov = V * Eigen::Vector3d(kPlaneEpsilon, 1.0, 1.0).asDiagonal() * V.transpose();
  plane.normal = V.col(0);
  plane.spread = std::max(0.0, es.eigenvalues()(0));
  return plane;
}
}  // namespace

GicpCloud::GicpCloud(const PointCloud& cloud, int covariance_neighbours)
    : tree(std::make_unique<geometry::KdTree>(cloud)),
      k_(covariance_neighbours),
      planes_(cloud.size()),
      has_plane_(cloud.size(), 0) {}
GicpCloud::~GicpCloud() = default;
GicpCloud::GicpCloud(GicpCloud&&) noexcept = default;

const PointCloud& GicpCloud::cloud() const { return tree->cloud(); }

const GicpCloud::Plane& GicpCloud::PlaneAt(std::size_t i) const {
  if (!has_plane_[i]) {
    planes_[i] = LocalPlane(*tree, cloud().points[i].xyz(), k_);
    has_plane_[i] = 1;
  }
  return planes_[i];
}

void GicpCloud::PrepareAllPlanes() {
  for (std::size_t i = 0; i < planes_.size(); ++i) PlaneAt(i);
}

namespace {
// The normal equations of one GN step at T: H = sum J^T W J, g = sum J^T W r over the pairs
// within max_corr (r = t - T s, J = dr/dxi = [ [Ts]x, -I ]).
struct NormalEquations {
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  std::size_t pairs = 0;
};

NormalEquations Linearise(const GicpCloud& target, const GicpCloud& source, const Pose& T, double max_corr) {
  NormalEquations ne;
  const float max_d2 = float(max_corr * max_corr);
  const Eigen::Matrix3d R = T.linear();
  const PointCloud& src = source.cloud();
  const PointCloud& tgt = target.cloud();
  for (std::size_t i = 0; i < src.size(); ++i) {
    const Eigen::Vector3d q = T * src.points[i].xyz().cast<double>();
    std::uint32_t j = 0;
    float d2 = 0.f;
    if (!target.tree->Nearest(q.cast<float>(), &j, &d2) || d2 >= max_d2) continue;
    const Eigen::Vector3d r = tgt.points[j].xyz().cast<double>() - q;
    const Eigen::Matrix3d W = (target.PlaneAt(j).cov + R * source.PlaneAt(i).cov * R.transpose()).inverse();
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = Skew(q);
    J.rightCols<3>() = -Eigen::Matrix3d::Identity();
    const Eigen::Matrix<double, 6, 3> JtW = J.transpose() * W;
    ne.H += JtW * J;
    ne.g += JtW * r;
    ++ne.pairs;
  }
  return ne;
}
}  // namespace

GicpResult AlignGicp(const GicpCloud& target, const GicpCloud& source, const Pose& guess, const GicpOptions& opt) {
  GicpResult res;
  res.T = guess;
  for (res.iterations = 0; res.iterations < opt.max_iterations; ++res.iterations) {
    const NormalEquations ne = Linearise(target, source, res.T, opt.max_correspondence_m);
    if (ne.pairs < opt.min_pairs) return res;  // not converged: too little overlap to solve
    const Vector6d xi = ne.H.ldlt().solve(-ne.g);
    if (!xi.allFinite()) return res;
    res.T = ExpTwist(xi) * res.T;
    if (xi.head<3>().norm() < opt.converged_rotation_rad && xi.tail<3>().norm() < opt.converged_translation_m) {
      res.converged = true;
      ++res.iterations;
      break;
    }
  }
  // Out of iterations without a blow-up still counts as converged (the verification gates
  // judge the result), as in PCL's GICP.
  res.converged = res.converged || res.iterations == opt.max_iterations;
  return res;
}

}  // namespace ltm::slam
