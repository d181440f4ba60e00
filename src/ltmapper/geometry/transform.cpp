// Transforms and point filters. Every function keeps the optional per-point arrays aligned.
#include "ltmapper/geometry/geometry.hpp"

#include <cmath>

namespace ltm::geometry {

namespace {
// Applies p' = R p + t in double (points far from the origin keep their precision).
inline void Apply(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, PointXYZI& p) {
  const Eigen::Vector3d q = R * Eigen::Vector3d(p.x, p.y, p.z) + t;
  p.x = static_cast<float>(q.x());
  p.y = static_cast<float>(q.y());
  p.z = static_cast<float>(q.z());
}

inline bool Finite(const PointXYZI& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

template <class T>
void Compact(std::vector<T>& v, const std::vector<bool>& keep) {
  if (v.empty()) return;
  std::size_t w = 0;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (keep[i]) v[w++] = v[i];
  v.resize(w);
}
}  // namespace

PointCloud Transform(const PointCloud& cloud, const Pose& T) {
  PointCloud out = cloud;
  TransformInPlace(out, T);
  return out;
}

void TransformInPlace(PointCloud& cloud, const Pose& T) {
  const Eigen::Matrix3d R = T.linear();
  const Eigen::Vector3d t = T.translation();
  for (auto& p : cloud.points) Apply(R, t, p);
}

PointCloud RangeFilter(const PointCloud& cloud, double min_range_m, double max_range_m) {
  const double lo2 = min_range_m * min_range_m;
  const double hi2 = max_range_m * max_range_m;
  std::vector<bool> keep(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.points[i];
    const double r2 = double(p.x) * p.x + double(p.y) * p.y + double(p.z) * p.z;
    keep[i] = r2 >= lo2 && r2 <= hi2;  // NaN compares false: dropped
  }
  return cloud.select(keep);
}

PointCloud CropBox(const PointCloud& cloud, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  std::vector<bool> keep(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.points[i];
    keep[i] = p.x >= lo.x() && p.x <= hi.x() && p.y >= lo.y() && p.y <= hi.y() &&
              p.z >= lo.z() && p.z <= hi.z();
  }
  return cloud.select(keep);
}

std::size_t RemoveNonFinite(PointCloud& cloud) {
  cloud.CheckConsistent("RemoveNonFinite");
  std::vector<bool> keep(cloud.size());
  std::size_t dropped = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    keep[i] = Finite(cloud.points[i]);
    dropped += keep[i] ? 0 : 1;
  }
  if (dropped == 0) return 0;
  Compact(cloud.points, keep);
  Compact(cloud.cls, keep);
  Compact(cloud.session, keep);
  Compact(cloud.object, keep);
  return dropped;
}

}  // namespace ltm::geometry
