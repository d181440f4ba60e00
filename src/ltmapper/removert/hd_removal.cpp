// HD removal by remove-then-revert on multi-resolution range images (Removert, Kim & Kim 2020).
//
// Remove: at each removal resolution (fine to coarse) a map point is a candidate when at least
//   remove_min_votes keyframes see through it and those are at least remove_min_ratio of the
//   keyframes with evidence about it (see-through + hit). Fine pixels catch small and thin
//   movers; coarse pixels (min range over a larger solid angle) catch what fine pixels miss
//   between beams. The candidates are the union over resolutions.
// Revert: false removals come from pixel quantisation (grazing ground, silhouette edges, thin
//   poles, pose error): a fine pixel's min range belongs to a different surface than the point.
//   At a coarser revert resolution the pixel's min range includes the nearer neighbours, so a
//   static point is observed as a surface (hit) by many keyframes while a moving object's trace
//   is hit only by the few keyframes that saw the object there. A candidate is reverted when,
//   at some revert resolution, hits >= revert_min_hits and hits >= revert_hit_ratio * S, S being
//   its largest see-through count over the removal resolutions. Only candidates are projected
//   at the revert resolutions, and their hits include returns on their surface plane
//   (hd.revert_surface_max_m): ground seen at a grazing angle is sampled metres apart in range.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <unordered_set>
#include <utility>

