// Private helpers of the removert module (not installed, not included outside this folder).
#pragma once

#include "ltmapper/removert/removert.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Core>

#include <algorithm>
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
// point. Min range per pixel, +inf = no return. Build() reuses the buffers, so one image per
// worker serves all its keyframes.
class MultiResImage {
 public:
  // keep_returns: Build() also keeps each pixel's nearest return (sensor frame, Returns()).
  // within_beams: points are judged only within the beams' span (PointBounds; HD removal), else
  // anywhere in the images' FOV (LD: a change above the top beam is still judged by it).
  MultiResImage(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg, bool keep_returns = false,
                bool within_beams = false);
  // Projects a scan (sensor frame); returns within [min_range, max_range] only. Then each
  // level's min-pooled twin: the min over the (2w+1) x (2w+1) window centred on each pixel
  // (columns wrap around), w = window_px.
  void Build(const PointCloud& scan);
  int levels() const { return int(levels_.size()); }
  // Angles of a scan return (sensor frame). False when outside the images' vertical FOV or at
  // ~0 range. Project() and Build() evaluate the same float operations four points at a time
  // (SSE2): keep them in step.
  bool Angles(const Eigen::Vector3f& p, float* range, float* pitch, float* yaw) const {
    return AnglesWithin(p, up_, down_, range, pitch, yaw);
  }
  // The same for a point to judge: within the beams' span (PointBounds), else false.
  bool PointAngles(const Eigen::Vector3f& p, float* range, float* pitch, float* yaw) const {
    return AnglesWithin(p, point_up_, point_down_, range, pitch, yaw);
  }
  // The points (x[i], y[i], z[i]) (world frame; readable up to n + 3: batches of four) within
  // 3D distance sqrt(radius2) of the sensor position c, moved into the sensor frame
  // (Rt (p - c)), whose PointAngles() are valid: returns how many; their input positions go to
  // idx[0, count) and their Angles() to range / pitch / yaw[0, count) (n long each). Batches of
  // four (SSE2) use the same float operations in the same order as the scalar code (Eigen's
  // products included), so the results are identical.
  std::size_t Project(const float* x, const float* y, const float* z, std::size_t n,
                      const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, float radius2,
                      std::uint32_t* idx, float* range, float* pitch, float* yaw) const;
  // One level's pixel rule, small enough for hot loops to keep in registers.
  struct Grid {
    int rows = 0, cols = 0;
    float row_scale = 0.f, col_scale = 0.f;  // pixels per rad
    float up = 0.f;                          // [rad] top of the FOV
    // rows x cols pixels of row_deg x col_deg over the config's vertical FOV and 360 deg.
    static Grid Make(const RemovertConfig& cfg, double row_deg, double col_deg);
    int Row(float pitch) const {
      int row = int((up - pitch) * row_scale);
      if (row >= rows) row = rows - 1;
      if (row < 0) row = 0;
      return row;
    }
    int Col(float yaw) const {
      int col = int((kPiF - yaw) * col_scale);
      if (col >= cols) col -= cols;
      if (col < 0) col = 0;
      return col;
    }
    std::size_t Pixel(float pitch, float yaw) const {
      return std::size_t(Row(pitch)) * std::size_t(cols) + std::size_t(Col(yaw));
    }
  };
  const Grid& GridOf(int level) const { return levels_[std::size_t(level)].grid; }
  std::size_t Pixel(int level, float pitch, float yaw) const { return GridOf(level).Pixel(pitch, yaw); }
  // (pooled, range) of each pixel side by side: the vote test reads both, from one cache line.
  const float* Pairs(int level) const { return levels_[std::size_t(level)].pairs.data(); }
  // Per pixel, the sensor-frame position of its nearest return (only with keep_returns; valid
  // where the pixel has a return).
  const Eigen::Vector3f* Returns(int level) const { return levels_[std::size_t(level)].ret.data(); }
  int Cols(int level) const { return GridOf(level).cols; }

 private:
  static bool AnglesWithin(const Eigen::Vector3f& p, float up, float down, float* range, float* pitch, float* yaw) {
    const float rxy2 = p.x() * p.x() + p.y() * p.y();
    const float r = std::sqrt(rxy2 + p.z() * p.z());
    if (!(r > 1e-6f)) return false;
    const float pt = FastAtan2(p.z(), std::sqrt(rxy2));
    if (pt > up || pt < down) return false;
    *range = r;
    *pitch = pt;
    *yaw = FastAtan2(p.y(), p.x());
    return true;
  }
  // [rad] The elevations a point may have to be judged (point_up_, point_down_): a ring sensor's
  // outermost beams widened by their scatter (SensorModel::spread_deg). Beyond them no ray passes
  // on the far side of a point: the one beam on its near side returning farther (grazing ground
  // below the lowest beam of a tilted sensor) is no evidence that its place is free. Without
  // rings (or a resolved sensor) the images' FOV.
  void PointBounds(const RemovertConfig& cfg);
  static std::vector<int> WindowRows(const RemovertConfig& cfg, int rows, double row_deg);
  struct Level {
    Grid grid;
    std::vector<int> window_rows;  // per row: how far the pool looks for the nearest beam (WindowRows)
    int scatter_rows = 0;          // rows within the beams' estimated scatter: pooled whole
    bool both_sides = false;       // no rings: evidence only with a return above and below
    std::vector<std::uint8_t> sides;
    std::vector<float> range, pooled, tmp, pairs;
    std::vector<Eigen::Vector3f> ret;  // keep_returns
  };
  void Pool(Level& L) const;         // PoolColumns then PoolRows (or a copy when window_px is 0)
  void PoolColumns(Level& L) const;  // horizontal min over +-window_px columns into tmp
  void PoolRows(Level& L) const;     // vertical: scatter rows whole, then the nearest beam above / below
  bool keep_returns_ = false;
  int window_ = 0;
  float up_ = 0.f, down_ = 0.f;              // [rad] the images' vertical FOV (scan returns)
  float point_up_ = 0.f, point_down_ = 0.f;  // [rad] points judged (PointBounds)
  float min_range_ = 0.f, max_range_ = 0.f;
  std::vector<Level> levels_;
};

