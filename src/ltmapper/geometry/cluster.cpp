// Euclidean clusters (union-find over the kd-tree's radius neighbours), the longest horizontal
// edge of a cluster's oriented box, and the lowest point per xy cell (the ground under things).
#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Eigenvalues>
#include <boost/geometry.hpp>
#include <boost/geometry/geometries/point_xy.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

namespace ltm::geometry {

namespace {
std::uint32_t Root(std::vector<std::uint32_t>& parent, std::uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];  // path halving
  return i;
}

// Union-find over the pairs (i, j), j > i, that `joined(i, j, d2)` accepts among the kd-tree's
// neighbours of i within radius(i): the pairs are found on `threads` cores a batch at a time and
// joined on one, so the components, and the labels, do not depend on the order of the joins.
template <class Radius, class Joined>
std::vector<std::uint32_t> ClusterLabels(const PointCloud& cloud, int threads, Radius radius, Joined joined) {
  const std::size_t n = cloud.size();
  std::vector<std::uint32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0u);
  if (n == 0) return parent;
  const KdTree tree(cloud, threads);
  constexpr std::size_t kChunk = 1024, kChunksPerBatch = 64;  // batches bound the pairs held
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> pairs(kChunksPerBatch);
  for (std::size_t b = 0; b < n; b += kChunk * kChunksPerBatch) {
    const std::size_t chunks = std::min(kChunksPerBatch, (n - b + kChunk - 1) / kChunk);
    ParallelFor(chunks, threads, [&](std::size_t c) {
      pairs[c].clear();
      const std::size_t from = b + c * kChunk, to = std::min(n, from + kChunk);
      for (std::size_t i = from; i < to; ++i)
        for (const auto& [j, d2] : tree.RadiusUnsorted(cloud.points[i].xyz(), radius(i)))
          if (j > i && joined(i, j, d2)) pairs[c].emplace_back(std::uint32_t(i), j);
    });
    for (std::size_t c = 0; c < chunks; ++c)
      for (const auto& [i, j] : pairs[c]) {
        const std::uint32_t ri = Root(parent, i), rj = Root(parent, j);
        if (ri != rj) parent[std::max(ri, rj)] = std::min(ri, rj);  // the root is the lowest index
      }
  }
  std::vector<std::uint32_t> label(n), number(n, std::uint32_t(-1));
  std::uint32_t clusters = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t r = Root(parent, std::uint32_t(i));
    if (number[r] == std::uint32_t(-1)) number[r] = clusters++;
    label[i] = number[r];
  }
  return label;
}

std::vector<std::vector<std::uint32_t>> Members(const std::vector<std::uint32_t>& label) {
  std::vector<std::vector<std::uint32_t>> members;
  for (std::size_t i = 0; i < label.size(); ++i) {
    if (label[i] >= members.size()) members.resize(label[i] + 1);  // numbered in order of first point
    members[label[i]].push_back(std::uint32_t(i));
  }
  return members;
}
}  // namespace

std::vector<std::uint32_t> EuclideanClusters(const PointCloud& cloud, double gap_m, int threads) {
  return ClusterLabels(cloud, threads, [&](std::size_t) { return float(gap_m); },
                       [](std::size_t, std::uint32_t, float) { return true; });
}

std::vector<std::vector<std::uint32_t>> EuclideanClusterMembers(const PointCloud& cloud, double gap_m, int threads) {
  return Members(EuclideanClusters(cloud, gap_m, threads));
}

Eigen::Vector2f SampleJoinGaps(double azimuth_step_deg, double vertical_step_deg, double range_m) {
  constexpr double kGapsPerStep = 2.0, kDegToRad = M_PI / 180.0;  // 1 / cos 60 deg
  return Eigen::Vector2f(float(azimuth_step_deg), float(vertical_step_deg)) * float(kGapsPerStep * kDegToRad * range_m);
}