namespace ltm::removert {

void RemovertConfig::Validate(const std::string& where) const {
  ValidateConfig(*this, where);
  auto fail = [&](const std::string& what) { throw Error(where + ": " + what); };
  if (!(fov_up_deg > fov_down_deg)) fail("sensor.fov_up_deg must be above sensor.fov_down_deg");
  if (!(max_range_m > min_range_m)) fail("sensor.max_range_m must exceed sensor.min_range_m");
  if (remove_resolutions_deg.empty()) fail("hd.remove_resolutions_deg must not be empty");
  if (revert && revert_resolutions_deg.empty())
    fail("hd.revert_resolutions_deg must not be empty when hd.revert is true");
  if (ld_resolutions_deg.empty()) fail("ld.resolutions_deg must not be empty");
}

namespace {

// ---- Session-map voxelisation: the same clouds as geometry::VoxelDownsample, point for point
// (voxel index floor(coordinate / voxel), centroids summed in double in point order, output in
// voxel (x, y, z) order), faster on what BuildSessionMap voxelises: single scans (radix sort of
// the voxel keys instead of a comparison sort) and concatenations of voxelised clouds, whose
// sorted runs are merged instead of sorted again. Clouds outside that (optional arrays,
// non-finite points, voxel indices spanning 2^21 or more per axis, a run out of order) go to
// VoxelDownsample itself.

constexpr int kAxisBits = 21;                          // largest voxel index span per axis: 2^21
constexpr double kMaxVoxelIndex = 4503599627370496.0;  // 2^52: beyond, floor() is no integer test
constexpr std::size_t kChunk = 1 << 16;                // points per parallel task

// f(c) for c in [0, chunks): in parallel, or in the calling thread for threads == 1 (a scan
// inside BuildSessionMap's own parallel loop).
template <class F>
void ForChunks(std::size_t chunks, int threads, F&& f) {
  if (threads == 1) {
    for (std::size_t c = 0; c < chunks; ++c) f(c);
  } else {
    detail::ParallelFor(chunks, threads, f);
  }
}

// Voxel index floor(c / voxel_m) as VoxelDownsample computes it (double division), false when
// not an integer below 2^52 in magnitude (NaN, infinity). Truncation and a correction instead of
// std::floor: the same integer, without a libm call per coordinate.
inline bool VoxelIndex(float c, double voxel_m, std::int64_t* k) {
  const double v = double(c) / voxel_m;
  if (!(std::fabs(v) < kMaxVoxelIndex)) return false;
  std::int64_t t = std::int64_t(v);
  if (double(t) > v) --t;
  *k = t;
  return true;
}

// Voxel keys of the cloud's points: (ix, iy, iz) relative to the lowest indices, packed so that
// integer order is (x, y, z) order; *bits = the key width. False when the cloud is not handled.
bool VoxelKeys(const PointCloud& cloud, double voxel_m, int threads, std::vector<std::uint64_t>* keys,
               int* bits) {
  const std::size_t n = cloud.size();
  if (!cloud.cls.empty() || !cloud.session.empty() || !cloud.object.empty()) return false;
  if (n == 0 || n >= std::numeric_limits<std::uint32_t>::max()) return false;
  if (!(voxel_m > 0.0) || !std::isfinite(voxel_m)) return false;
  // Index bounds from coordinate bounds (the index is monotonic in the coordinate).
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  struct Box {
    float lo[3], hi[3];
  };
  std::vector<Box> boxes(chunks);
  ForChunks(chunks, threads, [&](std::size_t c) {
    Box B;
    const PointXYZI& p0 = cloud.points[c * kChunk];
    B.lo[0] = B.hi[0] = p0.x;
    B.lo[1] = B.hi[1] = p0.y;
    B.lo[2] = B.hi[2] = p0.z;
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const PointXYZI& p = cloud.points[i];
      B.lo[0] = std::min(B.lo[0], p.x);
      B.hi[0] = std::max(B.hi[0], p.x);
      B.lo[1] = std::min(B.lo[1], p.y);
      B.hi[1] = std::max(B.hi[1], p.y);
      B.lo[2] = std::min(B.lo[2], p.z);
      B.hi[2] = std::max(B.hi[2], p.z);
    }
    boxes[c] = B;
  });
  std::int64_t lo[3], hi[3];
  int shift[3];
  for (int a = 0; a < 3; ++a) {
    float l = boxes[0].lo[a], h = boxes[0].hi[a];
    for (const Box& B : boxes) {
      l = std::min(l, B.lo[a]);
      h = std::max(h, B.hi[a]);
    }
    if (!VoxelIndex(l, voxel_m, &lo[a]) || !VoxelIndex(h, voxel_m, &hi[a])) return false;
    const std::uint64_t span = std::uint64_t(hi[a] - lo[a]);
    if (span >> kAxisBits) return false;
    int w = 0;
    while ((span >> w) != 0) ++w;
    shift[a] = w;
  }
  *bits = shift[0] + shift[1] + shift[2];
  keys->resize(n);
  std::vector<std::uint8_t> ok(chunks, 1);
  ForChunks(chunks, threads, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const PointXYZI& p = cloud.points[i];
      std::int64_t k[3] = {0, 0, 0};
      // Not an index, or outside the bounds: a NaN coordinate (the bounds skip NaNs).
      if (!(VoxelIndex(p.x, voxel_m, &k[0]) && VoxelIndex(p.y, voxel_m, &k[1]) &&
            VoxelIndex(p.z, voxel_m, &k[2]))) {
        ok[c] = 0;
        return;
      }
      for (int a = 0; a < 3; ++a)
        if (k[a] < lo[a] || k[a] > hi[a]) {
          ok[c] = 0;
          return;
        }
      (*keys)[i] = (std::uint64_t(k[0] - lo[0]) << (shift[1] + shift[2])) |
                   (std::uint64_t(k[1] - lo[1]) << shift[2]) | std::uint64_t(k[2] - lo[2]);
    }
  });
  return std::all_of(ok.begin(), ok.end(), [](std::uint8_t o) { return o != 0; });
}

