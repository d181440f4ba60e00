// Private to src/ltmapper/map: what the object rules share between the step's per-cluster rules
// (objects.cpp) and the rules that join the parts of one object (object_parts.cpp): the ground
// band, the sensor's and the map's sampling at a cluster's range, whether a cluster floats, the
// step's surface its reference never observed, and the parts rules themselves.
#pragma once

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/config.hpp"
#include "ltmapper/map/detail.hpp"
#include "ltmapper/map/map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <memory>
#include <unordered_set>
#include <vector>

namespace ltm::map::detail {

using Floor = geometry::LowestGrid;
constexpr double kDegToRad = M_PI / 180.0;

// An xy cell of a grid `cell` wide (KeyOf), hashable.
struct CellKey {
  std::int64_t x, y;
  bool operator==(const CellKey& o) const { return x == o.x && y == o.y; }
};
struct CellKeyHash {
  std::size_t operator()(const CellKey& c) const { return std::size_t(c.x * 73856093) ^ std::size_t(c.y * 19349663); }
};

inline CellKey KeyOf(const Eigen::Vector3f& p, double cell) {
  return {std::int64_t(std::floor(double(p.x()) / cell)), std::int64_t(std::floor(double(p.y()) / cell))};
}

// The xy cells (`r` wide) that hold some points: a point in one of them or in one of their eight
// neighbours is Near (every point within r of them is). Memory: one entry per occupied cell.
class NearCells {
 public:
  explicit NearCells(double r) : r_(r) {}
  void Add(const Eigen::Vector3f& p) { cells_.insert(Key(KeyOf(p, r_))); }
  bool empty() const { return cells_.empty(); }
  bool Near(const Eigen::Vector3f& p) const {
    const CellKey k = KeyOf(p, r_);
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        if (cells_.count(Key({k.x + dx, k.y + dy}))) return true;
    return false;
  }

