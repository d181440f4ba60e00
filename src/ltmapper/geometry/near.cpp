// Points near a set: the key set and the radius index (geometry.hpp).
#include "ltmapper/geometry/geometry.hpp"

#include <cmath>

namespace ltm::geometry {
namespace {

constexpr std::uint64_t kEmpty = ~0ull;  // no key has all 63 bits and the 64th set

std::uint64_t Mix(std::uint64_t x) {  // splitmix64 finaliser
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

std::uint64_t Pack(std::int64_t x, std::int64_t y, std::int64_t z) {
  constexpr std::uint64_t m = (1ull << 21) - 1;
  return ((std::uint64_t(x) & m) << 42) | ((std::uint64_t(y) & m) << 21) | (std::uint64_t(z) & m);
}

constexpr std::size_t kAround = 27;  // the cells around a cell, its own included

}  // namespace

KeySet::KeySet(std::size_t expected) {
  std::size_t cap = 16;
  while (cap < expected * 2) cap <<= 1;
  slots_.assign(cap, kEmpty);
  mask_ = cap - 1;
}

void KeySet::Insert(std::uint64_t key) {
  if ((count_ + 1) * 2 > slots_.size()) Grow();
  std::size_t h = Mix(key) & mask_;
  while (slots_[h] != kEmpty) {
    if (slots_[h] == key) return;
    h = (h + 1) & mask_;
  }
  slots_[h] = key;
  ++count_;
}

bool KeySet::Contains(std::uint64_t key) const {
  std::size_t h = Mix(key) & mask_;
  while (slots_[h] != kEmpty) {
    if (slots_[h] == key) return true;
    h = (h + 1) & mask_;
  }
  return false;
}

void KeySet::Grow() {
  std::vector<std::uint64_t> old;
  old.swap(slots_);
  slots_.assign(old.size() * 2, kEmpty);
  mask_ = slots_.size() - 1;
  count_ = 0;
  for (std::uint64_t k : old)
    if (k != kEmpty) Insert(k);
}

RadiusIndex::RadiusIndex(std::vector<Eigen::Vector3d> set, double radius, std::size_t lookups)
    : set_(std::move(set)), cell_(radius > 0 ? radius : 1e-9), r2_(radius * radius) {
  grid_.reserve(set_.size());
  std::vector<Eigen::Vector3d> firsts;  // a point of each occupied cell
  for (std::size_t k = 0; k < set_.size(); ++k) {
    auto& slot = grid_[Key(CellOf(set_[k]), 0, 0, 0)];
    if (slot.empty()) firsts.push_back(set_[k]);
    slot.push_back(std::uint32_t(k));
  }
  prefilter_ = firsts.size() * kAround < lookups;
  if (!prefilter_) return;
  near_cells_ = KeySet(firsts.size() * kAround);
  for (const Eigen::Vector3d& p : firsts) {
    const Cell c = CellOf(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) near_cells_.Insert(Key(c, dx, dy, dz));
  }
}

RadiusIndex::Cell RadiusIndex::CellOf(const Eigen::Vector3d& p) const {
  return {std::int64_t(std::floor(p.x() / cell_)), std::int64_t(std::floor(p.y() / cell_)),
          std::int64_t(std::floor(p.z() / cell_))};
}

std::uint64_t RadiusIndex::Key(const Cell& c, int dx, int dy, int dz) {
  return Pack(c[0] + dx, c[1] + dy, c[2] + dz);
}

bool RadiusIndex::Near(const Eigen::Vector3d& p) const {
  if (set_.empty()) return false;
  const Cell c = CellOf(p);  // once: the 27 cells around it are offsets of it
  if (prefilter_ && !near_cells_.Contains(Key(c, 0, 0, 0))) return false;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const auto it = grid_.find(Key(c, dx, dy, dz));
        if (it == grid_.end()) continue;
        for (std::uint32_t j : it->second)
          if ((set_[j] - p).squaredNorm() <= r2_) return true;
      }
  return false;
}

std::vector<bool> WithinRadius(const PointCloud& cloud, const PointCloud& query, double radius_m, int threads) {
  std::vector<bool> mask(cloud.size(), false);
  if (cloud.empty() || query.empty()) return mask;
  std::vector<Eigen::Vector3d> set(query.size());
  for (std::size_t k = 0; k < query.size(); ++k) set[k] = query.points[k].xyz().cast<double>();
  const RadiusIndex index(std::move(set), radius_m, cloud.size());
  std::vector<std::uint8_t> near(cloud.size(), 0);  // not vector<bool>: threads write neighbours
  ParallelForChunks(cloud.size(), threads, 8192, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) near[i] = index.Near(cloud.points[i].xyz().cast<double>());
  });
  std::copy(near.begin(), near.end(), mask.begin());
  return mask;
}

}  // namespace ltm::geometry
