// Pose-graph residuals of LT-SLAM (internal header of the slam module and its tests; Eigen
// only, so the functors can be differentiated by Ceres' autodiff in pose_graph.cpp and checked
// against numerical Jacobians in the tests).
//
// A pose is a parameter block of 7 doubles [tx ty tz qx qy qz qw] (Eigen quaternion order),
// T = (R(q), t), mapping p -> R p + t.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>

namespace ltm::slam::detail {

template <typename T>
struct Se3 {
  Eigen::Quaternion<T> q;
  Eigen::Matrix<T, 3, 1> t;
};

template <typename T>
Se3<T> Load(const T* x) {
  return {Eigen::Quaternion<T>(x[6], x[3], x[4], x[5]), Eigen::Matrix<T, 3, 1>(x[0], x[1], x[2])};
}
template <typename T>
Se3<T> Mul(const Se3<T>& a, const Se3<T>& b) {
  return {a.q * b.q, a.q * b.t + a.t};
}
template <typename T>
Se3<T> Inv(const Se3<T>& a) {
  const Eigen::Quaternion<T> qi = a.q.conjugate();
  return {qi, -(qi * a.t)};
}

// SE(3) logarithm as [rho; omega]: omega = log(R) (axis * angle), rho = V(omega)^-1 t with
//   V^-1 = I - 1/2 W + c W^2,  W = [omega]x,  c = (1 - theta sin(theta) / (2 (1 - cos theta))) / theta^2
// (Barfoot, "State Estimation for Robotics", eq. 7.86 ff.). Below theta = 0.1 the Taylor series
// c = 1/12 + theta^2/720 + theta^4/30240 avoids the cancellation in 1 - cos.
template <typename T>
Eigen::Matrix<T, 6, 1> Log(const Se3<T>& e) {
  using std::atan2;
  using std::sqrt;
  using std::sin;
  using std::cos;
  Eigen::Quaternion<T> q = e.q;
  if (q.w() < T(0)) q.coeffs() = -q.coeffs();  // shortest rotation
  const Eigen::Matrix<T, 3, 1> v = q.vec();
  const T sin_sq = v.squaredNorm();
  Eigen::Matrix<T, 3, 1> omega;
  if (sin_sq > T(1e-20)) {
    const T sin_half = sqrt(sin_sq);
    const T theta = T(2) * atan2(sin_half, q.w());
    omega = v * (theta / sin_half);
  } else {
    omega = v * (T(2) / q.w());  // first order: theta ~ 2 |v| / w
  }
  const T theta_sq = omega.squaredNorm();
  T c;
  if (theta_sq < T(1e-2)) {
    c = T(1.0 / 12.0) + theta_sq * (T(1.0 / 720.0) + theta_sq * T(1.0 / 30240.0));
  } else {
    const T theta = sqrt(theta_sq);
    c = (T(1) - theta * sin(theta) / (T(2) * (T(1) - cos(theta)))) / theta_sq;
  }
  const Eigen::Matrix<T, 3, 1> wt = omega.cross(e.t);
  const Eigen::Matrix<T, 3, 1> rho = e.t - T(0.5) * wt + c * omega.cross(wt);
  Eigen::Matrix<T, 6, 1> r;
  r << rho, omega;
  return r;
}

// A relative-pose measurement z between two poses a and b with its square-root information:
// r = sqrt_info * Log(z^-1 * a^-1 * b), the residual of both factors below.
struct RelativePoseResidual {
  Se3<double> z_inv;
  Eigen::Matrix<double, 6, 6> sqrt_info;
  RelativePoseResidual(const Eigen::Isometry3d& z, const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : sqrt_info(sqrt_information) {
    const Eigen::Isometry3d zi = z.inverse();
    z_inv.q = Eigen::Quaterniond(zi.linear()).normalized();
    z_inv.t = zi.translation();
  }
  template <typename T>
  bool Residual(const Se3<T>& a, const Se3<T>& b, T* residual) const {
    const Se3<T> zi{z_inv.q.cast<T>(), z_inv.t.cast<T>()};
    const Se3<T> e = Mul(zi, Mul(Inv(a), b));
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(residual);
    out = sqrt_info.cast<T>() * Log(e);
    return true;
  }
};

// Odometry / intra-session loop: r = sqrt_info * Log(z^-1 * x_a^-1 * x_b).
struct BetweenFactor : RelativePoseResidual {
  using RelativePoseResidual::RelativePoseResidual;
  template <typename T>
  bool operator()(const T* xa, const T* xb, T* residual) const {
    return Residual(Load(xa), Load(xb), residual);
  }
};

// Gravity: a keyframe's vertical (the session frame's z in its sensor frame) stays where the
// odometry put it, r = (R(q)^T z - up) / sigma: inertial odometry holds roll and pitch to gravity,
// they do not drift. Its component along `up` is second order, so the residual is the tilt.
struct GravityFactor {
  Eigen::Vector3d up;
  double inv_sigma;  // [1/rad]
  template <typename T>
  bool operator()(const T* x, T* residual) const {
    const Se3<T> p = Load(x);
    const Eigen::Matrix<T, 3, 1> u = p.q.normalized().conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    Eigen::Map<Eigen::Matrix<T, 3, 1>> out(residual);
    out = (u - up.cast<T>()) * T(inv_sigma);
    return true;
  }
};

// Inter-session loop through the anchors (paper eq. 2):
//   r = sqrt_info * Log( z^-1 * (A_a * x_a)^-1 * (A_b * x_b) ).
struct AnchorLoopFactor : RelativePoseResidual {
  using RelativePoseResidual::RelativePoseResidual;
  template <typename T>
  bool operator()(const T* anchor_a, const T* xa, const T* anchor_b, const T* xb, T* residual) const {
    return Residual(Mul(Load(anchor_a), Load(xa)), Mul(Load(anchor_b), Load(xb)), residual);
  }
};

// Dynamic Covariance Scaling (Agarwal et al., ICRA 2013) as an M-estimator on s = |r|^2: the DCS
// weight is w(s) = min(1, 2 phi / (phi + s))^2, so rho'(s) = w(s) and, integrating,
//   rho(s) = s                          for s <= phi
//   rho(s) = 3 phi - 4 phi^2 / (phi + s) for s > phi   (continuous with its first derivative).
inline void DcsLoss(double phi, double s, double rho[3]) {
  if (s <= phi) {
    rho[0] = s;
    rho[1] = 1.0;
    rho[2] = 0.0;
  } else {
    const double d = phi + s;
    rho[0] = 3.0 * phi - 4.0 * phi * phi / d;
    rho[1] = 4.0 * phi * phi / (d * d);
    rho[2] = -8.0 * phi * phi / (d * d * d);
  }
}

}  // namespace ltm::slam::detail
