// HD removal, last step: a removed body's other returns (CompleteBodies).
//
// A mover is one rigid body. In the scan of a keyframe that met it, its returns above the ground
// are one cluster, and where the other keyframes saw through a part of it at that place, the body
// was not there at their time: the whole of it was a mover's. Removal decides map point by map
// point, and far away it decides a mover in pieces. A car 40-50 m out is sampled by two or three
// rows: the lowest, a few decimetres above the ground, is never seen through (the window's beam
// below it returns from the ground in front of it, within the range tolerance), and where only the
// last keyframes of a drive met a car, few see through its trail while the coarse windows credit
// it with hits from the ground at its range. What stayed is the residue LD later takes for a
// change. So, per keyframe: its returns above the ground, clustered (BodiesMet); a cluster no
// longer than hd.body_max_m of which at least hd.remove_min_ratio of the returns lie in removed map
// voxels, and whose map points' removal votes pooled pass removal's own test (SeenThroughAsOne), is
// a body the keyframe met. A map point goes when every keyframe that returned in its voxel above
// the ground met it in such a body (a standing thing a mover brushed is returned by the keyframes
// before and after it, alone; one whose removal went wrong in part fails the pooled votes).
// Only for ring sensors: the rows are what leave a far body's lowest part unseen through, and one
// scan of a scanner without rings samples a place in a pattern of its own, so the share of a
// cluster its removal took says less of the whole (seed 7's rosette, true poses: a low wall 2.3 m
// beside the query's path that removal had taken part of went further and became a false
// disappeared object, 7/12 (1.00) -> (0.88)).
#include "ltmapper/removert/detail.hpp"

#include <mutex>

namespace ltm::removert::detail {

namespace {

// The map point of each voxel. A session map is in voxel order (x, then y, then z index:
// VoxelDownsample's), and is searched as it is; any other map through a sorted copy of its voxels,
// 16 bytes a point (a hash map of the 7.5 M voxels of a 1000-keyframe session took 0.37 GB more).
// A keyframe's scan for the map is in that order too, so its returns are looked up one after
// another from where the last one was found (Cursor): a gallop over the few voxels between them,
// not a search of the whole map each time.
struct VoxelEntry {
  std::int32_t x, y, z;
  std::uint32_t index;
  bool operator<(const VoxelEntry& o) const { return x != o.x ? x < o.x : (y != o.y ? y < o.y : z < o.z); }
};
class VoxelTable {
 public:
  // Where the last lookup of a run of ascending voxels ended.
  struct Cursor {
    std::size_t at = 0;
  };

  VoxelTable(const PointCloud& map, double voxel_m) : map_(map), voxel_m_(voxel_m) {
    bool sorted = true;
    VoxelEntry last{}, e{};
    for (std::size_t i = 0; i < map.size() && sorted; ++i) {
      sorted = Of(map.points[i], &e) && (i == 0 || last < e);
      last = e;
    }
    if (sorted) return;
    for (std::size_t i = 0; i < map.size(); ++i)
      if (Of(map.points[i], &e)) entries_.push_back({e.x, e.y, e.z, std::uint32_t(i)});
    std::sort(entries_.begin(), entries_.end());
    sorted_copy_ = true;
  }
  // The map point of p's voxel; false where the map holds none. Fastest when p's voxel follows the
  // cursor's last one.
  bool Find(const PointXYZI& p, Cursor* cursor, std::uint32_t* index) const {
    VoxelEntry e{};
    if (!Of(p, &e)) return false;
    const std::size_t n = size();
    std::size_t lo = cursor->at, hi = n;
    if (lo > 0 && !(At(lo - 1) < e)) lo = 0;  // not past the cursor's last voxel: search from the start
    for (std::size_t step = 1; lo + step <= n; step *= 2) {  // gallop: the first entry not below e lies in (lo, lo + step]
      if (!(At(lo + step - 1) < e)) {
        hi = lo + step - 1;
        break;
      }
      lo += step;
    }
    while (lo < hi) {
      const std::size_t mid = lo + (hi - lo) / 2;
      if (At(mid) < e) lo = mid + 1;
      else hi = mid;
    }
    cursor->at = lo;
    if (lo == n || e < At(lo)) return false;
    *index = sorted_copy_ ? entries_[lo].index : std::uint32_t(lo);
    return true;
  }

