// KdTree: nanoflann (1.4.x API) over the xyz of a PointCloud.
// Distances are accumulated in double (float coordinates, float differences, double squares),
// so clouds far from the origin (+-1e6 m) still get exact neighbour sets; results are returned
// as float squared distances, ordered by (distance, index) (RadiusUnsorted: the tree's order).
//
// A large cloud is a forest: median splits along the widest axis (the top of a kd-tree) cut it
// into blocks of at most `block_points`, and each block gets its own nanoflann tree, the blocks
// built in parallel (nanoflann 1.4 builds one tree on one core: a 3.4 M-point map took 0.5 s
// while every other core waited, issue 18). Queries visit the blocks whose box reaches the query,
// so radius and count results are the exact sets of one tree. The cut depends on the points
// alone, never on the thread count.
#include "ltmapper/geometry/geometry.hpp"

#include <nanoflann.hpp>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
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

namespace {

constexpr std::size_t kBlockPoints = std::size_t(1) << 17;  // default block size (build time only)

using Xyz = std::array<float, 3>;

// nanoflann dataset adaptor over a block's own copy of its points.
struct BlockAdaptor {
  const std::vector<Xyz>* xyz = nullptr;
  std::size_t kdtree_get_point_count() const { return xyz->size(); }
  float kdtree_get_pt(std::uint32_t idx, std::size_t dim) const { return (*xyz)[idx][dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};
using BlockMetric = nanoflann::L2_Simple_Adaptor<float, BlockAdaptor, double, std::uint32_t>;
using BlockTree = nanoflann::KDTreeSingleIndexAdaptor<BlockMetric, BlockAdaptor, 3, std::uint32_t>;

// Squared distance from q to the box [lo, hi], a lower bound of every inside point's: the same
// float differences as the metric (rounding is monotonic), squared and summed in double.
double BoxDist2(const Xyz& lo, const Xyz& hi, const float* q) {
  double s = 0.0;
  for (int d = 0; d < 3; ++d) {
    const float diff = q[d] < lo[d] ? lo[d] - q[d] : (q[d] > hi[d] ? q[d] - hi[d] : 0.f);
    s += double(diff) * double(diff);
  }
  return s;
}

// One block of a forest: its points (copied, in block order), their cloud indices, its box.
struct Block {
  std::vector<Xyz> xyz;
  std::vector<std::uint32_t> ids;
  Xyz lo{}, hi{};
  BlockAdaptor adaptor;
  std::unique_ptr<BlockTree> tree;
};

// The cut as a tree: a leaf is a block; an inner node's box holds its two children's.
struct Node {
  Xyz lo{}, hi{};
  int left = -1, right = -1, block = -1;
};

// Cuts order[b, e) at its median along the widest axis of its points until every range holds at
// most `block` points; appends the ranges in order. Ties on the axis go by index, so the cut is
// the same whatever the thread count.
void CutIntoBlocks(const PointCloud& c, std::uint32_t* b, std::uint32_t* e, std::size_t block,
                   std::vector<std::pair<std::uint32_t*, std::uint32_t*>>* out) {
  if (std::size_t(e - b) <= block) {
    out->emplace_back(b, e);
    return;
  }
  Xyz lo{c.points[*b].x, c.points[*b].y, c.points[*b].z}, hi = lo;
  for (const std::uint32_t* i = b; i != e; ++i) {
    const PointXYZI& p = c.points[*i];
    const Xyz v{p.x, p.y, p.z};
    for (int d = 0; d < 3; ++d) lo[d] = std::min(lo[d], v[d]), hi[d] = std::max(hi[d], v[d]);
  }
  int axis = 0;
  for (int d = 1; d < 3; ++d)
    if (double(hi[d]) - lo[d] > double(hi[axis]) - lo[axis]) axis = d;
  auto coord = [&](std::uint32_t i) { return axis == 0 ? c.points[i].x : (axis == 1 ? c.points[i].y : c.points[i].z); };
  std::uint32_t* mid = b + (e - b) / 2;
  std::nth_element(b, mid, e, [&](std::uint32_t x, std::uint32_t y) {
    const float cx = coord(x), cy = coord(y);
    return cx != cy ? cx < cy : x < y;
  });
  std::vector<std::pair<std::uint32_t*, std::uint32_t*>> left, right;
  tbb::parallel_invoke([&] { CutIntoBlocks(c, b, mid, block, &left); },
                       [&] { CutIntoBlocks(c, mid, e, block, &right); });
  out->insert(out->end(), left.begin(), left.end());
  out->insert(out->end(), right.begin(), right.end());
}

std::unique_ptr<Block> MakeBlock(const PointCloud& c, const std::uint32_t* b, const std::uint32_t* e) {
  auto blk = std::make_unique<Block>();
  blk->ids.assign(b, e);
  blk->xyz.reserve(blk->ids.size());
  for (const std::uint32_t i : blk->ids) blk->xyz.push_back({c.points[i].x, c.points[i].y, c.points[i].z});
  blk->lo = blk->hi = blk->xyz.front();
  for (const Xyz& v : blk->xyz)
    for (int d = 0; d < 3; ++d) blk->lo[d] = std::min(blk->lo[d], v[d]), blk->hi[d] = std::max(blk->hi[d], v[d]);
  blk->adaptor.xyz = &blk->xyz;
  blk->tree = std::make_unique<BlockTree>(3, blk->adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafMaxSize));
  return blk;
}

}  // namespace

struct KdTree::Impl {
  std::shared_ptr<const PointCloud> cloud;
  CloudAdaptor adaptor;
  std::unique_ptr<Tree> tree;                // one tree over the cloud itself (small clouds), or
  std::vector<std::unique_ptr<Block>> blocks;  // a forest, and its cut
  std::vector<Node> nodes;

