// Change composition (paper eq. 4): P ⊙ LD = P − ND + PD, its inverse, and the delta between two
// states of a keyframe. On the store's grid the set difference is exact: a stored ND point is a
// copy of the point it removes, so "the same point" is "the same quantised key".
#include "ltmapper/map/detail.hpp"

#include <cmath>
#include <unordered_map>

namespace ltm::map {
namespace detail {
namespace {

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
  std::vector<bool> mask(cloud.size(), false);
  if (cloud.empty() || query.empty()) return mask;
  auto at = [](const QPoint& p) { return Eigen::Vector3d(p.x, p.y, p.z); };
  std::vector<Eigen::Vector3d> set(query.size());
  for (std::size_t k = 0; k < query.size(); ++k) set[k] = at(query[k]);
  const geometry::RadiusIndex index(std::move(set), radius_units, cloud.size());
  for (std::size_t k = 0; k < cloud.size(); ++k) mask[k] = index.Near(at(cloud[k]));
  return mask;
}

}  // namespace detail

}  // namespace ltm::map