std::vector<std::vector<std::uint32_t>> EuclideanClusterMembers(const PointCloud& cloud,
                                                                const std::vector<Eigen::Vector2f>& gaps, int threads) {
  if (gaps.size() != cloud.size())
    throw Error("EuclideanClusterMembers: " + std::to_string(gaps.size()) + " gaps for " + std::to_string(cloud.size()) +
                " points");
  for (const auto& g : gaps)
    if (!(g.minCoeff() > 0.f)) throw Error("EuclideanClusterMembers: a gap is not positive");
  return Members(ClusterLabels(cloud, threads, [&](std::size_t i) { return gaps[i].maxCoeff(); },
                               [&](std::size_t i, std::uint32_t j, float) {
                                 const PointXYZI &a = cloud.points[i], &b = cloud.points[j];
                                 const Eigen::Vector2f g = gaps[i].cwiseMin(gaps[j]);
                                 const float dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
                                 return (dx * dx + dy * dy) / (g.x() * g.x()) + dz * dz / (g.y() * g.y()) < 1.f;
                               }));
}

namespace {
// The box of the n points xy(k) along unit axis u (yaw, length) and u turned 90 deg counter-clockwise
// (width), offsets taken from `origin` (a point near them: their mean keeps the sums exact).
template <class F>
HorizontalBox BoxAlong(const Eigen::Vector2d& u, std::size_t n, F xy, const Eigen::Vector2d& origin) {
  const Eigen::Vector2d v(-u.y(), u.x());
  double a0 = 1e300, a1 = -1e300, b0 = 1e300, b1 = -1e300;
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Vector2d d = xy(k) - origin;
    a0 = std::min(a0, d.dot(u)), a1 = std::max(a1, d.dot(u));
    b0 = std::min(b0, d.dot(v)), b1 = std::max(b1, d.dot(v));
  }
  HorizontalBox box;
  box.yaw_rad = std::atan2(u.y(), u.x());
  box.center = origin + u * (a0 + a1) / 2 + v * (b0 + b1) / 2;
  box.length = a1 - a0;
  box.width = b1 - b0;
  return box;
}
}  // namespace

HorizontalBox HorizontalBoxOf(const PointCloud& cloud, const std::vector<std::uint32_t>& idx) {
  const std::size_t n = idx.empty() ? cloud.size() : idx.size();
  auto xy = [&](std::size_t k) {
    const PointXYZI& p = cloud.points[idx.empty() ? k : idx[k]];
    return Eigen::Vector2d(double(p.x), double(p.y));
  };
  HorizontalBox box;
  if (n == 0) return box;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t k = 0; k < n; ++k) mean += xy(k);
  mean /= double(n);
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (std::size_t k = 0; k < n; ++k) cov += (xy(k) - mean) * (xy(k) - mean).transpose();
  return BoxAlong(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvectors().col(1), n, xy, mean);
}

HorizontalBox SidesBoxOf(const PointCloud& cloud, const std::vector<std::uint32_t>& idx) {
  namespace bg = boost::geometry;
  using Point = bg::model::d2::point_xy<double>;
  const std::size_t n = idx.empty() ? cloud.size() : idx.size();
  if (n < 3) return HorizontalBoxOf(cloud, idx);
  bg::model::multi_point<Point> pts;
  pts.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    const PointXYZI& p = cloud.points[idx.empty() ? k : idx[k]];
    pts.emplace_back(double(p.x), double(p.y));
  }
  bg::model::ring<Point> hull;
  bg::convex_hull(pts, hull);
  const auto hull_at = [&](std::size_t k) { return Eigen::Vector2d(hull[k].x(), hull[k].y()); };
  const Eigen::Vector2d origin = hull_at(0);
  HorizontalBox best;
  double best_mean = std::numeric_limits<double>::infinity(), best_area = best_mean;
  for (std::size_t e = 0; e + 1 < hull.size(); ++e) {
    const Eigen::Vector2d edge = hull_at(e + 1) - hull_at(e);
    if (edge.norm() < 1e-9) continue;
    const Eigen::Vector2d u = edge.normalized(), v(-u.y(), u.x());
    const HorizontalBox b = BoxAlong(u, hull.size(), hull_at, origin);
    const Eigen::Vector2d lo = b.center - u * b.length / 2 - v * b.width / 2;  // the box's (u, v) corner
    double sum = 0.0;  // each point's distance to its nearest side
    for (const Point& q : pts) {
      const Eigen::Vector2d d = Eigen::Vector2d(q.x(), q.y()) - lo;
      const double a = d.dot(u), c = d.dot(v);
      sum += std::min(std::min(a, b.length - a), std::min(c, b.width - c));
    }
    const double mean = sum / double(n), area = b.length * b.width;
    if (mean > best_mean || (mean == best_mean && area >= best_area)) continue;
    best_mean = mean, best_area = area, best = b;
    if (b.width > b.length) {  // the longer side is the major axis
      best.yaw_rad = std::atan2(v.y(), v.x());
      std::swap(best.length, best.width);
    }
  }
  if (!std::isfinite(best_mean)) return HorizontalBoxOf(cloud, idx);  // all points on one spot
  return best;
}