 private:
  std::size_t size() const { return sorted_copy_ ? entries_.size() : map_.size(); }
  VoxelEntry At(std::size_t i) const {  // the i-th voxel in order
    if (sorted_copy_) return entries_[i];
    VoxelEntry e{};
    Of(map_.points[i], &e);
    return e;
  }
  bool Of(const PointXYZI& p, VoxelEntry* e) const {  // false beyond 2^31 voxels from the origin
    constexpr std::int64_t kMax = std::numeric_limits<std::int32_t>::max();
    const std::int64_t v[3] = {VoxelIndex(p.x, voxel_m_), VoxelIndex(p.y, voxel_m_), VoxelIndex(p.z, voxel_m_)};
    for (std::int64_t c : v)
      if (c > kMax || c < -kMax) return false;
    *e = {std::int32_t(v[0]), std::int32_t(v[1]), std::int32_t(v[2]), 0};
    return true;
  }
  const PointCloud& map_;
  double voxel_m_;
  bool sorted_copy_ = false;         // false: the map is in voxel order, searched as it is
  std::vector<VoxelEntry> entries_;  // the sorted copy
};

// The keyframe's returns above the ground within submap_radius_m of it (xy; the map points it
// tests), each with its map point (the voxel's; a return whose voxel the map does not hold, outside
// a tile's map, is left out).
struct Returns {
  PointCloud points;
  std::vector<std::uint32_t> map_index;
};
Returns ReturnsAboveGround(const WorldKeyframe& kf, const VoxelTable& table, const geometry::LowestGrid& low,
                          const RemovertConfig& cfg) {
  const PointCloud scan = ScanForMap(kf, cfg, nullptr);
  const Eigen::Vector3d at = kf.T_world_sensor.translation();
  const double reach2 = cfg.submap_radius_m * cfg.submap_radius_m;
  Returns out;
  VoxelTable::Cursor cursor;  // the scan is in voxel order (VoxelDownsample's)
  for (const PointXYZI& p : scan.points) {
    const double dx = p.x - at.x(), dy = p.y - at.y();
    if (dx * dx + dy * dy > reach2) continue;
    if (p.z <= GroundNear(low, p) + float(cfg.map_voxel_m)) continue;  // the ground layer (as GroundwardMask)
    std::uint32_t index = 0;
    if (!table.Find(p, &cursor, &index)) continue;
    out.points.points.push_back(p);
    out.map_index.push_back(index);
  }
  return out;
}

// The returns within reach_m (xy) of a removed one: every body no longer than reach_m that the
// keyframe met lies among them, whole.
std::vector<std::uint32_t> NearRemoved(const Returns& r, const std::vector<std::uint8_t>& removed, double reach_m) {
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells;  // removed returns by xy cell of reach_m
  auto cell = [&](float v) { return std::int64_t(std::floor(double(v) / reach_m)); };
  const auto& pts = r.points.points;
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (removed[r.map_index[i]]) cells[PackXY(cell(pts[i].x), cell(pts[i].y))].push_back(std::uint32_t(i));
  std::vector<std::uint32_t> near;
  if (cells.empty()) return near;
  const float reach2 = float(reach_m * reach_m);
  auto within = [&](std::size_t i) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy) {
        const auto it = cells.find(PackXY(cell(pts[i].x) + dx, cell(pts[i].y) + dy));
        if (it == cells.end()) continue;
        for (std::uint32_t j : it->second) {
          const float ex = pts[j].x - pts[i].x, ey = pts[j].y - pts[i].y;
          if (ex * ex + ey * ey <= reach2) return true;
        }
      }
    return false;
  };
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (within(i)) near.push_back(std::uint32_t(i));
  return near;
}

// Removal's vote pooled over a cluster's map points (members index `near`, whose entries index r): at some
// removal resolution, its see-through votes are at least remove_min_votes and remove_min_ratio of
// its see-through + hit votes. A mover's body passes it as a whole (0.27-1.0 on seed 61's far cars,
// whose lowest rows alone have none); a standing car whose votes went wrong in part does not
// (0.05-0.11 on the default seed's VLP-16, where 35-44 % of a parked car's returns per scan were
// removed).
bool SeenThroughAsOne(const std::vector<std::uint32_t>& members, const std::vector<std::uint32_t>& near, const Returns& r,
                      const VisibilityVotes& votes, const RemovertConfig& cfg) {
  for (int l = 0; l < votes.levels; ++l) {
    double see = 0.0, hit = 0.0;
    for (std::uint32_t j : members) {
      see += votes.See(l, r.map_index[near[j]]);
      hit += votes.Hit(l, r.map_index[near[j]]);
    }
    if (see >= cfg.remove_min_votes && see >= cfg.remove_min_ratio * (see + hit)) return true;
  }
  return false;
}

