// ltmapper geometry: voxel downsampling, kd-tree, transforms, range filtering, range images.
// Depends on core, Eigen, TBB and nanoflann (nanoflann and TBB only inside the .cpp files).
// Functions that run in parallel take the thread count as an argument (0 = all cores); nothing
// sets a process-wide thread limit.
#pragma once

#include "ltmapper/core/core.hpp"
#include "ltmapper/geometry/sensor.hpp"  // SensorModel: beam tables, presets, estimation

#include <array>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

namespace ltm::geometry {

// ------------------------------------------------------------------------------ transforms
// p' = T * p for every point; optional arrays are kept.
PointCloud Transform(const PointCloud& cloud, const Pose& T);
void TransformInPlace(PointCloud& cloud, const Pose& T);
// Keeps points with min_range <= |p| <= max_range [m] (range measured from the origin).
PointCloud RangeFilter(const PointCloud& cloud, double min_range_m, double max_range_m);
// Keeps points inside the axis-aligned box [lo, hi].
PointCloud CropBox(const PointCloud& cloud, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);
// Drops NaN / Inf points; returns how many were dropped.
std::size_t RemoveNonFinite(PointCloud& cloud);

// -------------------------------------------------------------------------- voxel downsampling
// One point per occupied voxel of edge `voxel_m`: the centroid of its points (intensity
// averaged too). Optional arrays take the value of the voxel's first point (lowest index).
// Non-finite points are ignored. Voxel index = floor(coordinate / voxel_m). Sums are in double
// and in point-index order, so the output is bit-identical for any thread count. Output order is
// deterministic (sorted by voxel key) whatever the thread count.
PointCloud VoxelDownsample(const PointCloud& cloud, double voxel_m, int threads = 0);
// The same result for a concatenation of VoxelDownsample outputs (same voxel), the i-th starting
// at run_starts[i] (ascending from 0): their voxel-ordered runs are merged instead of sorted
// again. Runs out of voxel order are sorted as VoxelDownsample would.
PointCloud VoxelDownsampleRuns(const PointCloud& cloud, const std::vector<std::size_t>& run_starts, double voxel_m,
                               int threads = 0);

// ----------------------------------------------------------------------------------- kd-tree
// nanoflann kd-tree over a cloud's xyz. Owns a copy of the cloud or shares it. The cloud must be
// finite (ltm::Error otherwise: see RemoveNonFinite). Distances are computed in double and
// returned as float; "within radius" means squared distance < radius^2 (strict). Equal
// distances are ordered by index. A cloud of more than `block_points` points (0 = 131072) is cut
// into blocks of at most that many, each its own tree, built on `threads` cores; results do not
// depend on `threads` (Knn may pick another of several points at exactly the k-th distance than
// one tree would).
class KdTree {
 public:
  explicit KdTree(PointCloud cloud, int threads = 1, std::size_t block_points = 0);  // owns
  explicit KdTree(std::shared_ptr<const PointCloud> cloud, int threads = 1,
                  std::size_t block_points = 0);  // shares
  ~KdTree();
  KdTree(KdTree&&) noexcept;
  KdTree& operator=(KdTree&&) noexcept;

  const PointCloud& cloud() const;
  std::size_t size() const;
  // k nearest neighbours: (index, squared distance) sorted by distance; fewer when the cloud
  // has fewer than k points.
  std::vector<std::pair<std::uint32_t, float>> Knn(const Eigen::Vector3f& q, std::size_t k) const;
  // Nearest neighbour; returns false when the cloud is empty.
  bool Nearest(const Eigen::Vector3f& q, std::uint32_t* index, float* sq_dist) const;
  // All points within `radius` [m]: (index, squared distance) sorted by distance.
  std::vector<std::pair<std::uint32_t, float>> Radius(const Eigen::Vector3f& q, float radius) const;
  // The same points in the tree's order (the same for the same cloud): cheaper where only the set
  // matters (clustering: sorting was a third of its time).
  std::vector<std::pair<std::uint32_t, float>> RadiusUnsorted(const Eigen::Vector3f& q, float radius) const;
  // Number of points within `radius`, stopping early once `max_count` is reached.
  std::size_t CountWithin(const Eigen::Vector3f& q, float radius, std::size_t max_count) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ------------------------------------------------------------------------ points near a set
// A set of 63-bit keys (open addressing, splitmix64 hash); all ones is never a key (keys pack
// three 21-bit fields).
class KeySet {
 public:
  explicit KeySet(std::size_t expected = 0);
  void Insert(std::uint64_t key);
  bool Contains(std::uint64_t key) const;
  std::size_t size() const { return count_; }

