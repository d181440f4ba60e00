// KdTree: nanoflann (1.4.x API) over the xyz of a PointCloud.
// Distances are accumulated in double (float coordinates, float differences, double squares),
// so clouds far from the origin (+-1e6 m) still get exact neighbour sets; results are returned
// as float squared distances, ordered by (distance, index).
#include "ltmapper/geometry/geometry.hpp"

#include <nanoflann.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace ltm::geometry {

namespace {

constexpr std::size_t kLeafMaxSize = 16;  // points per kd-tree leaf (speed trade-off only)

// nanoflann dataset adaptor.
struct CloudAdaptor {
  const PointCloud* cloud = nullptr;
  std::size_t kdtree_get_point_count() const { return cloud->size(); }
  float kdtree_get_pt(std::uint32_t idx, std::size_t dim) const {
    const PointXYZI& p = cloud->points[idx];
    return dim == 0 ? p.x : (dim == 1 ? p.y : p.z);
  }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};

using Metric = nanoflann::L2_Simple_Adaptor<float, CloudAdaptor, double, std::uint32_t>;
using Tree = nanoflann::KDTreeSingleIndexAdaptor<Metric, CloudAdaptor, 3, std::uint32_t>;

// Collects every point with squared distance < r2.
class RadiusSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  RadiusSet(double r2, std::vector<std::pair<std::uint32_t, float>>* out) : r2_(r2), out_(out) {}
  std::size_t size() const { return out_->size(); }
  bool full() const { return true; }
  bool addPoint(double d2, std::uint32_t idx) {
    if (d2 < r2_) out_->emplace_back(idx, static_cast<float>(d2));
    return true;
  }
  double worstDist() const { return r2_; }

 private:
  double r2_;
  std::vector<std::pair<std::uint32_t, float>>* out_;
};

// Counts points with squared distance < r2; stops the search at max_count.
class CountSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  CountSet(double r2, std::size_t max_count) : r2_(r2), max_(max_count) {}
  std::size_t size() const { return count_; }
  bool full() const { return true; }
  bool addPoint(double d2, std::uint32_t) {
    if (d2 < r2_) ++count_;
    return count_ < max_;  // false = done searching
  }
  double worstDist() const { return r2_; }

 private:
  double r2_;
  std::size_t max_;
  std::size_t count_ = 0;
};

inline bool ByDistThenIndex(const std::pair<std::uint32_t, float>& a,
                            const std::pair<std::uint32_t, float>& b) {
  return a.second != b.second ? a.second < b.second : a.first < b.first;
}

}  // namespace

struct KdTree::Impl {
  std::shared_ptr<const PointCloud> cloud;
  CloudAdaptor adaptor;
  std::unique_ptr<Tree> tree;

  explicit Impl(std::shared_ptr<const PointCloud> c) : cloud(std::move(c)) {
    if (!cloud) throw Error("KdTree: null cloud");
    if (cloud->size() >= std::numeric_limits<std::uint32_t>::max())
      throw Error("KdTree: more than 2^32 - 1 points");
    for (std::size_t i = 0; i < cloud->size(); ++i) {
      const PointXYZI& p = cloud->points[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw Error("KdTree: point " + std::to_string(i) + " is not finite (use RemoveNonFinite)");
    }
    adaptor.cloud = cloud.get();
    tree = std::make_unique<Tree>(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafMaxSize));
  }
};

KdTree::KdTree(PointCloud cloud)
    : impl_(std::make_unique<Impl>(std::make_shared<const PointCloud>(std::move(cloud)))) {}
KdTree::KdTree(std::shared_ptr<const PointCloud> cloud) : impl_(std::make_unique<Impl>(std::move(cloud))) {}
KdTree::~KdTree() = default;
KdTree::KdTree(KdTree&&) noexcept = default;
KdTree& KdTree::operator=(KdTree&&) noexcept = default;

const PointCloud& KdTree::cloud() const { return *impl_->cloud; }
std::size_t KdTree::size() const { return impl_->cloud->size(); }

std::vector<std::pair<std::uint32_t, float>> KdTree::Knn(const Eigen::Vector3f& q,
                                                          std::size_t k) const {
  std::vector<std::pair<std::uint32_t, float>> out;
  k = std::min(k, size());
  if (k == 0) return out;
  std::vector<std::uint32_t> idx(k);
  std::vector<double> d2(k);
  nanoflann::KNNResultSet<double, std::uint32_t, std::size_t> set(k);
  set.init(idx.data(), d2.data());
  impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
  out.reserve(set.size());
  for (std::size_t i = 0; i < set.size(); ++i) out.emplace_back(idx[i], static_cast<float>(d2[i]));
  std::sort(out.begin(), out.end(), ByDistThenIndex);
  return out;
}

bool KdTree::Nearest(const Eigen::Vector3f& q, std::uint32_t* index, float* sq_dist) const {
  if (size() == 0) return false;
  std::uint32_t idx = 0;
  double d2 = 0;
  nanoflann::KNNResultSet<double, std::uint32_t, std::size_t> set(1);
  set.init(&idx, &d2);
  impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
  if (set.size() == 0) return false;
  if (index) *index = idx;
  if (sq_dist) *sq_dist = static_cast<float>(d2);
  return true;
}

std::vector<std::pair<std::uint32_t, float>> KdTree::Radius(const Eigen::Vector3f& q,
                                                             float radius) const {
  std::vector<std::pair<std::uint32_t, float>> out;
  if (size() == 0 || !(radius > 0.f)) return out;
  RadiusSet set(double(radius) * double(radius), &out);
  impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
  std::sort(out.begin(), out.end(), ByDistThenIndex);
  return out;
}

std::size_t KdTree::CountWithin(const Eigen::Vector3f& q, float radius, std::size_t max_count) const {
  if (size() == 0 || !(radius > 0.f) || max_count == 0) return 0;
  CountSet set(double(radius) * double(radius), max_count);
  impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
  return set.size();
}

}  // namespace ltm::geometry