double LongestHorizontalEdge(const PointCloud& cloud, const std::vector<std::uint32_t>& idx) {
  if (idx.size() < 2) return 0.0;
  const HorizontalBox box = HorizontalBoxOf(cloud, idx);
  return std::max(box.length, box.width);
}

std::int64_t LowestGrid::Cell(double v) const { return std::int64_t(std::floor(v / cell_m_)); }

// 32 bits per axis: cells of 1 cm still span +-21000 km.
std::int64_t LowestGrid::Pack(std::int64_t ix, std::int64_t iy) { return (ix << 32) ^ (iy & 0xffffffffll); }

void LowestGrid::Add(const PointCloud& cloud) {
  if (cell_m_ <= 0.0) return;
  for (const auto& p : cloud.points) {
    const auto [it, added] = z_.emplace(Pack(Cell(p.x), Cell(p.y)), p.z);
    if (!added) it->second = std::min(it->second, p.z);
  }
}

void LowestGrid::Add(const LowestGrid& other) {
  for (const auto& [cell, z] : other.z_) {
    const auto [it, added] = z_.emplace(cell, z);
    if (!added) it->second = std::min(it->second, z);
  }
}

void LowestGrid::Watch(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int grow) {
  if (cell_m_ <= 0.0) return;
  for (std::int64_t ix = Cell(lo.x()) - grow; ix <= Cell(hi.x()) + grow; ++ix)
    for (std::int64_t iy = Cell(lo.y()) - grow; iy <= Cell(hi.y()) + grow; ++iy)
      z_.emplace(Pack(ix, iy), std::numeric_limits<float>::infinity());
}

void LowestGrid::AddWatched(const PointCloud& cloud) {
  if (z_.empty()) return;
  for (const auto& p : cloud.points) {
    const auto it = z_.find(Pack(Cell(p.x), Cell(p.y)));
    if (it != z_.end()) it->second = std::min(it->second, p.z);
  }
}

bool LowestGrid::At(const Eigen::Vector3f& p, float* z) const {
  if (z_.empty()) return false;
  const auto it = z_.find(Pack(Cell(p.x()), Cell(p.y())));
  if (it == z_.end() || !std::isfinite(it->second)) return false;
  *z = it->second;
  return true;
}

float LowestGrid::Under(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int grow) const {
  float best = std::numeric_limits<float>::infinity();
  if (z_.empty()) return best;
  for (std::int64_t ix = Cell(lo.x()) - grow; ix <= Cell(hi.x()) + grow; ++ix)
    for (std::int64_t iy = Cell(lo.y()) - grow; iy <= Cell(hi.y()) + grow; ++iy) {
      const auto it = z_.find(Pack(ix, iy));
      if (it != z_.end()) best = std::min(best, it->second);
    }
  return best;
}

}  // namespace ltm::geometry