// One centroid per run of equal keys along `order` (point indices by key, then index), as
// geometry::VoxelDownsample computes it. In parallel chunks of `order`: a chunk takes the runs
// that start in it.
PointCloud Centroids(const PointCloud& cloud, const std::vector<std::uint64_t>& keys,
                     const std::vector<std::uint32_t>& order, int threads) {
  const std::size_t n = order.size();
  auto starts_run = [&](std::size_t j) { return j == 0 || keys[order[j]] != keys[order[j - 1]]; };
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<std::size_t> first(chunks + 1, 0);  // output index of each chunk's first run
  ForChunks(chunks, threads, [&](std::size_t c) {
    for (std::size_t j = c * kChunk; j < std::min(n, (c + 1) * kChunk); ++j)
      first[c + 1] += starts_run(j) ? 1 : 0;
  });
  for (std::size_t c = 0; c < chunks; ++c) first[c + 1] += first[c];
  PointCloud out;
  out.points.resize(first[chunks]);
  ForChunks(chunks, threads, [&](std::size_t c) {
    std::size_t v = first[c];
    for (std::size_t j = c * kChunk; j < std::min(n, (c + 1) * kChunk); ++j) {
      if (!starts_run(j)) continue;
      const std::uint64_t key = keys[order[j]];
      double sx = 0, sy = 0, sz = 0, si = 0;
      std::size_t e = j;
      for (; e < n && keys[order[e]] == key; ++e) {
        const PointXYZI& p = cloud.points[order[e]];
        sx += p.x;
        sy += p.y;
        sz += p.z;
        si += p.intensity;
      }
      const double inv = 1.0 / double(e - j);
      out.points[v++] = {float(sx * inv), float(sy * inv), float(sz * inv), float(si * inv)};
    }
  });
  return out;
}

