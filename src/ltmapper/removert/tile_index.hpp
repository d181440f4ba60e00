// Private to the removert module (not installed): the tile index over a map's xy (visibility.cpp).
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace ltm::removert::detail {

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

}  // namespace ltm::removert::detail