// The map points of the bodies this keyframe met (the rule above), not removed themselves: the
// clusters of its returns near removed ones: dilate_body_m apart in xy, and in z as far as one
// surface's rows lie apart at their range (at least dilate_body_m).
std::vector<std::uint32_t> BodiesMet(const Returns& r, const Eigen::Vector3f& sensor, const std::vector<std::uint8_t>& removed,
                                     const RemovertConfig& cfg, const VisibilityVotes& votes) {
  const std::vector<std::uint32_t> near = NearRemoved(r, removed, cfg.body_max_m);
  std::vector<std::uint32_t> grown;
  if (near.empty()) return grown;
  const PointCloud pts = r.points.select(near);
  const geometry::SensorModel& m = cfg.sensor_model;
  std::vector<Eigen::Vector2f> gaps(pts.size());
  for (std::size_t j = 0; j < pts.size(); ++j) {  // along the rows dilate_body_m; across them one surface's rows
    const double range = (pts.points[j].xyz() - sensor).norm();
    const float rows = geometry::SampleJoinGaps(m.azimuth_step_deg, m.CoarserStepDeg(), range).y();
    gaps[j] = Eigen::Vector2f(float(cfg.dilate_body_m), std::max(float(cfg.dilate_body_m), rows));
  }
  for (const auto& members : geometry::EuclideanClusterMembers(pts, gaps, 1)) {
    std::size_t in_removed = 0;
    for (std::uint32_t j : members) in_removed += removed[r.map_index[near[j]]];
    if (in_removed == 0 || double(in_removed) < cfg.remove_min_ratio * double(members.size())) continue;
    if (!SeenThroughAsOne(members, near, r, votes, cfg)) continue;
    if (geometry::LongestHorizontalEdge(pts, members) > cfg.body_max_m) continue;
    for (std::uint32_t j : members)
      if (!removed[r.map_index[near[j]]]) grown.push_back(r.map_index[near[j]]);
  }
  return grown;
}

}  // namespace

void CompleteBodies(const PointCloud& map, const std::vector<WorldKeyframe>& keyframes, const RemovertConfig& cfg,
                    const VisibilityVotes& votes, int threads, std::vector<std::uint8_t>* state) {
  if (cfg.body_max_m <= 0.0 || !cfg.SensorResolved() || !cfg.sensor_model.ring_based) return;
  std::vector<std::uint8_t> removed(map.size(), 0);
  bool any = false;
  for (std::size_t i = 0; i < map.size(); ++i) {
    removed[i] = (*state)[i] == HdDecision::kRemoved || (*state)[i] == HdDecision::kDilated;
    any = any || removed[i];
  }
  if (!any) return;
  const VoxelTable table(map, cfg.map_voxel_m);
  geometry::LowestGrid low(cfg.dilate_body_m);
  low.Add(map);
  std::vector<std::uint16_t> returned(map.size(), 0), met(map.size(), 0);
  std::mutex merge;
  ParallelFor(keyframes.size(), threads, [&](std::size_t k) {
    const Returns r = ReturnsAboveGround(keyframes[k], table, low, cfg);
    const Eigen::Vector3f sensor = keyframes[k].T_world_sensor.translation().cast<float>();
    const std::vector<std::uint32_t> grown = BodiesMet(r, sensor, removed, cfg, votes);
    const std::lock_guard<std::mutex> lock(merge);
    for (std::uint32_t i : r.map_index) returned[i] = std::uint16_t(std::min(0xffff, returned[i] + 1));
    for (std::uint32_t i : grown) met[i] = std::uint16_t(std::min(0xffff, met[i] + 1));
  });
  for (std::size_t i = 0; i < map.size(); ++i)
    if (met[i] > 0 && met[i] == returned[i]) (*state)[i] = HdDecision::kDilated;
}

}  // namespace ltm::removert::detail