// VoxelDownsample(scan, voxel_m, 1) of one scan: LSD radix sort of the keys (stable, so equal
// keys stay in index order).
PointCloud VoxelScan(const PointCloud& scan, double voxel_m) {
  if (scan.empty()) return PointCloud{};
  std::vector<std::uint64_t> keys;
  int bits = 0;
  if (!VoxelKeys(scan, voxel_m, 1, &keys, &bits)) return geometry::VoxelDownsample(scan, voxel_m, 1);
  constexpr int kDigit = 11;
  const std::size_t n = scan.size();
  std::vector<std::uint32_t> order(n), tmp(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = std::uint32_t(i);
  std::vector<std::uint32_t> count(std::size_t(1) << kDigit);
  for (int shift = 0; shift < bits; shift += kDigit) {
    std::fill(count.begin(), count.end(), 0u);
    const std::uint64_t mask = (std::uint64_t(1) << kDigit) - 1;
    for (std::uint32_t i : order) ++count[(keys[i] >> shift) & mask];
    std::uint32_t sum = 0;
    for (auto& c : count) sum += std::exchange(c, sum);
    for (std::uint32_t i : order) tmp[count[(keys[i] >> shift) & mask]++] = i;
    order.swap(tmp);
  }
  return Centroids(scan, keys, order, 1);
}

// VoxelDownsample(cloud, voxel_m, threads) of a concatenation of voxelised clouds starting at
// `runs` (ascending, runs[0] = 0): pairwise stable merges of the runs, each already in key order.
PointCloud VoxelRuns(const PointCloud& cloud, std::vector<std::size_t> runs, double voxel_m,
                     int threads) {
  if (cloud.empty()) return PointCloud{};
  const std::size_t n = cloud.size();
  std::vector<std::uint64_t> keys;
  int bits = 0;
  bool sorted = VoxelKeys(cloud, voxel_m, threads, &keys, &bits);
  runs.push_back(n);
  for (std::size_t r = 0; sorted && r + 1 < runs.size(); ++r)
    for (std::size_t i = runs[r] + 1; i < runs[r + 1] && sorted; ++i) sorted = keys[i - 1] <= keys[i];
  if (!sorted) return geometry::VoxelDownsample(cloud, voxel_m, threads);
  std::vector<std::uint32_t> order(n), tmp(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = std::uint32_t(i);
  // std::merge takes equal keys from the first range first: (key, index) order.
  auto by_key = [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; };
  while (runs.size() > 2) {
    const std::size_t pairs = (runs.size() - 1) / 2;
    detail::ParallelFor(pairs, threads, [&](std::size_t q) {
      const std::size_t b0 = runs[2 * q], b1 = runs[2 * q + 1], b2 = runs[2 * q + 2];
      std::merge(order.begin() + b0, order.begin() + b1, order.begin() + b1, order.begin() + b2,
                 tmp.begin() + b0, by_key);
    });
    std::vector<std::size_t> merged;
    for (std::size_t q = 0; q < pairs; ++q) merged.push_back(runs[2 * q]);
    if ((runs.size() - 1) % 2 == 1) {  // odd run out: copied as it is
      const std::size_t b0 = runs[runs.size() - 2];
      std::copy(order.begin() + b0, order.end(), tmp.begin() + b0);
      merged.push_back(b0);
    }
    merged.push_back(n);
    order.swap(tmp);
    runs.swap(merged);
  }
  return Centroids(cloud, keys, order, threads);
}

}  // namespace

PointCloud BuildSessionMap(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                           int threads) {
  // Batches of keyframes: each scan is range filtered, moved to the world frame and the batch
  // voxelised; the accumulated map is re-voxelised whenever it doubles, so memory stays at
  // about two maps plus one batch of scans. Every voxelisation equals VoxelDownsample's; the
  // voxelised clouds are in voxel order, so each concatenation is a list of sorted runs.
  const std::size_t batch = std::size_t(std::max(8, 4 * (threads > 0 ? threads : 2)));
  PointCloud acc;
  std::vector<std::size_t> acc_runs;  // starts of acc's sorted runs
  std::size_t last_size = 0;
  for (std::size_t b = 0; b < keyframes.size(); b += batch) {
    const std::size_t e = std::min(keyframes.size(), b + batch);
    std::vector<PointCloud> parts(e - b);
    detail::ParallelFor(e - b, threads, [&](std::size_t k) {
      const WorldKeyframe& kf = keyframes[b + k];
      const auto scan = detail::LoadScan(kf);
      PointCloud local = geometry::RangeFilter(*scan, cfg.min_range_m, cfg.max_range_m);
      local.cls.clear();
      local.session.clear();
      local.object.clear();
      geometry::TransformInPlace(local, kf.T_world_sensor);
      parts[k] = VoxelScan(local, cfg.map_voxel_m);
    });
    PointCloud merged;
    std::vector<std::size_t> part_runs;
    for (auto& p : parts) {
      part_runs.push_back(merged.size());
      merged.append(p);
    }
    acc_runs.push_back(acc.size());
    acc.append(VoxelRuns(merged, part_runs, cfg.map_voxel_m, threads));
    if (acc.size() > 2 * std::max<std::size_t>(last_size, 1 << 16)) {
      acc = VoxelRuns(acc, acc_runs, cfg.map_voxel_m, threads);
      acc_runs.assign(1, 0);
      last_size = acc.size();
    }
  }
  return VoxelRuns(acc, acc_runs, cfg.map_voxel_m, threads);
}

HdResult RemoveHdFromMap(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes,
                         const RemovertConfig& cfg, int threads) {
  cfg.Validate();
  const auto t0 = std::chrono::steady_clock::now();
  const int n_remove = int(cfg.remove_resolutions_deg.size());
  const VisibilityVotes votes = CountVisibility(map, keyframes, cfg.remove_resolutions_deg, cfg, threads);

  HdResult res;
  HdStats& st = res.stats;
  st.map_points = map.size();
  st.removed_per_resolution.assign(std::size_t(n_remove), 0);
  std::vector<std::uint32_t> cand;  // candidate map indices
  std::vector<double> s_max;        // their strongest removal evidence over the removal resolutions
  for (std::size_t i = 0; i < map.size(); ++i) {
    bool is_cand = false;
    double sm = 0;
    for (int l = 0; l < n_remove; ++l) {
      const double s = votes.See(l, i), h = votes.Hit(l, i);
      sm = std::max(sm, s);
      if (s >= cfg.remove_min_votes && s >= cfg.remove_min_ratio * (s + h)) {
        is_cand = true;
        ++st.removed_per_resolution[std::size_t(l)];
      }
    }
    if (!is_cand) continue;
    cand.push_back(std::uint32_t(i));
    s_max.push_back(sm);
  }
  st.candidates = cand.size();
  // Revert: only the candidates are projected again, at the coarser resolutions, counting hits
  // on their surface plane (normals from the map), so grazing ground is observed as a surface.
  std::vector<bool> dynamic(map.size(), false);
  std::vector<bool> reverted(cand.size(), false);
  if (cfg.revert && !cand.empty()) {
    const PointCloud cpts = map.select(cand);
    VisibilityOptions opt;
    std::vector<Eigen::Vector3f> normals;
    if (cfg.revert_surface_max_m > 0.0) {
      normals = detail::EstimateNormals(cpts, map, cfg.ld_normal_radius_m, threads);
      opt.normals = &normals;
      opt.surface_max_m = cfg.revert_surface_max_m;
    }
    const VisibilityVotes rv = CountVisibility(cpts, keyframes, cfg.revert_resolutions_deg, cfg, threads, opt);
    for (std::size_t j = 0; j < cand.size(); ++j)
      for (int l = 0; l < rv.levels && !reverted[j]; ++l) {
        const double h = rv.Hit(l, j);
        reverted[j] = h >= cfg.revert_min_hits && h >= cfg.revert_hit_ratio * s_max[j];
      }
  }
  for (std::size_t j = 0; j < cand.size(); ++j) {
    if (reverted[j]) {
      ++st.reverted;
    } else {
      dynamic[cand[j]] = true;
      ++st.removed;
    }
  }
  // Dilation: the map points next to a removed point (a wheel's or a foot's contact with the
  // ground shares its voxels with the ground) go too. Decided against the removed set before
  // dilation, so it grows by one radius, not transitively.
  if (cfg.dilate_m > 0.0 && st.removed > 0) {
    const PointCloud removed = map.select(dynamic);
    const geometry::KdTree tree(removed);
    const float r2 = float(cfg.dilate_m * cfg.dilate_m);
    // Cells (edge 4 * dilate_m) touched by some removed point's dilation ball: most map points
    // are far from every removed point and skip the kd-tree after one hash lookup.
    const double cell = 4.0 * cfg.dilate_m;
    auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) {
      return (x & 0x1FFFFF) | ((y & 0x1FFFFF) << 21) | ((z & 0x1FFFFF) << 42);
    };
    auto index = [&](float v, double off) { return std::int64_t(std::floor((double(v) + off) / cell)); };
    std::unordered_set<std::int64_t> touched;
    for (const PointXYZI& q : removed.points)
      for (int dx = -1; dx <= 1; dx += 2)
        for (int dy = -1; dy <= 1; dy += 2)
          for (int dz = -1; dz <= 1; dz += 2)
            touched.insert(key(index(q.x, dx * cfg.dilate_m), index(q.y, dy * cfg.dilate_m),
                               index(q.z, dz * cfg.dilate_m)));
    std::vector<std::uint8_t> grow(map.size(), 0);
    const std::size_t chunk = 8192;
    detail::ParallelFor((map.size() + chunk - 1) / chunk, threads, [&](std::size_t c) {
      const std::size_t b = c * chunk, e = std::min(map.size(), b + chunk);
      std::uint32_t j = 0;
      float d2 = 0.f;
      for (std::size_t i = b; i < e; ++i) {
        const PointXYZI& p = map.points[i];
        if (dynamic[i] || !touched.count(key(index(p.x, 0.0), index(p.y, 0.0), index(p.z, 0.0)))) continue;
        if (tree.Nearest(p.xyz(), &j, &d2) && d2 <= r2) grow[i] = 1;
      }
    });
    for (std::size_t i = 0; i < map.size(); ++i)
      if (grow[i]) {
        dynamic[i] = true;
        ++st.dilated;
      }
  }
  std::vector<bool> keep(dynamic.size());
  for (std::size_t i = 0; i < dynamic.size(); ++i) keep[i] = !dynamic[i];
  res.static_map = map.select(keep);
  res.hd_map = map.select(dynamic);
  st.seconds_votes = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

HdResult RemoveHd(const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                  int threads) {
  cfg.Validate();
  const auto t0 = std::chrono::steady_clock::now();
  const PointCloud map = BuildSessionMap(keyframes, cfg, threads);
  const double t_map = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  HdResult res = RemoveHdFromMap(map, keyframes, cfg, threads);
  res.stats.seconds_map = t_map;
  return res;
}

}  // namespace ltm::removert