 private:
  static std::uint64_t Key(const CellKey& c) { return (std::uint64_t(c.x) << 32) ^ (std::uint64_t(c.y) & 0xffffffffu); }
  double r_;
  std::unordered_set<std::uint64_t> cells_;
};

// Reject's reasons that MergeParts asks for too: a cluster shorter than object_min_length_m, and
// an appeared one most of whose space the reference never observed.
constexpr const char* kSmall = "small";
constexpr const char* kCoverage = "coverage";

// The change points objects are clustered from (GroupPoints): PD and strong ND, not weak ND.
inline bool Grouped(PointClass c) { return IsPd(c) || c == PointClass::kNDStrong; }

// Whether p lies above the ground band: object_ground_height_m over the floor of its cell (or its
// cell holds no floor).
inline bool AboveGround(const Eigen::Vector3f& p, const Floor& floor, const MapConfig& cfg) {
  float z = 0.f;
  return !floor.At(p, &z) || p.z() > z + float(cfg.object_ground_height_m);
}

// Indices of the change points of one group (disappeared: strong ND; appeared: PD) above ground.
inline std::vector<std::uint32_t> GroupPoints(const PointCloud& changes, bool appeared, const Floor& floor,
                                              const MapConfig& cfg) {
  std::vector<std::uint32_t> idx;
  for (std::size_t i = 0; i < changes.size(); ++i) {
    const PointClass c = changes.cls[i];
    if (Grouped(c) && IsPd(c) == appeared && AboveGround(changes.points[i].xyz(), floor, cfg))
      idx.push_back(std::uint32_t(i));
  }
  return idx;
}

// The sensor's sample gaps {horizontal, vertical} [m] that still join a cluster at `range_m`
// (geometry::SampleJoinGaps of its columns and rows: object_sensor_azimuth_step_deg,
// object_sensor_step_deg), before the cluster tolerance's floor.
inline Eigen::Vector2f SensorGapsAt(double range_m, const MapConfig& cfg) {
  return geometry::SampleJoinGaps(cfg.object_sensor_azimuth_step_deg, cfg.object_sensor_step_deg, range_m);
}

// The map's sample spacing: the output voxel, at least the store's quantisation step. An object's
// box grown by it holds the samples of its own surfaces (AttachedFraction, UnseenParts).
inline double SampleSpacing(const MapConfig& cfg) { return std::max(cfg.output_voxel_m, cfg.resolution_m); }

// The spacing of the sensor's rows on a surface at `range_m` facing it: r * object_sensor_step_deg.
inline double RowSpacing(double range_m, const MapConfig& cfg) {
  return range_m * cfg.object_sensor_step_deg * kDegToRad;
}

// The highest a cluster's lowest point may lie above the ground of its cell while it stands on it:
// object_max_clearance_m (the lower part LD matched to the other session's ground), plus one row
// of the sensor at the cluster's range (RowSpacing): the row below its lowest one passed under the
// thing, or over a low wall in front of it, and met the ground (seed 7's container seen over a
// wall from 36 m by an HDL-32E, rows 0.84 m apart there: its lowest point 1.14 m up, "floating").
inline double MaxClearance(const MapObject& o, const MapConfig& cfg) {
  return cfg.object_max_clearance_m + RowSpacing(o.range_m, cfg);
}
// Whether a cluster floats: its lowest point above MaxClearance (the rule off at object_max_clearance_m 0).
inline bool Floats(const MapObject& o, const MapConfig& cfg) {
  return cfg.object_max_clearance_m > 0.0 && o.clearance_m > MaxClearance(o, cfg);
}

// Whether q lies in o's axis-aligned box grown by r (a cheap test before the oriented box).
inline bool InGrownBox(const MapObject& o, const Eigen::Vector3f& q, double r) {
  const Eigen::Vector3d d = q.cast<double>();
  return !((d.array() < o.lo.array() - r).any() || (d.array() > o.hi.array() + r).any());
}

// A thin face (a fence, a hoarding, a wall): its oriented box no wider than the cluster tolerance.
inline bool ThinFace(const MapObject& o, const MapConfig& cfg) { return o.size.y() <= cfg.object_tolerance_m; }

// Whether a face spanning [face_lo, face_hi] along its line runs on past a thing spanning [lo, hi]
// along it by object_min_length_m or more at both ends: a thing standing beside a long face, two
// things (SplitFaces for one cluster of them, FaceRunsPast for two).
inline bool RunsOnPastBothEnds(double face_lo, double face_hi, double lo, double hi, const MapConfig& cfg) {
  return lo - face_lo >= cfg.object_min_length_m && face_hi - hi >= cfg.object_min_length_m;
}

// The step's surfaces its reference never observed near a group's change points, with their tree
// (built once per group: UnobservedBeside walks it for every cluster).
struct UnobservedSurface {
  PointCloud cloud;
  std::shared_ptr<const geometry::KdTree> tree;
  explicit UnobservedSurface(PointCloud c = {})
      : cloud(std::move(c)), tree(cloud.empty() ? nullptr : std::make_shared<const geometry::KdTree>(cloud)) {}
};

// How many points of `unobserved` a cluster reaches through them in hops of the cluster tolerance r.
std::size_t UnobservedBeside(const PointCloud& cluster, const UnobservedSurface& unobserved, double r);

// ---- two things of one cluster (object_split.cpp)
// A cluster's points (indices into the step's changes) and the cluster it was cut from (-1: none).
struct Piece {
  std::vector<std::uint32_t> sel;
  int cut_from = -1;
};
// The clusters with each thin upright face that runs on past the rest of its cluster by
// object_min_length_m (a fence and the tree that left beside it) cut into the face and the rest;
// the largest first.
std::vector<Piece> SplitFaces(const PointCloud& changes, std::vector<std::vector<std::uint32_t>> clusters,
                              const MapConfig& cfg);
// Two pieces SplitFaces cut from one cluster: no rule joins them again.
inline bool CutApart(const MapObject& a, const MapObject& b) { return a.cut_from >= 0 && a.cut_from == b.cut_from; }

// ---- the parts of one object (object_parts.cpp)
// Per cluster, the cluster of the same change that holds it up where it floats (-1: none); lowers
// its clearance to the holder's.
std::vector<int> HoldUp(std::vector<MapObject>& group, const MapConfig& cfg);
// Joins the clusters held up (HoldUp) that both pass the rules to their holders; returns which remain.
std::vector<bool> JoinHeldParts(std::vector<MapObject>& group, const std::vector<int>& holder);
// Lowers a floating cluster's clearance to the group's change points `idx` chained down from it.
void StandOnChangesBelow(std::vector<MapObject>& group, const PointCloud& changes, const std::vector<std::uint32_t>& idx,
                         const Floor& floor, const MapConfig& cfg);
// What a group's clusters did not observe: weak ND (disappeared), the step's unobserved surface (appeared).
PointCloud UnseenPool(const PointCloud& changes, bool appeared, const PointCloud& unobserved, const SessionRecord& step);
// Per cluster, its parts among `pool` the other session did not observe (indices into `pool`).
std::vector<std::vector<std::uint32_t>> UnseenParts(std::vector<MapObject>& group, const PointCloud& pool,
                                                    const Floor& floor, const MapConfig& cfg);
// An object takes its unseen parts (UnseenParts).
void KeepUnseenParts(MapObject& o, const PointCloud& part, const UnobservedSurface& unobserved, const MapConfig& cfg);
// Joins the pieces of one object split by a gap wider than the cluster's (accepted, and some rejected).
void MergeParts(std::deque<MapObject>& objects, std::vector<MapObject>& rejected, const MapConfig& cfg);
// The gap between two pieces of one face (GapBetween: from `whole`'s point nearest `part` to
// `part`'s nearest it, where one of those ends is a thin face pointing at the other): points every
// cluster tolerance along the gap, but for the ones next to its ends, and up the height both pieces
// share, and that height; no points when they are no such pieces.
struct Gap {
  std::vector<Eigen::Vector3d> points;
  double height = 0.0;  // [m] the height both pieces share, the band the gap's points span
  double bottom = 0.0;  // [m] the band's lowest z
  Eigen::Vector2d line = Eigen::Vector2d::UnitX();  // the face's direction across the gap (xy, unit)
  double step = 0.0;    // [m] the points' spacing along it: the width of the hole each stands for
};
Gap GapBetween(const MapObject& whole, const MapObject& part, const MapConfig& cfg);
// Whether the sensor poses of `views` (world from sensor) sampled the gap: each pose with a point of
// the gap in its horizontal field of view (object_sensor_azimuth_*) and a clear line of sight to it
// (no point of `blockers`, above the ground, null: none, within half the cluster tolerance of the
// line before it) adds the share of one row of its samples that falls on the gap's height band at
// that range (RowsOnBand: height / RowSpacing, at most 1), times the share of one column of its
// samples that falls on a point's hole (ColumnsOnHole: the hole's width across the line of sight
// over the column spacing there, at most 1); one row's worth in all is a sample. A far fence's gap
// in clear view of two keyframes of a VLP-16 68 m away (rows 2.4 m apart there, the band 0.6 m
// tall) was likely passed over by their rows; a face seen at a grazing angle from 67 m (seed 31's
// fence 9, 13 deg off the line of sight: columns 1 m apart along it) between its columns.
bool GapSampled(const Gap& gap, const std::vector<Pose>& views, const geometry::KdTree* blockers,
                const MapConfig& cfg);
// The step's changes of one side that objects are clustered from (`at`: GroupPoints), and a tree of
// them flat in xy.
struct SideChanges {
  explicit SideChanges(PointCloud points);
  PointCloud at;
  std::unique_ptr<geometry::KdTree> tree;  // null: no changes
};
// Leaves out the gap's points that a change of the pieces' side lies beside: within the cluster
// tolerance in xy, in the band the pieces share (Gap::bottom, height) grown by the tolerance. The
// face was sampled there and had changed too (seed 31's fence 9, seen at a grazing angle from 67 m:
// columns 1 m apart, each a cluster of its own between the two pieces).
void LeaveOutChanged(Gap& gap, const SideChanges& side, const MapConfig& cfg);
// Two pieces of one face of the same change join across a gap that the keyframes of the
// sessions that scanned them did not sample (GapSampled over the map's surfaces there), but for
// where the gap holds changes of their side (`changes`, the step's): there the face was sampled,
// and changed too.
void JoinHiddenGaps(std::deque<MapObject>& kept, const PointCloud& changes, const Store& store, const SessionRecord& step,
                    const Floor& floor, const MapConfig& cfg);
// Sets each object's hidden_length_m, measured up to upto[k] [m] (an object whose upto is 0 is not
// measured): past each end of its box's length, the columns a cluster tolerance apart (across its
// width, at its middle height) that the sessions that scanned it did not sample (GapSampled, over
// the map's surfaces there), or that changes of its side fill (a fragment of it too small to be a
// cluster), up to the first one they sampled and found free, summed over both ends.
void MeasureHiddenEnds(std::deque<MapObject>& objects, const std::vector<double>& upto, const PointCloud& changes,
                       const Store& store, const SessionRecord& step, const Floor& floor, const MapConfig& cfg);
// Each object takes its foot: the change points of its side in the ground band under it.
void KeepFeet(std::deque<MapObject>& kept, const PointCloud& changes, const Floor& floor, const MapConfig& cfg);

}  // namespace ltm::map::detail