 private:
  void Grow();
  std::vector<std::uint64_t> slots_;  // all ones = empty
  std::size_t mask_ = 0, count_ = 0;
};

// Whether a point lies within `radius` (inclusive, in the points' unit) of a set of points: the
// set in a hash grid of radius-sized cells, a point asked looks at the 27 cells around its own.
// `lookups` is about how many points will be asked: when the set occupies few cells against it
// (a keyframe's changes against its map), the cells near the set are marked first, so that a point
// far from the set costs one lookup instead of 27. The answer is the same either way. Near() is
// const and may be called from several threads.
class RadiusIndex {
 public:
  RadiusIndex(std::vector<Eigen::Vector3d> set, double radius, std::size_t lookups);
  bool Near(const Eigen::Vector3d& p) const;

 private:
  using Cell = std::array<std::int64_t, 3>;  // cell indices along x, y, z
  Cell CellOf(const Eigen::Vector3d& p) const;
  static std::uint64_t Key(const Cell& c, int dx, int dy, int dz);  // of the cell c + (dx, dy, dz)
  std::vector<Eigen::Vector3d> set_;
  double cell_, r2_;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid_;
  bool prefilter_ = false;
  KeySet near_cells_;
};
// The mask of `cloud`'s points within `radius_m` (inclusive) of a point of `query`.
std::vector<bool> WithinRadius(const PointCloud& cloud, const PointCloud& query, double radius_m, int threads = 1);

// ------------------------------------------------------------------------------- clusters
// Euclidean clusters: points closer than `gap_m` [m] (strict, as KdTree::Radius) are in one
// cluster, transitively. Returns each point's cluster number, 0 .. clusters - 1, numbered in the
// order of their lowest point index (deterministic, whatever `threads`). Non-finite points:
// ltm::Error (KdTree).
std::vector<std::uint32_t> EuclideanClusters(const PointCloud& cloud, double gap_m, int threads = 1);
// The same clusters as point indices: cluster k's points in ascending order, the clusters in
// EuclideanClusters' numbering (none for an empty cloud).
std::vector<std::vector<std::uint32_t>> EuclideanClusterMembers(const PointCloud& cloud, double gap_m, int threads = 1);
// Clusters with gaps per point, for surfaces a sensor samples in rows and columns far apart:
// points i and j join when (horizontal distance / gh)^2 + (dz / gv)^2 < 1, gh and gv the smaller
// of the two points' gaps (gaps[i] = {horizontal, vertical} [m], both > 0; gaps.size() ==
// cloud.size(), else ltm::Error). With every gap {g, g}, the same clusters as above with gap g.
std::vector<std::vector<std::uint32_t>> EuclideanClusterMembers(const PointCloud& cloud,
                                                                const std::vector<Eigen::Vector2f>& gaps, int threads = 1);
// The gaps {horizontal, vertical} [m] that still join a far surface's samples into one cluster at
// `range_m`, for a sensor sampling columns `azimuth_step_deg` and rows `vertical_step_deg` apart:
// r * step, up to twice that on a surface seen at up to 60 deg incidence (1 / cos 60 deg).
Eigen::Vector2f SampleJoinGaps(double azimuth_step_deg, double vertical_step_deg, double range_m);
// The xy-oriented box of cloud[idx] (all points when idx is empty): its major axis the principal
// axis of the points' x, y spread (2x2 covariance about their mean), at yaw_rad; the minor axis
// 90 deg counter-clockwise from it; the box's xy centre and its extents along the two axes [m].
struct HorizontalBox {
  double yaw_rad = 0.0;
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double length = 0.0, width = 0.0;  // along the major / minor axis
};
HorizontalBox HorizontalBoxOf(const PointCloud& cloud, const std::vector<std::uint32_t>& idx = {});
// The xy rectangle around cloud[idx] (all points when idx is empty) whose sides the points lie
// closest to: of the rectangles along the edges of the points' convex hull, the one with the least
// mean distance from a point to its nearest side (ties: the smaller area); the major axis is the
// longer side. A box scanned from outside has its points on one or two of its faces (an L): the
// rectangle along those faces has them on its sides, where the principal axes of HorizontalBoxOf
// run diagonal to the box and the smallest-area rectangle of an L's triangular hull may too.
HorizontalBox SidesBoxOf(const PointCloud& cloud, const std::vector<std::uint32_t>& idx = {});
// HorizontalBoxOf's longest edge [m]; 0 for fewer than two points.
double LongestHorizontalEdge(const PointCloud& cloud, const std::vector<std::uint32_t>& idx);

// The lowest z per square xy cell of edge cell_m (cell floor(x / cell_m), floor(y / cell_m)) of
// the clouds added: the local ground, where they have it. cell_m <= 0: always empty.
class LowestGrid {
 public:
  explicit LowestGrid(double cell_m) : cell_m_(cell_m) {}
  void Add(const PointCloud& cloud);
  void Add(const LowestGrid& other);  // the lower of both per cell (same cell_m)
  // Only some places wanted: Watch the cells overlapping the xy box [lo, hi] grown by `grow` cells,
  // then AddWatched(cloud) lowers those cells only (a whole map's points, few cells hashed).
  void Watch(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int grow = 0);
  void AddWatched(const PointCloud& cloud);
  bool empty() const { return z_.empty(); }
  double cell_m() const { return cell_m_; }
  // The lowest z of p's cell; false where no point fell in it (or it is watched and none did).
  bool At(const Eigen::Vector3f& p, float* z) const;
  // The lowest z over the cells overlapping the xy box [lo, hi] grown by `grow` cells on each
  // side; +inf where none has a point.
  float Under(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int grow = 0) const;

