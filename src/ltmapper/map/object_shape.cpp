// What an object's cloud says of its shape (object_shape.hpp).
#include "ltmapper/map/object_shape.hpp"

#include "ltmapper/map/detail.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <map>
#include <vector>

namespace ltm::map::detail {

// Centroid, axis-aligned box, class votes (of the changes seen, not of a disappeared object's
// joined unseen parts)
// and see-through share, of its points and of the surface beside them its reference never
// observed (MapObject::unobserved_beside).
void Describe(MapObject& o) {
  std::map<PointClass, std::size_t> votes;
  o.centroid.setZero();
  o.lo = o.hi = o.cloud.points[0].xyz().cast<double>();
  std::size_t seen_through = 0;
  for (std::size_t i = 0; i < o.cloud.size(); ++i) {
    const Eigen::Vector3d p = o.cloud.points[i].xyz().cast<double>();
    o.centroid += p;
    o.lo = o.lo.cwiseMin(p);
    o.hi = o.hi.cwiseMax(p);
    if (!Unseen(o.cloud.cls[i])) ++votes[o.cloud.cls[i]];
    if (SeenThrough(o.cloud.cls[i])) ++seen_through;
  }
  o.points = o.cloud.size();
  o.centroid /= double(o.points);
  o.observed_fraction = double(seen_through) / double(o.points + o.unobserved_beside);
  std::size_t best = 0;
  for (const auto& [c, n] : votes)
    if (n > best) best = n, o.cls = c;
}

// Oriented box: the xy rectangle whose sides the points lie closest to (geometry::SidesBoxOf: a
// box scanned on two faces is an L of points, whose principal axis tilts towards the shorter
// face), yaw of its longer side, extents along it and across, and z.
void OrientedBox(MapObject& o) {
  const geometry::HorizontalBox b = geometry::SidesBoxOf(o.cloud);
  o.yaw_rad = b.yaw_rad;
  o.box_center = Eigen::Vector3d(b.center.x(), b.center.y(), (o.lo.z() + o.hi.z()) / 2);
  o.size = Eigen::Vector3d(b.length, b.width, o.hi.z() - o.lo.z());
}

Spread3 Spread(const MapObject& o) {
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : o.cloud.points) {
    const Eigen::Vector3d d = p.xyz().cast<double>() - o.centroid;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov / double(o.points));
  return {es.eigenvalues().cwiseMax(0.0).cwiseSqrt(), es.eigenvectors().col(0), es.eigenvectors().col(1)};
}

// Share of a cluster's points left out at each end of its middle axis when measuring its width: a
// row of samples holding fewer (stray returns, a neighbour's edge) does not widen it.
constexpr double kWidthTrimShare = 0.05;

// Width: the extent of the cluster's points along its middle principal axis between the
// kWidthTrimShare and 1 - kWidthTrimShare quantiles. n rows of samples s apart span (n - 1) s
// whatever share of the points each row holds (at least kWidthTrimShare): a map gathers a surface's
// rows from keyframes at several ranges, so its rows rarely hold equal shares.
double Width(const MapObject& o, const Eigen::Vector3d& middle) {
  std::vector<double> along;
  along.reserve(o.cloud.size());
  for (const auto& p : o.cloud.points) along.push_back((p.xyz().cast<double>() - o.centroid).dot(middle));
  if (along.empty()) return 0.0;
  const auto at = [&](double q) {
    const auto k = std::ptrdiff_t(std::lround(q * double(along.size() - 1)));
    std::nth_element(along.begin(), along.begin() + k, along.end());
    return along[std::size_t(k)];
  };
  const double lo = at(kWidthTrimShare);
  return at(1.0 - kWidthTrimShare) - lo;
}

// Clearance of the cluster above the local ground: the smallest height of a point above the
// floor of its own cell (not the lowest cell under the box: slopes and curbs across a long
// cluster would count as clearance). Sets ground_z to the floor under that point.
double Clearance(MapObject& o, const geometry::LowestGrid& floor) {
  double best = 1e300;
  o.ground_z = o.lo.z();
  for (const auto& p : o.cloud.points) {
    float z = 0.f;
    if (!floor.At(p.xyz(), &z) || double(p.z - z) >= best) continue;
    best = double(p.z - z);
    o.ground_z = double(z);
  }
  return best == 1e300 ? 0.0 : best;
}

// Segment p-q against an axis-aligned box grown by `margin` (slab test).
bool SegmentHitsBox(const Eigen::Vector3d& p, const Eigen::Vector3d& q, Eigen::Vector3d lo, Eigen::Vector3d hi,
                    double margin) {
  lo.array() -= margin;
  hi.array() += margin;
  double t0 = 0.0, t1 = 1.0;
  const Eigen::Vector3d d = q - p;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12) {
      if (p[k] < lo[k] || p[k] > hi[k]) return false;
      continue;
    }
    double a = (lo[k] - p[k]) / d[k], b = (hi[k] - p[k]) / d[k];
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a), t1 = std::min(t1, b);
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace ltm::map::detail