  Impl(std::shared_ptr<const PointCloud> c, int threads, std::size_t block_points) : cloud(std::move(c)) {
    if (!cloud) throw Error("KdTree: null cloud");
    if (cloud->size() >= std::numeric_limits<std::uint32_t>::max())
      throw Error("KdTree: more than 2^32 - 1 points");
    for (std::size_t i = 0; i < cloud->size(); ++i) {
      const PointXYZI& p = cloud->points[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw Error("KdTree: point " + std::to_string(i) + " is not finite (use RemoveNonFinite)");
    }
    const std::size_t block = block_points > 0 ? block_points : kBlockPoints;
    if (cloud->size() <= block) {
      adaptor.cloud = cloud.get();
      tree = std::make_unique<Tree>(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafMaxSize));
      return;
    }
    std::vector<std::uint32_t> order(cloud->size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = std::uint32_t(i);
    std::vector<std::pair<std::uint32_t*, std::uint32_t*>> ranges;
    ParallelFor(1, threads, [&](std::size_t) {  // the arena bounds the cut's parallel halves
      CutIntoBlocks(*cloud, order.data(), order.data() + order.size(), block, &ranges);
    });
    blocks.resize(ranges.size());
    ParallelFor(ranges.size(), threads, [&](std::size_t k) { blocks[k] = MakeBlock(*cloud, ranges[k].first, ranges[k].second); });
    int next_block = 0;
    AddNode(cloud->size(), block, &next_block);
  }

  // The node of a range of `size` points cut as CutIntoBlocks cuts (halves until at most
  // `block`; leaves numbered in order) and its subtree; returns its index.
  int AddNode(std::size_t size, std::size_t block, int* next_block) {
    const int self = int(nodes.size());
    nodes.emplace_back();
    if (size <= block) {
      const Block& b = *blocks[std::size_t((*next_block)++)];
      nodes[std::size_t(self)].block = *next_block - 1;
      nodes[std::size_t(self)].lo = b.lo, nodes[std::size_t(self)].hi = b.hi;
      return self;
    }
    const int left = AddNode(size / 2, block, next_block), right = AddNode(size - size / 2, block, next_block);
    Node& n = nodes[std::size_t(self)];
    n.left = left, n.right = right;
    for (int d = 0; d < 3; ++d) {
      n.lo[d] = std::min(nodes[std::size_t(left)].lo[d], nodes[std::size_t(right)].lo[d]);
      n.hi[d] = std::max(nodes[std::size_t(left)].hi[d], nodes[std::size_t(right)].hi[d]);
    }
    return self;
  }

  // f(block) for every block whose box is nearer q than `limit2()` (read at each node), until
  // f returns false.
  template <class Limit, class F>
  void Visit(const float* q, const Limit& limit2, const F& f) const {
    int stack[64];  // the cut halves the points at every level: depth < 32
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const Node& n = nodes[std::size_t(stack[--top])];
      if (BoxDist2(n.lo, n.hi, q) >= limit2()) continue;
      if (n.block >= 0) {
        if (!f(n.block)) return;
      } else {
        stack[top++] = n.right;
        stack[top++] = n.left;
      }
    }
  }

