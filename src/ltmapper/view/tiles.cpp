// Tiled level of detail: the map cut into XY tiles, each filtered at a pyramid of voxels on
// demand. Tile edges are whole multiples of the coarsest voxel and every level's voxel is the
// base voxel times a power of two, so floor(x / voxel) of any level nests in the tile's cells:
// no voxel of any level straddles two tiles, and a level's tiles together equal the whole map
// filtered at that level's voxel (same centroids: a tile keeps its points in the map's order).
#include "internal.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace ltm::view {
namespace {

constexpr double kMaxTileIndex = 1.0e9;  // |ix|, |iy| beyond this do not fit the tile id
constexpr int kMaxLevels = 16;           // levels of a layer, coarse_budget's included

std::int64_t PackKey(int ix, int iy) { return (std::int64_t(ix) << 32) | std::int64_t(std::uint32_t(iy)); }

// Floor division for a negative numerator too.
std::int64_t FloorDiv(std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

int TileCells(const ViewConfig& cfg) {
  const int coarse_cells = 1 << (cfg.lod_levels - 1);  // base voxels per level-0 voxel
  const double coarse_m = cfg.base_voxel_m * coarse_cells;
  return int(std::max(1.0, std::round(cfg.tile_m / coarse_m))) * coarse_cells;
}

double LevelVoxel(const ViewConfig& cfg, int level) {
  if (level < 0 || level >= cfg.lod_levels)
    throw Error("view: level " + std::to_string(level) + " outside 0.." + std::to_string(cfg.lod_levels - 1));
  return std::ldexp(cfg.base_voxel_m, cfg.lod_levels - 1 - level);  // exact: a power-of-two scale
}

std::ptrdiff_t TiledCloud::Find(const Key& key) const {
  const auto it = std::lower_bound(keys.begin(), keys.end(), key);
  return it != keys.end() && *it == key ? it - keys.begin() : -1;
}

PointCloud TileCloud(const TiledCloud& tiles, std::size_t tile, int level) {
  const PointCloud& raw = tiles.raw.at(tile);
  return raw.empty() ? raw : geometry::VoxelDownsample(raw, tiles.levels.at(std::size_t(level)), 1);
}

std::shared_ptr<const std::string> TiledCloud::Encoded(std::size_t tile, int level, std::size_t* points) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto hit = encoded_.at(tile).at(std::size_t(level))) {
      if (points) *points = counts_[tile][std::size_t(level)];
      return hit;
    }
  }
  const PointCloud cloud = TileCloud(*this, tile, level);
  auto body = std::make_shared<const std::string>(EncodeCloud(cloud, levels[std::size_t(level)]));
  std::lock_guard<std::mutex> lock(mutex_);
  encoded_[tile][std::size_t(level)] = body;
  counts_[tile][std::size_t(level)] = cloud.size();
  if (points) *points = cloud.size();
  return body;
}

std::shared_ptr<const std::string> TiledCloud::All(int level) const {
  if (level == 0) return coarse;
  std::vector<PointCloud> parts(keys.size());
  ParallelFor(keys.size(), cfg.threads, [&](std::size_t t) { parts[t] = TileCloud(*this, t, level); });
  PointCloud all;
  for (const auto& p : parts) all.append(p);
  return std::make_shared<const std::string>(EncodeCloud(all, levels[std::size_t(level)]));
}

