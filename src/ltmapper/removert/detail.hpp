// Private helpers of the removert module (not installed, not included outside this folder).
#pragma once

#include "ltmapper/removert/removert.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <unordered_map>
#include <vector>

namespace ltm::removert::detail {

constexpr float kPiF = 3.14159265358979323846f;

// atan2 with |error| < 2e-5 rad (minimax polynomial of atan on [0, 1] plus octant folding).
// Pixels are >= 0.1 deg = 1.7e-3 rad, so at most ~1 % of points on a pixel border can land in
// the neighbouring pixel compared with std::atan2: harmless for voting, 5x faster.
inline float FastAtan2(float y, float x) {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float mx = ax > ay ? ax : ay;
  const float mn = ax > ay ? ay : ax;
  if (mx == 0.f) return 0.f;
  const float a = mn / mx;
  const float s = a * a;
  float r = ((((0.0208351f * s - 0.085133f) * s + 0.180141f) * s - 0.3302995f) * s + 0.999866f) * a;
  if (ay > ax) r = 0.5f * kPiF - r;
  if (x < 0.f) r = kPiF - r;
  return y < 0.f ? -r : r;
}

// The range image of one resolution: square pixels of `pixel_deg`, same pixel rule as
// geometry::RangeImage (row 0 = top of the FOV, column 0 at azimuth +180 deg, decreasing azimuth).
geometry::RangeImageConfig LevelConfig(const RemovertConfig& cfg, double pixel_deg);

// Range images of one scan at several resolutions, built from one (pitch, yaw) evaluation per
// point. Min range per pixel, +inf = no return.
class MultiResImage {
 public:
  MultiResImage(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg);
  // Projects a scan (sensor frame); returns within [min_range, max_range] only. Then each
  // level's min-pooled twin: the min over the (2w+1) x (2w+1) window centred on each pixel
  // (columns wrap around), w = window_px.
  void Build(const PointCloud& scan);
  int levels() const { return int(levels_.size()); }
  // Angles of a point (sensor frame). False when outside the vertical FOV or at ~0 range.
  bool Angles(const Eigen::Vector3f& p, float* range, float* pitch, float* yaw) const {
    const float rxy2 = p.x() * p.x() + p.y() * p.y();
    const float r = std::sqrt(rxy2 + p.z() * p.z());
    if (!(r > 1e-6f)) return false;
    const float pt = FastAtan2(p.z(), std::sqrt(rxy2));
    if (pt > up_ || pt < down_) return false;
    *range = r;
    *pitch = pt;
    *yaw = FastAtan2(p.y(), p.x());
    return true;
  }
  std::size_t Pixel(int level, float pitch, float yaw) const {
    const Level& L = levels_[std::size_t(level)];
    int row = int((up_ - pitch) * L.row_scale);
    if (row >= L.rows) row = L.rows - 1;
    if (row < 0) row = 0;
    int col = int((kPiF - yaw) * L.col_scale);
    if (col >= L.cols) col -= L.cols;
    if (col < 0) col = 0;
    return std::size_t(row) * std::size_t(L.cols) + std::size_t(col);
  }
  float At(int level, std::size_t pixel) const { return levels_[std::size_t(level)].range[pixel]; }
  float Pooled(int level, std::size_t pixel) const { return levels_[std::size_t(level)].pooled[pixel]; }
  int Rows(int level) const { return levels_[std::size_t(level)].rows; }
  int Cols(int level) const { return levels_[std::size_t(level)].cols; }

 private:
  struct Level {
    int rows = 0, cols = 0;
    float row_scale = 0.f, col_scale = 0.f;  // pixels per rad
    std::vector<float> range, pooled, tmp;
  };
  int window_ = 0;
  float up_ = 0.f, down_ = 0.f;  // [rad]
  float min_range_ = 0.f, max_range_ = 0.f;
  std::vector<Level> levels_;
};

// 2D tile index over a cloud's xy: points sorted by tile, each tile a contiguous range.
class TileIndex {
 public:
  TileIndex(const PointCloud& cloud, double tile_m);
  // order()[k] = index into the original cloud of the k-th sorted point.
  const std::vector<std::uint32_t>& order() const { return order_; }
  const std::vector<Eigen::Vector3f>& sorted() const { return sorted_; }
  // Calls f(begin, end) (sorted positions) for every tile within `radius` (2D) of `c`.
  void ForTilesNear(const Eigen::Vector3f& c, float radius,
                    const std::function<void(std::uint32_t, std::uint32_t)>& f) const;

 private:
  static std::int64_t Key(std::int32_t ix, std::int32_t iy) {
    return (std::int64_t(ix) << 32) ^ std::int64_t(std::uint32_t(iy));
  }
  double tile_m_;
  std::vector<std::uint32_t> order_;
  std::vector<Eigen::Vector3f> sorted_;
  std::unordered_map<std::int64_t, std::pair<std::uint32_t, std::uint32_t>> tiles_;
};

// The keyframe's scan (memory or file).
std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf);

// parallel_for over [0, n) inside a task_arena of `threads` (0 = default), grain 1.
void ParallelFor(std::size_t n, int threads, const std::function<void(std::size_t)>& f);

// Per point: keyframes see through it at any LD resolution (seen), and whether any keyframe had
// a return in the window at its pixel at all (observed) (occlusion.cpp).
// same: not seen through, and at least ld_same_min_hits keyframes hit it on its surface plane
// (the other session has this surface; its map is only sparser there). `own_map` (the map the
// points come from) gives their normals.
struct Visibility {
  std::vector<bool> seen, observed, same;
};
Visibility SeenThroughBy(const PointCloud& points, const PointCloud& own_map,
                         const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                         int threads);

// Unit normals of `points` from their neighbourhood in `map` (at most 16 nearest within
// radius_m): the PCA normal of a planar neighbourhood; for a line-like one (a far ground ring,
// a pole) the direction perpendicular to the line closest to vertical; +z with < 2 neighbours.
std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads);

// Points of `cloud` (world frame) moved into a keyframe's frame: p_local = T^-1 p.
PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor);

}  // namespace ltm::removert::detail
