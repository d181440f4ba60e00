// Visibility votes: the hot loop shared by HD removal (map vs own scans), weak/strong ND (central
// ND points vs query scans) and weak/strong PD (query PD points vs central scans).
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/io/io.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <string>

namespace ltm::removert {
namespace detail {

geometry::RangeImageConfig LevelConfig(const RemovertConfig& cfg, double pixel_deg) {
  geometry::RangeImageConfig c;
  c.fov_up_deg = cfg.fov_up_deg;
  c.fov_down_deg = cfg.fov_down_deg;
  c.rows = std::max(1, int(std::ceil((cfg.fov_up_deg - cfg.fov_down_deg) / pixel_deg - 1e-9)));
  c.cols = std::max(1, int(std::lround(360.0 / pixel_deg)));
  return c;
}

MultiResImage::MultiResImage(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg) {
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  up_ = float(cfg.fov_up_deg * kDeg);
  down_ = float(cfg.fov_down_deg * kDeg);
  min_range_ = float(cfg.min_range_m);
  max_range_ = float(cfg.max_range_m);
  window_ = cfg.window_px;
  const double fov = (cfg.fov_up_deg - cfg.fov_down_deg) * kDeg;
  for (double res : resolutions_deg) {
    const geometry::RangeImageConfig rc = LevelConfig(cfg, res);
    Level L;
    L.rows = rc.rows;
    L.cols = rc.cols;
    L.row_scale = float(rc.rows / fov);
    L.col_scale = float(rc.cols / (2.0 * 3.14159265358979323846));
    L.range.assign(std::size_t(L.rows) * L.cols, std::numeric_limits<float>::infinity());
    L.pooled = L.range;
    L.tmp = L.range;
    levels_.push_back(std::move(L));
  }
}

void MultiResImage::Build(const PointCloud& scan) {
  for (Level& L : levels_) std::fill(L.range.begin(), L.range.end(), std::numeric_limits<float>::infinity());
  const int nl = levels();
  for (const PointXYZI& q : scan.points) {
    float r, pitch, yaw;
    if (!Angles(Eigen::Vector3f(q.x, q.y, q.z), &r, &pitch, &yaw)) continue;
    if (r < min_range_ || r > max_range_) continue;
    for (int l = 0; l < nl; ++l) {
      float& px = levels_[std::size_t(l)].range[Pixel(l, pitch, yaw)];
      if (r < px) px = r;
    }
  }
  // Separable min filter: along columns (wrapping) into tmp, then along rows into pooled.
  const int w = window_;
  for (Level& L : levels_) {
    if (w == 0) {
      L.pooled = L.range;
      continue;
    }
    for (int r = 0; r < L.rows; ++r) {
      const float* src = &L.range[std::size_t(r) * L.cols];
      float* dst = &L.tmp[std::size_t(r) * L.cols];
      for (int c = 0; c < L.cols; ++c) {
        float m = src[c];
        for (int d = 1; d <= w; ++d) {
          int a = c - d, b = c + d;
          if (a < 0) a += L.cols;
          if (b >= L.cols) b -= L.cols;
          m = std::min(m, std::min(src[a], src[b]));
        }
        dst[c] = m;
      }
    }
    for (int r = 0; r < L.rows; ++r) {
      const int r0 = std::max(0, r - w), r1 = std::min(L.rows - 1, r + w);
      float* dst = &L.pooled[std::size_t(r) * L.cols];
      for (int c = 0; c < L.cols; ++c) {
        float m = std::numeric_limits<float>::infinity();
        for (int rr = r0; rr <= r1; ++rr) m = std::min(m, L.tmp[std::size_t(rr) * L.cols + c]);
        dst[c] = m;
      }
    }
  }
}

TileIndex::TileIndex(const PointCloud& cloud, double tile_m) : tile_m_(tile_m) {
  const std::size_t n = cloud.size();
  std::vector<std::int64_t> keys(n);
  for (std::size_t i = 0; i < n; ++i) {
    const PointXYZI& p = cloud.points[i];
    keys[i] = Key(std::int32_t(std::floor(p.x / tile_m)), std::int32_t(std::floor(p.y / tile_m)));
  }
  order_.resize(n);
  std::iota(order_.begin(), order_.end(), 0u);
  std::stable_sort(order_.begin(), order_.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
  sorted_.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    const PointXYZI& p = cloud.points[order_[k]];
    sorted_[k] = Eigen::Vector3f(p.x, p.y, p.z);
  }
  std::size_t k = 0;
  while (k < n) {
    std::size_t e = k + 1;
    const std::int64_t key = keys[order_[k]];
    while (e < n && keys[order_[e]] == key) ++e;
    tiles_[key] = {std::uint32_t(k), std::uint32_t(e)};
    k = e;
  }
}

void TileIndex::ForTilesNear(const Eigen::Vector3f& c, float radius,
                             const std::function<void(std::uint32_t, std::uint32_t)>& f) const {
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
      if (it != tiles_.end()) f(it->second.first, it->second.second);
    }
  }
}

std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf) {
  if (kf.cloud) return kf.cloud;
  if (kf.cloud_path.empty())
    throw Error("removert: keyframe " + std::to_string(kf.index) + " has neither a cloud nor a path");
  auto cloud = std::make_shared<PointCloud>(io::ReadCloud(kf.cloud_path));
  geometry::RemoveNonFinite(*cloud);
  return cloud;
}