namespace {
constexpr std::int64_t kNoTile = std::numeric_limits<std::int64_t>::min();  // not finite: left out

TiledCloud::Key Unpack(std::int64_t k) { return {int(k >> 32), int(std::int32_t(std::uint32_t(k & 0xffffffffu)))}; }

// Tile of every point (kNoTile: not finite, left out as VoxelDownsample would); the same cell
// index as geometry::VoxelDownsample at the finest level.
std::vector<std::int64_t> PointTiles(const PointCloud& raw, const ViewConfig& cfg, int cells) {
  const std::size_t n = raw.size();
  std::vector<std::int64_t> key(n, kNoTile);
  const std::size_t chunk = 1 << 16;
  ParallelFor((n + chunk - 1) / chunk, cfg.threads, [&](std::size_t c) {
    for (std::size_t i = c * chunk; i < std::min(n, (c + 1) * chunk); ++i) {
      const PointXYZI& p = raw.points[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
      const double cx = std::floor(double(p.x) / cfg.base_voxel_m), cy = std::floor(double(p.y) / cfg.base_voxel_m);
      if (std::abs(std::floor(cx / cells)) > kMaxTileIndex || std::abs(std::floor(cy / cells)) > kMaxTileIndex)
        throw Error("view: a point at (" + std::to_string(p.x) + ", " + std::to_string(p.y) + ") is too far out to tile");
      key[i] = PackKey(int(FloorDiv(std::int64_t(cx), cells)), int(FloorDiv(std::int64_t(cy), cells)));
    }
  });
  return key;
}

// t.keys (ascending) and t.raw: every tile's points in the map's order, with their class.
void SplitIntoTiles(const PointCloud& raw, const std::vector<std::int64_t>& key, TiledCloud& t) {
  std::unordered_map<std::int64_t, std::size_t> count;
  for (std::int64_t k : key)
    if (k != kNoTile) ++count[k];
  std::vector<std::int64_t> packed;
  for (const auto& kv : count) packed.push_back(kv.first);
  std::sort(packed.begin(), packed.end(), [](std::int64_t a, std::int64_t b) { return Unpack(a) < Unpack(b); });
  std::unordered_map<std::int64_t, std::size_t> slot;
  t.raw.resize(packed.size());
  for (std::size_t s = 0; s < packed.size(); ++s) {
    slot[packed[s]] = s;
    t.keys.push_back(Unpack(packed[s]));
    t.raw[s].points.reserve(count[packed[s]]);
    t.raw[s].cls.reserve(count[packed[s]]);
  }
  const bool has_cls = raw.cls.size() == raw.size();
  for (std::size_t i = 0; i < raw.size(); ++i) {
    if (key[i] == kNoTile) continue;
    PointCloud& c = t.raw[slot[key[i]]];
    c.points.push_back(raw.points[i]);
    c.cls.push_back(has_cls ? raw.cls[i] : PointClass::kUnknown);
  }
}

// t.bounds: per tile min x, y, z, max x, y, z.
void TileBounds(TiledCloud& t) {
  t.bounds.resize(t.keys.size());
  ParallelFor(t.keys.size(), t.cfg.threads, [&](std::size_t s) {
    std::array<float, 6> b{};
    for (int a = 0; a < 3; ++a) b[a] = std::numeric_limits<float>::max(), b[3 + a] = std::numeric_limits<float>::lowest();
    for (const auto& p : t.raw[s].points) {
      b[0] = std::min(b[0], p.x), b[1] = std::min(b[1], p.y), b[2] = std::min(b[2], p.z);
      b[3] = std::max(b[3], p.x), b[4] = std::max(b[4], p.y), b[5] = std::max(b[5], p.z);
    }
    t.bounds[s] = b;
  });
}

// t.levels and every tile at level 0: the coarsest configured voxel, doubled while the whole
// layer holds more than coarse_budget points there and the doubled voxel still nests in the
// tiles' cells.
std::vector<PointCloud> CoarseLevel(TiledCloud& t, int cells) {
  const ViewConfig& cfg = t.cfg;
  for (int k = 0; k < cfg.lod_levels; ++k) t.levels.push_back(LevelVoxel(cfg, k));
  std::vector<PointCloud> coarse(t.keys.size());
  for (int extra = 0;; ++extra) {
    if (extra > 0) t.levels.insert(t.levels.begin(), 2 * t.levels.front());
    ParallelFor(t.keys.size(), cfg.threads, [&](std::size_t s) { coarse[s] = TileCloud(t, s, 0); });
    std::size_t total = 0;
    for (const auto& c : coarse) total += c.size();
    const int next_cells = 1 << (cfg.lod_levels + extra);  // base cells per voxel one level coarser
    if (total <= std::size_t(cfg.coarse_budget) || cells % next_cells != 0 || int(t.levels.size()) >= kMaxLevels) break;
  }
  return coarse;
}
}  // namespace

// Level 0 encoded per tile and for the whole layer; the finer levels are filled on demand.
void TiledCloud::CacheLevel0(const std::vector<PointCloud>& level0) {
  const std::size_t nlevels = levels.size();
  encoded_.assign(keys.size(), std::vector<std::shared_ptr<const std::string>>(nlevels));
  counts_.assign(keys.size(), std::vector<std::size_t>(nlevels, 0));
  coarse_counts.resize(keys.size());
  ParallelFor(keys.size(), cfg.threads, [&](std::size_t s) {
    coarse_counts[s] = level0[s].size();
    counts_[s][0] = level0[s].size();
    encoded_[s][0] = std::make_shared<const std::string>(EncodeCloud(level0[s], levels[0]));
  });
  PointCloud all;
  for (const auto& c : level0) all.append(c);
  coarse = std::make_shared<const std::string>(EncodeCloud(all, levels[0]));
}

std::shared_ptr<TiledCloud> BuildTiles(const PointCloud& raw, const ViewConfig& cfg) {
  auto out = std::make_shared<TiledCloud>();
  TiledCloud& t = *out;
  t.cfg = cfg;
  const int cells = TileCells(cfg);
  t.tile_edge_m = cells * cfg.base_voxel_m;
  SplitIntoTiles(raw, PointTiles(raw, cfg, cells), t);
  TileBounds(t);
  t.CacheLevel0(CoarseLevel(t, cells));
  t.bytes = raw.size() * (sizeof(PointXYZI) + 1) + 2 * t.coarse->size();
  return out;
}

}  // namespace ltm::view