  // The leaf whose box holds q, down the cut (-1 when none does).
  int Home(const float* q) const {
    auto holds = [q](const Node& n) {
      return n.lo[0] <= q[0] && q[0] <= n.hi[0] && n.lo[1] <= q[1] && q[1] <= n.hi[1] && n.lo[2] <= q[2] &&
             q[2] <= n.hi[2];
    };
    std::size_t at = 0;
    if (!holds(nodes[at])) return -1;
    while (nodes[at].block < 0) {
      const Node &l = nodes[std::size_t(nodes[at].left)], &r = nodes[std::size_t(nodes[at].right)];
      if (holds(l)) at = std::size_t(nodes[at].left);
      else if (holds(r)) at = std::size_t(nodes[at].right);
      else return -1;
    }
    return int(at);
  }

  // Whether no point outside leaf `node` can be nearer q than sqrt(d2): q's margin to the leaf
  // box's faces exceeds it, by more than the metric's float rounding (2^-23 relative in d2).
  bool Inside(int node, const float* q, double d2) const {
    const Node& n = nodes[std::size_t(node)];
    double m = std::numeric_limits<double>::infinity();
    for (int d = 0; d < 3; ++d) m = std::min({m, double(q[d]) - n.lo[d], double(n.hi[d]) - q[d]});
    return m * m > d2 * (1.0 + 1e-6);
  }

  // f(block) for the blocks that may hold points nearer q than sqrt(r2): only q's own leaf when
  // that ball lies inside its box (most queries), else every block whose box is nearer.
  template <class F>
  void VisitWithin(const float* q, double r2, const F& f) const {
    const int home = Home(q);
    if (home >= 0 && Inside(home, q, r2)) {
      f(nodes[std::size_t(home)].block);
      return;
    }
    Visit(q, [r2] { return r2; }, f);
  }