void ParallelFor(std::size_t n, int threads, const std::function<void(std::size_t)>& f) {
  if (n == 0) return;
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
                      });
  });
}

PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor) {
  return geometry::Transform(cloud, T_world_sensor.inverse());
}

}  // namespace detail

VisibilityVotes CountVisibility(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                                const std::vector<double>& resolutions_deg,
                                const RemovertConfig& cfg, int threads,
                                const VisibilityOptions& options) {
  const bool count_occluded = options.count_occluded;
  if (options.normals && options.normals->size() != points.size())
    throw Error("removert: " + std::to_string(options.normals->size()) + " normals for " +
                std::to_string(points.size()) + " points");
  if (keyframes.size() >= 65535)
    throw Error("removert: " + std::to_string(keyframes.size()) +
                " keyframes in one session; vote counters hold at most 65534");
  VisibilityVotes out;
  out.points = points.size();
  out.levels = int(resolutions_deg.size());
  const std::size_t n = points.size();
  const std::size_t L = resolutions_deg.size();
  out.see.assign(n * L, 0);
  out.hit.assign(n * L, 0);
  if (count_occluded) out.occ.assign(n * L, 0);
  if (n == 0 || L == 0 || keyframes.empty()) return out;

  const detail::TileIndex index(points, cfg.tile_m);
  const auto& pts = index.sorted();
  // Counters in tile order; each keyframe adds at most 1 per point and level, so uint16 with
  // fewer than 65535 keyframes never overflows.
  std::unique_ptr<std::atomic<std::uint16_t>[]> see(new std::atomic<std::uint16_t>[n * L]());
  std::unique_ptr<std::atomic<std::uint16_t>[]> hit(new std::atomic<std::uint16_t>[n * L]());
  std::unique_ptr<std::atomic<std::uint16_t>[]> occ(
      count_occluded ? new std::atomic<std::uint16_t>[n * L]() : nullptr);
  const float radius = float(cfg.submap_radius_m);
  const float r2 = radius * radius;
  const float tol_abs = float(cfg.tol_abs_m), tol_rel = float(cfg.tol_rel);
  // Surface hits: range one pixel spans on the point's plane per unit range and tan(incidence).
  const float surface_max = float(options.surface_max_m);
  const bool surface = options.normals != nullptr && surface_max > 0.f;
  std::vector<float> pixel_rad(L);
  for (std::size_t l = 0; l < L; ++l) pixel_rad[l] = float(resolutions_deg[l] * 3.14159265358979323846 / 180.0);
  const int nl = int(L);

  detail::ParallelFor(keyframes.size(), threads, [&](std::size_t k) {
    const WorldKeyframe& kf = keyframes[k];
    const auto scan = detail::LoadScan(kf);
    detail::MultiResImage img(cfg, resolutions_deg);
    img.Build(*scan);
    const Eigen::Matrix3f Rt = kf.T_world_sensor.linear().transpose().cast<float>();
    const Eigen::Vector3f c = kf.T_world_sensor.translation().cast<float>();
    index.ForTilesNear(c, radius, [&](std::uint32_t b, std::uint32_t e) {
      for (std::uint32_t i = b; i < e; ++i) {
        const Eigen::Vector3f d = pts[i] - c;
        if (d.squaredNorm() > r2) continue;
        const Eigen::Vector3f ps = Rt * d;
        float r, pitch, yaw;
        if (!img.Angles(ps, &r, &pitch, &yaw)) continue;
        const float tol = tol_abs + tol_rel * r;
        // tan(incidence) of the ray on the point's surface (capped at grazing incidence).
        float tan_inc = 0.f;
        if (surface) {
          const float c = std::fabs((*options.normals)[index.order()[i]].dot(d)) / r;
          tan_inc = std::sqrt(std::max(0.f, 1.f - c * c)) / std::max(c, 1e-3f);
        }
        for (int l = 0; l < nl; ++l) {
          // See-through: even the nearest return in the window around the point's pixel lies
          // beyond it (so grazing surfaces and silhouette edges, whose neighbouring pixels
          // return nearer, give no vote). Hit: the pixel's own or the window's nearest return
          // is at the point's range.
          const std::size_t pix = img.Pixel(l, pitch, yaw);
          const float s = img.Pooled(l, pix);
          if (!std::isfinite(s)) continue;  // no return anywhere in the window: no evidence
          const std::size_t slot = std::size_t(l) * n + i;
          if (s > r + tol) {
            see[slot].fetch_add(1, std::memory_order_relaxed);
          } else if (std::fabs(s - r) <= tol || std::fabs(img.At(l, pix) - r) <= tol ||
                     (surface && std::fabs(img.At(l, pix) - r) <=
                                     std::min(surface_max, std::max(tol, r * pixel_rad[std::size_t(l)] * tan_inc)))) {
            hit[slot].fetch_add(1, std::memory_order_relaxed);
          } else if (count_occluded) {
            occ[slot].fetch_add(1, std::memory_order_relaxed);
          }
        }
      }
    });
  });

  const auto& order = index.order();
  for (std::size_t l = 0; l < L; ++l) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t orig = std::size_t(order[i]);
      out.see[l * n + orig] = see[l * n + i].load(std::memory_order_relaxed);
      out.hit[l * n + orig] = hit[l * n + i].load(std::memory_order_relaxed);
      if (count_occluded) out.occ[l * n + orig] = occ[l * n + i].load(std::memory_order_relaxed);
    }
  }
  return out;
}

}  // namespace ltm::removert