 private:
  std::int64_t Cell(double v) const;  // the cell index along one axis
  static std::int64_t Pack(std::int64_t ix, std::int64_t iy);
  double cell_m_;
  std::unordered_map<std::int64_t, float> z_;
};

// ------------------------------------------------------------------------------ range images
// Spherical projection of a spinning LiDAR. Rows span the vertical FOV (row 0 = top), columns
// the full 360 deg (column 0 at azimuth +180 deg, increasing clockwise seen from above, i.e.
// with decreasing azimuth atan2(y, x)).
struct RangeImageConfig {
  double fov_up_deg = 2.0;       // [deg] upper edge of the vertical FOV
  double fov_down_deg = -24.8;   // [deg] lower edge (negative = below the horizon)
  int rows = 64;                 // pixels over the vertical FOV
  int cols = 900;                // pixels over 360 deg
};

class RangeImage {
 public:
  RangeImage() : RangeImage(RangeImageConfig{}) {}
  // Throws ltm::Error when rows/cols < 1 or fov_up_deg <= fov_down_deg.
  explicit RangeImage(const RangeImageConfig& cfg);
  const RangeImageConfig& config() const { return cfg_; }
  int rows() const { return cfg_.rows; }
  int cols() const { return cfg_.cols; }
  // Pixel of a point in the sensor frame; false when outside the vertical FOV or at range ~0.
  bool Project(const Eigen::Vector3f& p, int* row, int* col, float* range) const;
  // Pixel rule: row = floor((fov_up - pitch) / fov * rows) (pitch = asin(z/|p|); a point exactly
  // on the lower edge goes to the last row), col = floor((pi - atan2(y, x)) / (2 pi) * cols)
  // wrapped into [0, cols). Straight ahead (+x) is column cols/2, straight behind column 0.
  // Resets to "no return" (+inf) and projects `cloud` (sensor frame), keeping the minimum range
  // per pixel. Also records, per pixel, the index of the point that won (-1 = none).
  void Build(const PointCloud& cloud);
  float At(int row, int col) const { return range_[std::size_t(row) * cfg_.cols + col]; }
  int IndexAt(int row, int col) const { return index_[std::size_t(row) * cfg_.cols + col]; }
  const std::vector<float>& data() const { return range_; }

 private:
  RangeImageConfig cfg_;
  double up_rad_ = 0, down_rad_ = 0, fov_rad_ = 0;
  float up_f_ = 0.f, down_f_ = 0.f;    // [rad] FOV edges as floats for the hot loop
  float row_scale_ = 0.f;              // rows / fov [1/rad]
  float col_scale_ = 0.f;              // cols / (2 pi) [1/rad]
  std::vector<float> range_;
  std::vector<int> index_;
};

}  // namespace ltm::geometry