// A scan's nearest return per (column, row) cell of BeamTest::col_deg x row_deg, stored column
// by column: rows far finer than the beam spacing, so the rows between two beams stay empty and
// the first returns above and below a direction are the two beams around it.
class ColumnImage {
 public:
  ColumnImage(const RemovertConfig& cfg, const BeamTest& test);
  void Build(const PointCloud& scan);
  // BeamTest for a point ps (sensor frame; its range, pitch and yaw as MultiResImage::Angles
  // gives them) on the plane n . x = off (plane[0..3], sensor frame).
  bool Observed(float range, float pitch, float yaw, const Eigen::Vector3f& ps, const float* plane) const;

 private:
  BeamTest test_;
  MultiResImage::Grid grid_;  // cells stored column by column: [col * rows + row]
  std::vector<int> span_;     // [rows] per row: how far above / below to look for the beams
  float down_ = 0.f;          // [rad]
  float min_range_ = 0.f, max_range_ = 0.f;
  std::vector<float> range_;          // +inf = no return
  std::vector<Eigen::Vector3f> ret_;  // the cell's nearest return
};

// 2D tile index over a cloud's xy: points sorted by tile, each tile a contiguous range.
// Coordinates are kept as separate x / y / z arrays (plus 3 padding entries, so batches of four
// may read past a tile's end).
class TileIndex {
 public:
  TileIndex(const PointCloud& cloud, double tile_m);
  // order()[k] = index into the original cloud of the k-th sorted point.
  const std::vector<std::uint32_t>& order() const { return order_; }
  const float* x() const { return x_.data(); }
  const float* y() const { return y_.data(); }
  const float* z() const { return z_.data(); }
  std::size_t tiles() const { return ranges_.size(); }
  // Calls f(tile, begin, end) (tile id in [0, tiles()), sorted positions [begin, end)) for every
  // tile within `radius` (2D) of `c`.
  template <class F>
  void ForTilesNear(const Eigen::Vector3f& c, float radius, F&& f) const {
    const double t = tile_m_;
    const std::int32_t x0 = std::int32_t(std::floor((c.x() - radius) / t));
    const std::int32_t x1 = std::int32_t(std::floor((c.x() + radius) / t));
    const std::int32_t y0 = std::int32_t(std::floor((c.y() - radius) / t));
    const std::int32_t y1 = std::int32_t(std::floor((c.y() + radius) / t));
    const double r2 = double(radius) * radius;
    for (std::int32_t ix = x0; ix <= x1; ++ix) {
      for (std::int32_t iy = y0; iy <= y1; ++iy) {
        // Distance from c to the tile's rectangle.
        const double dx = std::max({ix * t - c.x(), 0.0, c.x() - (ix + 1) * t});
        const double dy = std::max({iy * t - c.y(), 0.0, c.y() - (iy + 1) * t});
        if (dx * dx + dy * dy > r2) continue;
        auto it = tiles_.find(Key(ix, iy));
        if (it == tiles_.end()) continue;
        const auto& rg = ranges_[it->second];
        f(it->second, rg.first, rg.second);
      }
    }
  }

 private:
  // The same bits as (ix << 32) ^ uint32(iy), shifted as unsigned: a negative ix is no UB.
  static std::int64_t Key(std::int32_t ix, std::int32_t iy) {
    return std::int64_t((std::uint64_t(std::int64_t(ix)) << 32) ^ std::uint64_t(std::uint32_t(iy)));
  }
  double tile_m_;
  std::vector<std::uint32_t> order_;
  std::vector<float> x_, y_, z_;
  std::unordered_map<std::int64_t, std::uint32_t> tiles_;        // key -> tile id
  std::vector<std::pair<std::uint32_t, std::uint32_t>> ranges_;  // tile id -> [begin, end)
};

// The keyframe's scan (memory or file).
std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf);

// parallel_for over [0, n) inside a task_arena of `threads` (0 = default), grain 1.
using ltm::ParallelFor;  // core.hpp

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

// The at most kNeighbourhoodPoints nearest points of `cloud` within `radius` of p: how many, their
// mean offset from p, and the eigen decomposition (ascending) of their covariance.
constexpr std::size_t kNeighbourhoodPoints = 16;
struct Neighbourhood {
  int n = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();
  Eigen::Matrix3d eigenvectors = Eigen::Matrix3d::Identity();
};
Neighbourhood FitNeighbourhood(const geometry::KdTree& tree, const PointCloud& cloud, const Eigen::Vector3f& p,
                               float radius);

// Unit normals of `points` from their neighbourhood in `map` (at most 16 nearest within
// radius_m): the PCA normal of a planar neighbourhood; for a line-like one (a far ground ring,
// a pole) the direction perpendicular to the line closest to vertical; +z with < 2 neighbours.
std::vector<Eigen::Vector3f> EstimateNormals(const PointCloud& points, const PointCloud& map,
                                             double radius_m, int threads);

// Points of `cloud` (world frame) moved into a keyframe's frame: p_local = T^-1 p.
PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor);

}  // namespace ltm::removert::detail