  // The forest's k nearest (global index, double squared distance), best first by (distance,
  // index): the block the query falls in (or the nearer child at every node) first, then every
  // block whose box is not farther than the k-th found.
  std::vector<std::pair<std::uint32_t, double>> ForestKnn(const float* q, std::size_t k) const {
    int home = Home(q);
    std::size_t at = home >= 0 ? std::size_t(home) : 0;
    while (nodes[at].block < 0) {
      const Node &l = nodes[std::size_t(nodes[at].left)], &r = nodes[std::size_t(nodes[at].right)];
      at = std::size_t(BoxDist2(l.lo, l.hi, q) <= BoxDist2(r.lo, r.hi, q) ? nodes[at].left : nodes[at].right);
    }
    const int first = nodes[at].block;
    std::vector<std::pair<std::uint32_t, double>> best;
    std::vector<std::uint32_t> idx(k);
    std::vector<double> d2(k);
    auto add = [&](int b) {
      const Block& blk = *blocks[std::size_t(b)];
      nanoflann::KNNResultSet<double, std::uint32_t, std::size_t> set(std::min(k, blk.xyz.size()));
      set.init(idx.data(), d2.data());
      blk.tree->findNeighbors(set, q, nanoflann::SearchParams());
      for (std::size_t i = 0; i < set.size(); ++i) best.emplace_back(blk.ids[idx[i]], d2[i]);
      std::sort(best.begin(), best.end(), [](const auto& a, const auto& c) {
        return a.second != c.second ? a.second < c.second : a.first < c.first;
      });
      if (best.size() > k) best.resize(k);
    };
    add(first);
    if (best.size() == k && home >= 0 && Inside(home, q, best.back().second)) return best;
    const double inf = std::numeric_limits<double>::infinity();
    // Not farther than the k-th: `>=` prunes, so a box at exactly the k-th distance is still read.
    Visit(q, [&] { return best.size() < k ? inf : std::nextafter(best.back().second, inf); },
          [&](int b) {
            if (b != first) add(b);
            return true;
          });
    return best;
  }
};

KdTree::KdTree(PointCloud cloud, int threads, std::size_t block_points)
    : impl_(std::make_unique<Impl>(std::make_shared<const PointCloud>(std::move(cloud)), threads, block_points)) {}
KdTree::KdTree(std::shared_ptr<const PointCloud> cloud, int threads, std::size_t block_points)
    : impl_(std::make_unique<Impl>(std::move(cloud), threads, block_points)) {}
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
  if (!impl_->tree) {
    for (const auto& [i, d2] : impl_->ForestKnn(q.data(), k)) out.emplace_back(i, static_cast<float>(d2));
    std::sort(out.begin(), out.end(), ByDistThenIndex);
    return out;
  }
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
  if (!impl_->tree) {
    const auto best = impl_->ForestKnn(q.data(), 1);
    idx = best.front().first, d2 = best.front().second;
  } else {
    nanoflann::KNNResultSet<double, std::uint32_t, std::size_t> set(1);
    set.init(&idx, &d2);
    impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
    if (set.size() == 0) return false;
  }
  if (index) *index = idx;
  if (sq_dist) *sq_dist = static_cast<float>(d2);
  return true;
}

std::vector<std::pair<std::uint32_t, float>> KdTree::Radius(const Eigen::Vector3f& q,
                                                             float radius) const {
  std::vector<std::pair<std::uint32_t, float>> out = RadiusUnsorted(q, radius);
  std::sort(out.begin(), out.end(), ByDistThenIndex);
  return out;
}

std::vector<std::pair<std::uint32_t, float>> KdTree::RadiusUnsorted(const Eigen::Vector3f& q,
                                                                     float radius) const {
  std::vector<std::pair<std::uint32_t, float>> out;
  if (size() == 0 || !(radius > 0.f)) return out;
  const double r2 = double(radius) * double(radius);
  if (impl_->tree) {
    RadiusSet set(r2, &out);
    impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
  }
  if (!impl_->blocks.empty())
    impl_->VisitWithin(q.data(), r2, [&](int b) {
      const Block& blk = *impl_->blocks[std::size_t(b)];
      const std::size_t from = out.size();
      RadiusSet set(r2, &out);
      blk.tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
      for (std::size_t i = from; i < out.size(); ++i) out[i].first = blk.ids[out[i].first];
      return true;
    });
  return out;
}

std::size_t KdTree::CountWithin(const Eigen::Vector3f& q, float radius, std::size_t max_count) const {
  if (size() == 0 || !(radius > 0.f) || max_count == 0) return 0;
  const double r2 = double(radius) * double(radius);
  if (impl_->tree) {
    CountSet set(r2, max_count);
    impl_->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
    return set.size();
  }
  std::size_t count = 0;
  impl_->VisitWithin(q.data(), r2, [&](int b) {
    CountSet set(r2, max_count - count);
    impl_->blocks[std::size_t(b)]->tree->findNeighbors(set, q.data(), nanoflann::SearchParams());
    count += set.size();
    return count < max_count;
  });
  return count;
}

}  // namespace ltm::geometry
