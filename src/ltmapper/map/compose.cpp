// Change composition (paper eq. 4): P ⊙ LD = P − ND + PD, its inverse, and the delta between two
// states of a keyframe. On the store's grid the set difference is exact: a stored ND point is a
// copy of the point it removes, so "the same point" is "the same quantised key".
#include "ltmapper/map/detail.hpp"

#include <cmath>
#include <unordered_map>

namespace ltm::map {
namespace detail {
namespace {

// Points of cloud within `radius` of any query point; get(k) returns a point as Vector3d. The
// query points go into a grid of radius-sized cells; a cloud point looks at the 27 cells around
// its own. When the query occupies few cells against the cloud's size (a keyframe's strong ND
// against its map points), the cells near any query point are marked first, so a cloud point far
// from every query point costs one lookup instead of 27. The result is the same either way.
template <class GetC, class GetQ>
std::vector<bool> WithinRadiusImpl(std::size_t nc, GetC getc, std::size_t nq, GetQ getq, double radius) {
  std::vector<bool> mask(nc, false);
  if (nc == 0 || nq == 0) return mask;
  const double cell = radius > 0 ? radius : 1e-9;
  const double r2 = radius * radius;
  auto cell_of = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(int(std::floor(p.x() / cell)), int(std::floor(p.y() / cell)), int(std::floor(p.z() / cell)));
  };
  auto pack = [](int x, int y, int z) {
    constexpr std::uint64_t m = (1ull << 21) - 1;
    return ((std::uint64_t(std::uint32_t(x)) & m) << 42) | ((std::uint64_t(std::uint32_t(y)) & m) << 21) |
           (std::uint64_t(std::uint32_t(z)) & m);
  };
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
  std::vector<Eigen::Vector3i> cells;  // the occupied ones
  grid.reserve(nq);
  for (std::size_t k = 0; k < nq; ++k) {
    const Eigen::Vector3i c = cell_of(getq(k));
    auto& slot = grid[pack(c.x(), c.y(), c.z())];
    if (slot.empty()) cells.push_back(c);
    slot.push_back(std::uint32_t(k));
  }
  constexpr std::size_t kAround = 27;
  const bool prefilter = cells.size() * kAround < nc;
  KeySet near(prefilter ? cells.size() * kAround : 0);
  if (prefilter)
    for (const Eigen::Vector3i& c : cells)
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) near.Insert(pack(c.x() + dx, c.y() + dy, c.z() + dz));
  for (std::size_t k = 0; k < nc; ++k) {
    const Eigen::Vector3d p = getc(k);
    const Eigen::Vector3i c = cell_of(p);
    if (prefilter && !near.Contains(pack(c.x(), c.y(), c.z()))) continue;
    bool hit = false;
    for (int dx = -1; dx <= 1 && !hit; ++dx)
      for (int dy = -1; dy <= 1 && !hit; ++dy)
        for (int dz = -1; dz <= 1 && !hit; ++dz) {
          auto it = grid.find(pack(c.x() + dx, c.y() + dy, c.z() + dz));
          if (it == grid.end()) continue;
          for (std::uint32_t j : it->second)
            if ((getq(j) - p).squaredNorm() <= r2) {
              hit = true;
              break;
            }
        }
    mask[k] = hit;
  }
  return mask;
}

bool IsRemoved(std::uint8_t role) { return role == kRemovedChange || role == kRemovedSuperseded; }

// `state` without the points of the delta's `leaving` roles, plus those of its `entering` roles
// (as state points, role kAdded): the one rule of both directions of a step.
template <class Leaving, class Entering>
QCloud Apply(const QCloud& state, const QCloud& delta, Leaving leaving, Entering entering) {
  KeySet gone(delta.size());
  std::size_t entered = 0;
  for (const QPoint& p : delta) {
    if (leaving(p.role)) gone.Insert(Key(p));
    if (entering(p.role)) ++entered;
  }
  QCloud out;
  out.reserve(state.size() + entered);
  if (gone.size() == 0) {
    out = state;
  } else {
    for (const QPoint& p : state)
      if (!gone.Contains(Key(p))) out.push_back(p);
  }
  for (const QPoint& p : delta)
    if (entering(p.role)) {
      out.push_back(p);
      out.back().role = kAdded;
    }
  return out;
}

bool IsAdded(std::uint8_t role) { return role == kAdded; }

}  // namespace

QCloud ApplyForward(const QCloud& state, const QCloud& delta) { return Apply(state, delta, IsRemoved, IsAdded); }

QCloud ApplyInverse(const QCloud& state, const QCloud& delta) { return Apply(state, delta, IsAdded, IsRemoved); }

QCloud MakeDelta(const QCloud& latest, const QCloud& target, const KeySet& change_keys, const QCloud& info) {
  KeySet latest_keys(latest.size()), target_keys(target.size());
  for (const QPoint& p : latest) latest_keys.Insert(Key(p));
  for (const QPoint& p : target) target_keys.Insert(Key(p));
  QCloud delta;
  for (const QPoint& p : latest) {
    const std::uint64_t k = Key(p);
    if (target_keys.Contains(k)) continue;
    delta.push_back(p);
    delta.back().role = change_keys.Contains(k) ? kRemovedChange : kRemovedSuperseded;
  }
  for (const QPoint& p : target) {
    if (latest_keys.Contains(Key(p))) continue;
    delta.push_back(p);
    delta.back().role = kAdded;
  }
  for (const QPoint& p : info) {
    delta.push_back(p);
    delta.back().role = kInfoNDWeak;
  }
  return delta;
}

QCloud Unmatched(const QCloud& cloud, const QCloud& other) {
  KeySet keys(other.size());
  for (const QPoint& p : other) keys.Insert(Key(p));
  static constexpr int kStep[7][3] = {{0, 0, 0}, {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  QCloud out;
  for (const QPoint& p : cloud) {
    bool near = false;
    for (const auto& d : kStep) {
      QPoint q = p;
      q.x += d[0], q.y += d[1], q.z += d[2];
      if ((near = keys.Contains(Key(q)))) break;
    }
    if (!near) out.push_back(p);
  }
  return out;
}

std::vector<bool> WithinRadiusQ(const QCloud& cloud, const QCloud& query, double radius_units) {
  auto get = [](const QCloud& c) {
    return [&c](std::size_t k) { return Eigen::Vector3d(c[k].x, c[k].y, c[k].z); };
  };
  return WithinRadiusImpl(cloud.size(), get(cloud), query.size(), get(query), radius_units);
}

}  // namespace detail

std::vector<bool> WithinRadius(const PointCloud& cloud, const PointCloud& query, double radius_m) {
  auto get = [](const PointCloud& c) {
    return [&c](std::size_t k) { return c.points[k].xyz().cast<double>().eval(); };
  };
  return detail::WithinRadiusImpl(cloud.size(), get(cloud), query.size(), get(query), radius_m);
}

}  // namespace ltm::map
