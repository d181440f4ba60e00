// The parts of one object (steps 3-4 of objects.cpp's list): a cluster held up by another
// (HoldUp, JoinHeldParts) or by change points under it (StandOnChangesBelow), the parts the other
// session did not observe (UnseenPool, UnseenParts, KeepUnseenParts), pieces split by a gap wider
// than the cluster's (MergeParts), and an object's foot in the ground band (KeepFeet). Also how far
// an appeared cluster reaches through the step's surface its reference never observed
// (UnobservedBeside), which the coverage rule and KeepUnseenParts count.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/object_rules.hpp"
#include "ltmapper/map/object_shape.hpp"

#include <algorithm>
#include <deque>
#include <limits>
#include <memory>
#include <numeric>
#include <unordered_set>

namespace ltm::map::detail {
namespace {

// Appends `part` (points with their classes) to `whole` and describes it again (box, class votes, height).
void Absorb(MapObject& whole, const PointCloud& part) {
  whole.cloud.append(part);
  Describe(whole);
  OrientedBox(whole);
  whole.height_above_ground = whole.hi.z() - whole.ground_z;
}

// Whether p lies over or under o's axis-aligned xy box grown by `tol` (ChainBelow, ChainAbove).
bool InColumns(const MapObject& o, const PointXYZI& p, double tol) {
  return double(p.x) >= o.lo.x() - tol && double(p.x) <= o.hi.x() + tol && double(p.y) >= o.lo.y() - tol &&
         double(p.y) <= o.hi.y() + tol;
}

// The points of `by_z` (indices into `changes`, highest first) under o's xy box grown by `tol`
// that reach down from its bottom with no vertical gap wider than `tol`, highest first.
std::vector<std::uint32_t> ChainBelow(const MapObject& o, const PointCloud& changes,
                                      const std::vector<std::uint32_t>& by_z, double tol) {
  std::vector<std::uint32_t> chain;
  double reached = o.lo.z();
  for (std::uint32_t i : by_z) {
    const PointXYZI& p = changes.points[i];
    if (double(p.z) >= o.lo.z() || !InColumns(o, p, tol)) continue;
    if (double(p.z) < reached - tol) break;
    reached = double(p.z);
    chain.push_back(i);
  }
  return chain;
}

// The points of `by_z` (highest first) over o's xy box grown by `tol` that reach up from its top
// with no vertical gap wider than `tol`, lowest first (ChainBelow upside down).
std::vector<std::uint32_t> ChainAbove(const MapObject& o, const PointCloud& changes,
                                      const std::vector<std::uint32_t>& by_z, double tol) {
  std::vector<std::uint32_t> chain;
  double reached = o.hi.z();
  for (auto it = by_z.rbegin(); it != by_z.rend(); ++it) {
    const PointXYZI& p = changes.points[*it];
    if (double(p.z) <= o.hi.z() || !InColumns(o, p, tol)) continue;
    if (double(p.z) > reached + tol) break;
    reached = double(p.z);
    chain.push_back(*it);
  }
  return chain;
}

// `idx` sorted by z, highest first (for ChainBelow, ChainAbove).
std::vector<std::uint32_t> ByZ(const PointCloud& changes, std::vector<std::uint32_t> idx) {
  std::sort(idx.begin(), idx.end(), [&](std::uint32_t a, std::uint32_t b) { return changes.points[a].z > changes.points[b].z; });
  return idx;
}

// Lowers o's clearance to that of the lowest of `chain` above the floor of its cell.
void StandOn(MapObject& o, const PointCloud& changes, const std::vector<std::uint32_t>& chain, const Floor& floor) {
  float z = 0.f;
  if (!chain.empty() && floor.At(changes.points[chain.back()].xyz(), &z))
    o.clearance_m = std::min(o.clearance_m, double(changes.points[chain.back()].z) - double(z));
}

// Share of `part`'s points inside `whole`'s oriented box grown by `margin` (of the points seen: not
// of its unseen parts). The oriented box, not the axis-aligned one: a fence or wall that runs
// diagonally to the map's axes has an axis-aligned box metres wide, and a car parked beside it
// lies inside that.
double InsideShare(const MapObject& part, const MapObject& whole, double margin) {
  const InOrientedBox in_box(whole, margin, margin);
  std::size_t n = 0, seen = 0;
  for (std::size_t i = 0; i < part.cloud.size(); ++i) {
    if (Unseen(part.cloud.cls[i])) continue;
    n += in_box(part.cloud.points[i].xyz().cast<double>()) ? 1 : 0;
    ++seen;
  }
  return double(n) / double(std::max<std::size_t>(seen, 1));
}

// Does `part` come within one missed line of the sensor's samples of `whole`? Clustering joins
// samples up to SensorGapsAt apart (twice the sampling step: a surface seen at up to 60 deg
// incidence), so where the sensor missed one line of samples between two parts of one surface (a
// container's corner, a strip a thin occluder hid) they lie up to twice that apart, horizontally
// and vertically, at the smaller of the two ranges (the finer sampling, as Cluster takes the
// smaller gap). Near the sensor the cluster tolerance, larger there, stays the bound: no part
// joins there that Cluster did not already join. Samples are the points seen (as InsideShare and
// FarSideOf count them): two objects' unseen parts (UnseenParts: the rows over and inside each box
// the other session did not observe) can share points where the boxes meet, and so join nothing.
// Seed 41's car parked at a tree's foot, both gone, was one object with the tree through the weak
// ND at the ground between them (the nearest seen points of the two 1 m or more apart).
bool OneLineApart(const MapObject& part, const MapObject& whole, const MapConfig& cfg) {
  const Eigen::Vector2f reach = (2.f * SensorGapsAt(std::min(part.range_m, whole.range_m), cfg))
                                    .cwiseMax(float(cfg.object_tolerance_m));
  const Eigen::Vector3d grow(reach.x(), reach.x(), reach.y());
  if (((part.lo - whole.hi).array() > grow.array()).any() || ((whole.lo - part.hi).array() > grow.array()).any())
    return false;
  const PointCloud samples = SeenPoints(whole.cloud);
  if (samples.empty()) return false;
  const geometry::KdTree tree(samples);
  for (std::size_t i = 0; i < part.cloud.size(); ++i) {
    if (Unseen(part.cloud.cls[i])) continue;
    const auto& p = part.cloud.points[i];
    for (const auto& hit : tree.RadiusUnsorted(p.xyz(), reach.maxCoeff())) {
      const Eigen::Vector3f d = samples.points[hit.first].xyz() - p.xyz();
      if ((d.head<2>() / reach.x()).squaredNorm() + (d.z() / reach.y()) * (d.z() / reach.y()) < 1.f) return true;
    }
  }
  return false;
}

// Is `part` the far side of `whole`'s box? A view of a box shows its near long side whole, and its
// width only as far as the view reaches; the far long side, seen through other gaps, is a face
// parallel to it: in whole's frame its seen points span no more than the cluster tolerance across,
// lie within whole's length and between the ground under it and its top, reach up to its lowest
// point (all grown by the tolerance: a face of it, not a post under it), and lie at most whole's
// length from its axis (a box is no deeper than it is long: the length is its longer side). Seed
// 7's moved container left its far long face, 2.44 m behind the near one, as a disappeared object
// of its own on three sensors; a VLP-16 37 m from another saw its roof in two rows (1.36-1.78 m
// up) and its far face down to 0.14 m: the box stands on the ground below the roof it showed.
bool FarSideOf(const MapObject& part, const MapObject& whole, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  const BoxFrame frame(whole);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo, top = -lo;
  for (std::size_t i = 0; i < part.cloud.size(); ++i) {
    if (Unseen(part.cloud.cls[i])) continue;
    const Eigen::Vector3d q = part.cloud.points[i].xyz().cast<double>();
    const Eigen::Vector2d l = frame.Local(q);
    const double along = l.x(), across = l.y();
    if (std::abs(along) > 0.5 * whole.size.x() + tol || std::abs(across) > whole.size.x() ||
        q.z() < std::min(whole.lo.z(), whole.ground_z) - tol || q.z() > whole.hi.z() + tol)
      return false;
    lo = std::min(lo, across), hi = std::max(hi, across), top = std::max(top, q.z());
  }
  return hi >= lo && hi - lo <= tol && top >= whole.lo.z() - tol;
}

// Is `face` a thin face (ThinFace) that runs on past `other`, no thin face, by object_min_length_m
// or more on both sides along its length: a thing standing beside a long face? That is two things,
// as SplitFaces cuts one cluster of them (object_split.cpp FaceAndRest); as two clusters they are
// no pieces of each other either. Seed 53's tree 7 stood 0.6 m beside fence 9 and both left; on
// the HDL-32E they were two clusters, one missed line of samples apart 100 m out (OneLineApart),
// and joined: one object of 8159 points, 13.9 x 5.2 m (tree IoU 0.51, the fence not found).
bool FaceRunsPast(const MapObject& face, const MapObject& other, const MapConfig& cfg) {
  if (!ThinFace(face, cfg) || ThinFace(other, cfg)) return false;
  const BoxFrame frame(face);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const auto& p : other.cloud.points) {
    const double along = frame.Local(p.xyz().cast<double>()).x();
    lo = std::min(lo, along), hi = std::max(hi, along);
  }
  const double half = 0.5 * face.size.x();
  return RunsOnPastBothEnds(-half, half, lo, hi, cfg);
}

// Is `part` a piece of `whole`: the same change, not a thing beside a long face (FaceRunsPast,
// either way), and at least object_merge_inside_fraction of its points inside whole's box (grown
// by the tolerance: an occlusion gap), one missed line of samples from it (OneLineApart), or its
// far side (FarSideOf)?
bool PieceOf(const MapObject& part, const MapObject& whole, const MapConfig& cfg) {
  return whole.change == part.change && !CutApart(part, whole) && !FaceRunsPast(part, whole, cfg) &&
         !FaceRunsPast(whole, part, cfg) &&
         (InsideShare(part, whole, cfg.object_tolerance_m) >= cfg.object_merge_inside_fraction ||
          OneLineApart(part, whole, cfg) || FarSideOf(part, whole, cfg));
}

}  // namespace

// How many points of `unobserved` (the step's surfaces its reference never observed, beside the
// group) the cluster's points reach through them in hops of the cluster tolerance r, as Euclidean
// clustering joins points. In a keyframe the step created, an appeared cluster is only what the
// reference's rays reached of a surface that goes on there: a wall's rim row its rays passed where
// the step's pose erred (seed 3's HDL-32E and tilted VLP-16, the stress row's unlooped session
// start). In the reference's keyframes those points are the cluster's own. `unobserved` holds only
// the cells around the group's change points (ReadStepMaps), so the reach ends there.
std::size_t UnobservedBeside(const PointCloud& cluster, const UnobservedSurface& unobserved, double r) {
  if (!unobserved.tree) return 0;
  std::unordered_set<std::uint32_t> reached;
  std::vector<std::uint32_t> front;
  const auto reach_from = [&](const Eigen::Vector3f& p) {
    for (const auto& [j, d] : unobserved.tree->Radius(p, float(r)))
      if (reached.insert(j).second) front.push_back(j);
  };
  for (const auto& p : cluster.points) reach_from(p.xyz());
  while (!front.empty()) {
    const std::uint32_t i = front.back();
    front.pop_back();
    reach_from(unobserved.cloud.points[i].xyz());
  }
  return reached.size();
}

// A cluster that floats (Floats) still stands on the ground when another cluster of the same
// change holds it up: under its xy box (both grown by the cluster tolerance), topping out between
// MaxClearance below its bottom (the rows between them not scanned) and the tolerance above it,
// and itself standing on the ground. A cut tree's canopy and its trunk are two clusters where
// the trunk's top was not scanned; the canopy then takes the trunk's clearance (one level: a
// cluster held up by a floating one still floats). Not by a thin face that runs on past it on
// both sides (FaceRunsPast): a tree's crown over the fence it stood beside, its trunk unseen, is
// no part of the fence. Returns per cluster the index of the one that holds it up (the lowest), or
// -1: the two are parts of one object (JoinHeldParts).
std::vector<int> HoldUp(std::vector<MapObject>& group, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  std::vector<int> holder(group.size(), -1);
  std::vector<double> held(group.size());
  for (std::size_t i = 0; i < group.size(); ++i) {
    const MapObject& o = group[i];
    held[i] = o.clearance_m;
    if (!Floats(o, cfg)) continue;
    for (std::size_t j = 0; j < group.size(); ++j) {
      const MapObject& b = group[j];
      const bool under = (b.lo.head<2>().array() <= o.hi.head<2>().array() + 2.0 * tol).all() &&
                         (b.hi.head<2>().array() >= o.lo.head<2>().array() - 2.0 * tol).all();
      const bool just_below = b.hi.z() <= o.lo.z() + tol && b.hi.z() >= o.lo.z() - MaxClearance(o, cfg);
      if (j != i && under && just_below && !Floats(b, cfg) && !CutApart(o, b) && !FaceRunsPast(b, o, cfg) &&
          b.clearance_m < held[i]) {
        held[i] = b.clearance_m;
        holder[i] = int(j);
      }
    }
  }
  for (std::size_t i = 0; i < group.size(); ++i) group[i].clearance_m = held[i];
  return holder;
}

// A cluster held up by another (HoldUp) that both pass the rules is one object with it: a tree's
// canopy standing on its trunk, a container's top on its side (they were reported twice, the
// upper part a false object). The held part joins its holder; returns which clusters remain.
std::vector<bool> JoinHeldParts(std::vector<MapObject>& group, const std::vector<int>& holder) {
  std::vector<bool> keep(group.size(), true);
  for (std::size_t i = 0; i < group.size(); ++i) {
    const int h = holder[i];
    if (h < 0 || !group[i].rejected.empty() || !group[std::size_t(h)].rejected.empty() || !keep[std::size_t(h)]) continue;
    Absorb(group[std::size_t(h)], group[i].cloud);
    keep[i] = false;
  }
  return keep;
}

// A cluster stands on the group's own change points under it (`idx`: above the ground band),
// reaching down from its bottom with no vertical gap wider than the cluster tolerance: points
// too few to be a cluster of their own (HoldUp needs one) still hold it up. The appeared
// structure whose upper part OS1-64 saw as one cluster and whose lower part as scattered points
// floated.
void StandOnChangesBelow(std::vector<MapObject>& group, const PointCloud& changes, const std::vector<std::uint32_t>& idx,
                         const Floor& floor, const MapConfig& cfg) {
  if (cfg.object_max_clearance_m <= 0.0) return;
  const std::vector<std::uint32_t> by_z = ByZ(changes, idx);
  for (MapObject& o : group)
    if (Floats(o, cfg)) StandOn(o, changes, ChainBelow(o, changes, by_z, cfg.object_tolerance_m), floor);
}

namespace {
// A disappeared thin face's points of `pool` past its ends in its corridor (InFaceCorridor: as far
// as its own length past either end) and above the ground band, chained along its line from either
// end in steps of at most `hop` (UnseenParts' hop over and under it too): the rest of a fence the
// query saw through near one end and never observed beyond. Seed 3's fence 9 (8.9 m long, 73-97 m from the
// central's drive and 79-88 m from the query's, OS1-64): the query saw through 51 of its points, over
// 6 m, and never observed 172, most of them past those; the object held 107 of its 237 points (IoU
// 0.48: a false object and a miss), with its rest 145 (0.65).
std::vector<std::uint32_t> RestOfTheFace(const MapObject& o, const PointCloud& pool, double hop, const Floor& floor,
                                         const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  const BoxFrame frame(o);
  const double end = 0.5 * o.size.x();
  std::vector<std::pair<double, std::uint32_t>> ahead, behind;  // (how far past the end, index)
  for (std::uint32_t i = 0; i < pool.size(); ++i) {
    const Eigen::Vector3d q = pool.points[i].xyz().cast<double>();
    if (!InFaceCorridor(o, frame, q, tol) || !AboveGround(pool.points[i].xyz(), floor, cfg)) continue;
    const double a = frame.Local(q).x();
    if (a > end) ahead.emplace_back(a - end, i);
    if (a < -end) behind.emplace_back(-end - a, i);
  }
  std::vector<std::uint32_t> rest;
  for (auto* side : {&ahead, &behind}) {
    std::sort(side->begin(), side->end());
    double reached = 0.0;
    for (const auto& [past, i] : *side) {
      if (past > reached + hop) break;
      reached = past;
      rest.push_back(i);
    }
  }
  return rest;
}
}  // namespace

// A cluster's parts the other session did not observe, among `pool` (UnseenPool). Of those, the
// ones inside its oriented box (grown by the map's sample spacing: rows between the rows its beams
// passed), chained down from its bottom (ChainBelow), above the ground band, and chained up from
// its top (ChainAbove: the rows over a scanner's cone, or between its beams); a disappeared thin
// face's also along its line past its ends (RestOfTheFace). The cluster's
// clearance is counted from its lowest point (a fence whose upper half the query saw through while
// parked cars hid its lower half stands on the ground, it does not float; a trunk that stayed under
// a cut crown is unchanged, no weak ND); the rules judge what was seen, and an object keeps these
// parts in its cloud. Returns per cluster the parts' indices into `pool`.
std::vector<std::vector<std::uint32_t>> UnseenParts(std::vector<MapObject>& group, const PointCloud& pool,
                                                    const Floor& floor, const MapConfig& cfg) {
  std::vector<std::vector<std::uint32_t>> parts(group.size());
  if (pool.empty() || floor.empty()) return parts;
  std::vector<std::uint32_t> all(pool.size());
  std::iota(all.begin(), all.end(), 0u);
  const std::vector<std::uint32_t> by_z = ByZ(pool, std::move(all));
  const double edge = SampleSpacing(cfg), tol = cfg.object_tolerance_m;
  const double hop = std::max(edge, tol);  // how far apart the rows of an unseen part may lie
  for (std::size_t k = 0; k < group.size(); ++k) {
    const MapObject& o = group[k];
    std::vector<std::uint32_t> columns;  // the unseen points over and under o (one pass), highest first
    for (std::uint32_t i : by_z)
      if (InColumns(o, pool.points[i], hop)) columns.push_back(i);
    const InOrientedBox in_box(o, edge, 0.0);
    for (std::uint32_t i : columns)
      if (InGrownBox(o, pool.points[i].xyz(), edge) && in_box(pool.points[i].xyz().cast<double>()))
        parts[k].push_back(i);
    std::vector<std::uint32_t> lower;
    for (std::uint32_t i : ChainBelow(o, pool, columns, tol))
      if (AboveGround(pool.points[i].xyz(), floor, cfg)) lower.push_back(i);
    parts[k].insert(parts[k].end(), lower.begin(), lower.end());
    for (std::uint32_t i : ChainAbove(o, pool, columns, tol)) parts[k].push_back(i);
    if (o.change == "disappeared" && ThinFace(o, cfg)) {  // its rest may lie in its columns too: once each
      for (std::uint32_t i : RestOfTheFace(o, pool, hop, floor, cfg)) parts[k].push_back(i);
      std::sort(parts[k].begin(), parts[k].end());
      parts[k].erase(std::unique(parts[k].begin(), parts[k].end()), parts[k].end());
    }
    StandOn(group[k], pool, lower, floor);
  }
  return parts;
}

// What a group's clusters did not observe (UnseenParts): for the disappeared group the step's weak
// ND (stored in the columns of strong ND, store.cpp); for the appeared one the step's surface its
// reference never observed within the cluster tolerance's cells of the group (`unobserved`: the
// step's strong PD its changes do not hold; a new fence whose lower rows the reference saw free and
// whose upper rows its beams never reached), labelled as the step's strong PD for the object's cloud.
PointCloud UnseenPool(const PointCloud& changes, bool appeared, const PointCloud& unobserved, const SessionRecord& step) {
  if (!appeared) {
    std::vector<std::uint32_t> weak;
    for (std::size_t i = 0; i < changes.size(); ++i)
      if (Unseen(changes.cls[i])) weak.push_back(std::uint32_t(i));
    return changes.select(weak);
  }
  PointCloud pool = unobserved;
  pool.cls.assign(pool.size(), PointClass::kPDStrong);
  pool.session.assign(pool.size(), std::uint16_t(step.order));
  return pool;
}

// An object keeps its unseen parts (UnseenParts). An appeared object's are surface that
// UnobservedBeside counted beside it: what stays beside it is what it reaches through that surface
// and does not hold, so that its see-through share (Describe) counts each point once.
void KeepUnseenParts(MapObject& o, const PointCloud& part, const UnobservedSurface& unobserved, const MapConfig& cfg) {
  if (o.change == "appeared") {
    PointCloud all = o.cloud;
    all.append(part);
    o.unobserved_beside = UnobservedBeside(all, unobserved, cfg.object_tolerance_m) - part.size();
  }
  Absorb(o, part);
}

// Parts of one object split by a gap wider than the cluster's: an accepted cluster that is a piece
// of a larger accepted one (PieceOf) joins it; so does a cluster of `rejected` rejected only for its
// length (kSmall): too short to be an object alone, it is the part of one that an occluder cut off
// (a car behind a pole); and an appeared one rejected for coverage (kCoverage: the reference never
// observed most of its space) that is a piece of a larger appeared object: the reference saw that
// object's space free, and a thing that came is new as a whole (the far half of a container 62 m
// out whose near half the reference saw free: vlp16_drift3x). What joined an object leaves
// `rejected`.
void MergeParts(std::deque<MapObject>& objects, std::vector<MapObject>& rejected, const MapConfig& cfg) {
  if (cfg.object_merge_inside_fraction <= 0.0) return;
  std::sort(objects.begin(), objects.end(), [](const MapObject& a, const MapObject& b) { return a.points > b.points; });
  std::deque<MapObject> out;
  const auto whole_of = [&](const MapObject& o) -> MapObject* {
    for (auto& w : out)
      if (PieceOf(o, w, cfg)) return &w;
    return nullptr;
  };
  for (auto& o : objects) {
    if (MapObject* whole = whole_of(o))
      Absorb(*whole, o.cloud);
    else
      out.push_back(std::move(o));
  }
  const auto joins = [&](const MapObject& r) -> MapObject* {
    MapObject* whole = r.rejected == kSmall || r.rejected == kCoverage ? whole_of(r) : nullptr;
    return whole && (r.rejected == kSmall || whole->points > r.points) ? whole : nullptr;
  };
  std::vector<MapObject> still;
  for (auto& r : rejected) {
    if (MapObject* whole = joins(r))
      Absorb(*whole, r.cloud);
    else
      still.push_back(std::move(r));
  }
  rejected.swap(still);
  objects.swap(out);
}

// An object's foot: the change points of its side in the ground band (GroupPoints leaves them out,
// as they would glue objects to the ground and to each other) inside its oriented box grown by the
// map's sample spacing: those as high as its bottom or higher (where a cell holds no ground, its
// band reaches up there) and those chained down from its bottom (ChainBelow). A
// container's lowest rows and a car's wheels are the object's own surfaces: its cloud keeps them,
// each point in the first object that claims it. The rules judged the object without them.
void KeepFeet(std::deque<MapObject>& kept, const PointCloud& changes, const Floor& floor, const MapConfig& cfg) {
  std::vector<std::uint32_t> band;
  for (std::size_t i = 0; i < changes.size(); ++i)
    if (Grouped(changes.cls[i]) && !AboveGround(changes.points[i].xyz(), floor, cfg)) band.push_back(std::uint32_t(i));
  if (band.empty()) return;
  const std::vector<std::uint32_t> by_z = ByZ(changes, std::move(band));
  std::unordered_set<std::uint32_t> taken;
  const double edge = SampleSpacing(cfg);
  for (MapObject& o : kept) {
    const InOrientedBox in_box(o, edge, std::numeric_limits<double>::infinity());
    std::vector<std::uint32_t> side, foot;  // the band's points of o's side in its box's columns, highest first
    for (std::uint32_t i : by_z) {
      if (IsPd(changes.cls[i]) != IsPd(o.cls) || taken.count(i) || !in_box(changes.points[i].xyz().cast<double>()))
        continue;
      side.push_back(i);
      if (double(changes.points[i].z) >= o.lo.z()) foot.push_back(i);
    }
    const std::vector<std::uint32_t> below = ChainBelow(o, changes, side, cfg.object_tolerance_m);
    foot.insert(foot.end(), below.begin(), below.end());
    if (foot.empty()) continue;
    taken.insert(foot.begin(), foot.end());
    Absorb(o, changes.select(foot));
  }
}


namespace {
// The xy-closest pair of points of a and b: (index into a, index into b).
std::pair<std::uint32_t, std::uint32_t> ClosestPair(const PointCloud& a, const PointCloud& b) {
  PointCloud flat;
  for (const auto& p : b.points) flat.push_back(p.x, p.y, 0.0f);
  const geometry::KdTree tree(std::move(flat));
  std::pair<std::uint32_t, std::uint32_t> best{0, 0};
  float best_d = std::numeric_limits<float>::infinity();
  for (std::uint32_t i = 0; i < a.size(); ++i) {
    std::uint32_t j = 0;
    float d = 0.0f;
    if (tree.Nearest(Eigen::Vector3f(a.points[i].x, a.points[i].y, 0.0f), &j, &d) && d < best_d) best_d = d, best = {i, j};
  }
  return best;
}

// A piece's end at p: its points within two cluster tolerances of p in xy (indices).
std::vector<std::uint32_t> EndAt(const PointCloud& cloud, const Eigen::Vector2d& p, double tol) {
  std::vector<std::uint32_t> end;
  for (std::uint32_t i = 0; i < cloud.size(); ++i)
    if ((Eigen::Vector2d(cloud.points[i].x, cloud.points[i].y) - p).norm() <= 2.0 * tol) end.push_back(i);
  return end;
}

// Whether a piece's end (EndAt p) is a face pointing at q across the gap: a strip no wider than
// the cluster tolerance and at least that long, whose centre line carried on past p passes within
// the tolerance of q. A wall's stub at a corner is one; a car's end, or a face beside q's line, is not.
bool FacesAcross(const PointCloud& cloud, const std::vector<std::uint32_t>& end, const Eigen::Vector2d& p,
                 const Eigen::Vector2d& q, double tol) {
  if (end.size() < 2) return false;
  const geometry::HorizontalBox b = geometry::SidesBoxOf(cloud, end);
  if (b.width > tol || b.length < tol) return false;
  const Eigen::Vector2d axis(std::cos(b.yaw_rad), std::sin(b.yaw_rad)), d = q - b.center;
  const double along = d.dot(axis), across = std::abs(axis.x() * d.y() - axis.y() * d.x());
  return across <= tol && std::abs(along) > 0.5 * b.length && along * (p - b.center).dot(axis) > 0.0;
}

}  // namespace

// Two pieces of one face may lie apart along its line where the sessions that scanned it never
// saw the gap: a static surface hid it from every keyframe whose field of view held it (the
// rosette's fence, default seed: sampled at 0-5 m and 11-13.5 m of its 13.5 m; a structure 11-14 m
// out hid the middle from keyframes 32-42, and the keyframes with a clear line of sight to it had it
// 44-130 deg off their forward cone), or the few keyframes with a clear line to it had their rows
// pass above and below it (seed 23's fence 9 on the tilted VLP-16, 63-67 m out: 1-2 clear views of
// a gap 0.6 m tall, rows 2.3 m apart there). The pieces need not be thin faces, only their facing
// ends one (FacesAcross): seed 31's walled lot (walls on all four sides, 22.9 m by 11 m) was two
// clusters, the front wall with a 1.3 m stub of a side wall and the back wall with a 0.4 m one; the
// side wall's middle 8.9 m no keyframe saw. Where the keyframes looking that way sampled the gap
// (GapSampled), the face was not there (a gate, two fences), and the pieces stay apart. A piece ends
// where its views' sight ended, at an occluder's edge that the map holds only to the blocker radius:
// the gap's points one spacing (about a tolerance) from an end are left out (a keyframe's line past
// the edge of the building that hid seed 31's side wall reached 0.5 m beyond its stub, not 1 m).
Gap GapBetween(const MapObject& whole, const MapObject& part, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  if (whole.cloud.empty() || part.cloud.empty()) return {};
  const auto [i, j] = ClosestPair(whole.cloud, part.cloud);
  const Eigen::Vector2d p(whole.cloud.points[i].x, whole.cloud.points[i].y), q(part.cloud.points[j].x, part.cloud.points[j].y);
  if ((q - p).norm() <= tol) return {};  // beside each other: MergeParts' pieces
  const std::vector<std::uint32_t> end_w = EndAt(whole.cloud, p, tol), end_p = EndAt(part.cloud, q, tol);
  if (!FacesAcross(whole.cloud, end_w, p, q, tol) && !FacesAcross(part.cloud, end_p, q, p, tol)) return {};
  const double z_lo = std::max(whole.lo.z(), part.lo.z()), z_hi = std::min(whole.hi.z(), part.hi.z());
  if (z_hi < z_lo) return {};  // no height in common: not one face
  const double len = (q - p).norm();
  const int along = std::max(1, int(std::floor(len / tol)) - 1), up = std::max(1, int(std::floor((z_hi - z_lo) / tol)));
  Gap gap;
  gap.height = z_hi - z_lo;
  gap.bottom = z_lo;
  gap.line = (q - p) / len;
  gap.step = len / double(along + 1);
  const int margin = along >= 3 ? 1 : 0;  // the points next to an end: see above
  for (int a = 1 + margin; a <= along - margin; ++a) {
    const Eigen::Vector2d xy = p + (q - p) * double(a) / double(along + 1);
    for (int k = 0; k < up; ++k) gap.points.emplace_back(xy.x(), xy.y(), z_lo + (z_hi - z_lo) * (k + 0.5) / up);
  }
  return gap;
}

namespace {
// Whether direction d (world) lies in the horizontal field of view of a sensor at pose T.
bool InView(const Pose& T, const Eigen::Vector3d& d, const MapConfig& cfg) {
  const double half = cfg.object_sensor_azimuth_half_fov_deg;
  if (half <= 0.0) return true;  // not known: every direction
  const Eigen::Vector3d l = T.linear().transpose() * d;
  return geometry::InAzimuthArc(std::atan2(l.y(), l.x()) / kDegToRad, cfg.object_sensor_azimuth_center_deg, half);
}

// The in-view lines of sight of GapSampled, view by view (its index `v`), each walked every half
// tolerance from the sensor to a tolerance short of the gap point (the face's own ends are no
// blockers of it), `len` long to the gap point.
template <class Step>
void WalkLines(const std::vector<Eigen::Vector3d>& gap, const std::vector<Pose>& views, const MapConfig& cfg,
               const Step& step) {
  const double r = 0.5 * cfg.object_tolerance_m;
  for (std::size_t v = 0; v < views.size(); ++v)
    for (const Eigen::Vector3d& g : gap) {
      const Pose& T = views[v];
      const Eigen::Vector3d s = T.translation(), d = g - s;
      const double len = d.norm();
      if (len <= 0.0 || !InView(T, d, cfg)) continue;
      const Eigen::Vector3d u = d / len;
      if (!step(v, s, u, std::max(r, len - cfg.object_tolerance_m), len)) return;
    }
}

// The share of one row of the sensor's samples that falls on a band `height_m` tall at `range_m`:
// rows RowSpacing apart land on it with odds height / spacing (1 where the step is unknown).
double RowsOnBand(double height_m, double range_m, const MapConfig& cfg) {
  const double spacing = RowSpacing(range_m, cfg);
  return spacing > 0.0 ? std::min(1.0, height_m / spacing) : 1.0;
}

// The share of one column of the sensor's samples that falls on a gap point's hole (gap.step wide
// along the face) seen along `u` from `range_m`: its width across the line of sight over the
// columns' spacing there, range * object_sensor_azimuth_step_deg (1 where the step is unknown).
double ColumnsOnHole(const Gap& gap, const Eigen::Vector3d& u, double range_m, const MapConfig& cfg) {
  const double spacing = range_m * cfg.object_sensor_azimuth_step_deg * kDegToRad, flat = u.head<2>().norm();
  if (!(spacing > 0.0) || flat <= 0.0) return 1.0;
  const double across = gap.step * std::abs(u.x() * gap.line.y() - u.y() * gap.line.x()) / flat;
  return std::min(1.0, across / spacing);
}
}  // namespace

bool GapSampled(const Gap& gap, const std::vector<Pose>& views, const geometry::KdTree* blockers,
                const MapConfig& cfg) {
  const float r = float(0.5 * cfg.object_tolerance_m);
  double rows = 0.0, view_rows = 0.0;  // the sum over the views done, the current view's best
  std::size_t view = views.size();
  WalkLines(gap.points, views, cfg,
            [&](std::size_t v, const Eigen::Vector3d& s, const Eigen::Vector3d& u, double until, double len) {
              if (v != view) rows += view_rows, view_rows = 0.0, view = v;
              const double here = RowsOnBand(gap.height, len, cfg) * ColumnsOnHole(gap, u, len, cfg);
              if (here <= view_rows) return true;  // this view has a line as good already
              bool blocked = false;
              for (double t = r; t < until && !blocked && blockers; t += r)
                blocked = blockers->CountWithin((s + u * t).cast<float>(), r, 1) > 0;
              if (!blocked) view_rows = here;
              return rows + view_rows < 1.0;  // go on until one row's worth of samples
            });
  return rows + view_rows >= 1.0;
}

namespace {
// The xy cells (half a tolerance wide) the in-view lines of sight pass over: with their
// neighbours, the only places a blocker of GapSampled can lie (NearCells).
NearCells CellsOnLines(const std::vector<std::vector<Eigen::Vector3d>>& gaps, const std::vector<Pose>& views,
                       const MapConfig& cfg) {
  const double r = 0.5 * cfg.object_tolerance_m;
  NearCells cells(r);
  for (const auto& gap : gaps)
    WalkLines(gap, views, cfg,
              [&](std::size_t, const Eigen::Vector3d& s, const Eigen::Vector3d& u, double until, double) {
                for (double t = 0.0; t < until + r; t += r) cells.Add((s + u * t).cast<float>());
                return true;
              });
  return cells;
}

// Where the sessions that scanned a change of the step looked from: the step's session for what
// appeared, the sessions up to its reference for what disappeared (empty: a store without them).
std::vector<Pose> ViewsOf(const Store& store, const SessionRecord& step, bool appeared) {
  std::vector<Pose> views;
  for (int s = appeared ? step.order : 0; s <= (appeared ? step.order : step.reference); ++s) {
    const std::vector<Pose> t = store.Trajectory(s);
    views.insert(views.end(), t.begin(), t.end());
  }
  return views;
}

// The map's surfaces above the ground (the map after the step for what appeared, at the reference
// for what disappeared) over `cells`, streamed in their bounding box.
PointCloud BlockersOver(const NearCells& cells, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                        const Store& store, int session, const Floor& floor, const MapConfig& cfg) {
  const double r = 0.5 * cfg.object_tolerance_m;
  Region box;
  box.use_box = true, box.lo = lo.array() - r, box.hi = hi.array() + r;
  PointCloud out;
  store.StreamMapAt(session, box, [&](PointCloud&& part) {
    for (const auto& p : part.points)
      if (cells.Near(p.xyz()) && AboveGround(p.xyz(), floor, cfg)) out.push_back(p.x, p.y, p.z);
  });
  return out;
}

// The map's surfaces above the ground (BlockersOver, at `session`) that could block an in-view line
// of sight from `views` to a point of `gaps` (GapSampled's blockers), in a tree; null: none.
std::unique_ptr<geometry::KdTree> BlockersOfLines(const std::vector<std::vector<Eigen::Vector3d>>& gaps,
                                                  const std::vector<Pose>& views, const Store& store, int session,
                                                  const Floor& floor, const MapConfig& cfg) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& gap : gaps)
    for (const auto& g : gap) lo = lo.cwiseMin(g), hi = hi.cwiseMax(g);
  for (const Pose& T : views) lo = lo.cwiseMin(T.translation()), hi = hi.cwiseMax(T.translation());
  const PointCloud blockers = BlockersOver(CellsOnLines(gaps, views, cfg), lo, hi, store, session, floor, cfg);
  return blockers.empty() ? nullptr : std::make_unique<geometry::KdTree>(blockers);
}

struct GapPair {
  std::size_t whole, part;
  Gap gap;
};
}  // namespace

SideChanges::SideChanges(PointCloud points) : at(std::move(points)) {
  PointCloud flat;
  for (const auto& p : at.points) flat.push_back(p.x, p.y, 0.f);
  if (!flat.empty()) tree = std::make_unique<geometry::KdTree>(std::move(flat));
}

void LeaveOutChanged(Gap& gap, const SideChanges& side, const MapConfig& cfg) {
  if (!side.tree) return;
  const double tol = cfg.object_tolerance_m;
  std::vector<Eigen::Vector3d> open;
  for (const auto& g : gap.points) {
    bool changed = false;
    for (const auto& [j, sq] : side.tree->RadiusUnsorted(Eigen::Vector3f(float(g.x()), float(g.y()), 0.f), float(tol))) {
      const double z = side.at.points[j].z;
      changed = changed || (z >= gap.bottom - tol && z <= gap.bottom + gap.height + tol);
    }
    if (!changed) open.push_back(g);
  }
  gap.points.swap(open);
}

void JoinHiddenGaps(std::deque<MapObject>& kept, const PointCloud& changes, const Store& store, const SessionRecord& step,
                    const Floor& floor, const MapConfig& cfg) {
  if (cfg.object_merge_inside_fraction <= 0.0) return;
  for (const bool appeared : {false, true}) {
    std::vector<GapPair> pairs;  // the larger of the two (the first of equals) is the whole
    const auto whole_and_part = [&](std::size_t i, std::size_t j) {
      return i != j && (kept[i].change == "appeared") == appeared && kept[j].change == kept[i].change &&
             (kept[i].points > kept[j].points || (kept[i].points == kept[j].points && i < j));
    };
    for (std::size_t i = 0; i < kept.size(); ++i)
      for (std::size_t j = 0; j < kept.size(); ++j)
        if (whole_and_part(i, j))
          if (Gap gap = GapBetween(kept[i], kept[j], cfg); !gap.points.empty()) pairs.push_back({i, j, std::move(gap)});
    if (!pairs.empty()) {
      const SideChanges side(changes.select(GroupPoints(changes, appeared, floor, cfg)));
      for (auto& p : pairs) LeaveOutChanged(p.gap, side, cfg);
    }
    const std::vector<Pose> views = pairs.empty() ? std::vector<Pose>() : ViewsOf(store, step, appeared);
    if (views.empty()) continue;
    std::vector<std::vector<Eigen::Vector3d>> gaps;
    for (const auto& p : pairs) gaps.push_back(p.gap.points);
    const std::unique_ptr<geometry::KdTree> tree =
        BlockersOfLines(gaps, views, store, appeared ? step.order : step.reference, floor, cfg);
    std::vector<bool> joined(kept.size(), false);
    for (const auto& p : pairs) {
      if (joined[p.whole] || joined[p.part] || (!p.gap.points.empty() && GapSampled(p.gap, views, tree.get(), cfg)))
        continue;
      Absorb(kept[p.whole], kept[p.part].cloud);
      joined[p.part] = true;
    }
    std::deque<MapObject> out;
    for (std::size_t k = 0; k < kept.size(); ++k)
      if (!joined[k]) out.push_back(std::move(kept[k]));
    kept.swap(out);
  }
}

namespace {
// Where o's end `end` (+1 or -1 along its oriented box's length axis) is: across the axis, the
// offsets from the box's centre line of its points within a cluster tolerance of that end, a
// tolerance apart (the face it ends with, or the one face of an L that reaches it).
std::vector<double> EndAcross(const MapObject& o, int end, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  const BoxFrame frame(o);
  std::vector<long> slots;
  for (const auto& p : o.cloud.points) {
    const Eigen::Vector2d d = frame.Local(p.xyz().cast<double>());
    if (double(end) * d.x() >= 0.5 * o.size.x() - tol) slots.push_back(std::lround(d.y() / tol));
  }
  std::sort(slots.begin(), slots.end());
  slots.erase(std::unique(slots.begin(), slots.end()), slots.end());
  std::vector<double> out;
  for (const long k : slots) out.push_back(double(k) * tol);
  return out;
}

// The column `past` [m] beyond o's end `end`, a cluster tolerance wide along its length: a point at
// each offset `across` (EndAcross), at the middle of o's height band.
Gap ColumnPastEnd(const MapObject& o, int end, double past, const std::vector<double>& offsets, const MapConfig& cfg) {
  const BoxFrame frame(o);
  Gap column;
  column.height = o.hi.z() - o.lo.z();
  column.bottom = o.lo.z();
  column.line = Eigen::Vector2d(std::cos(o.yaw_rad), std::sin(o.yaw_rad));
  column.step = cfg.object_tolerance_m;
  for (const double w : offsets) {
    const Eigen::Vector2d xy = frame.World(double(end) * (0.5 * o.size.x() + past), w);
    column.points.emplace_back(xy.x(), xy.y(), column.bottom + 0.5 * column.height);
  }
  return column;
}

// One end of an object, and its columns outwards (ColumnPastEnd), a tolerance apart, as far as
// upto (MeasureHiddenEnds) reaches.
struct EndColumns {
  std::size_t object;
  int end;
  std::vector<Gap> columns;
};
std::vector<EndColumns> EndsToMeasure(const std::deque<MapObject>& objects, const std::vector<double>& upto,
                                      bool appeared, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  std::vector<EndColumns> ends;
  for (std::size_t k = 0; k < objects.size(); ++k) {
    if ((objects[k].change == "appeared") != appeared || !(upto[k] > 0.0)) continue;
    for (const int end : {-1, 1}) {
      ends.push_back({k, end, {}});
      const std::vector<double> offsets = EndAcross(objects[k], end, cfg);
      for (double past = tol; past < upto[k] + tol && !offsets.empty(); past += tol)
        ends.back().columns.push_back(ColumnPastEnd(objects[k], end, past, offsets, cfg));
    }
  }
  return ends;
}

// The step's changes of one side (PD or strong ND) at any height: a far fragment whose cell holds
// no ground sample is its own floor (GroupPoints leaves it out), and EndFilled takes the object's
// own ground instead.
SideChanges AllOfSide(const PointCloud& changes, bool appeared) {
  std::vector<std::uint32_t> idx;
  for (std::size_t i = 0; i < changes.size(); ++i)
    if (Grouped(changes.cls[i]) && IsPd(changes.cls[i]) == appeared) idx.push_back(std::uint32_t(i));
  return SideChanges(changes.select(idx));
}

// Whether a change of o's side lies within the cluster tolerance (xy) of a point of `column` past
// o's end `end` (outside its box: not o's own), above the ground band over o's ground and at most a
// tolerance over its top: a fragment of it.
bool EndFilled(const Gap& column, const MapObject& o, int end, const SideChanges& side, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m, lo = o.ground_z + cfg.object_ground_height_m, hi = o.hi.z() + tol;
  const BoxFrame frame(o);
  const auto past_end = [&](const PointXYZI& p) {
    return double(end) * frame.Local(p.xyz().cast<double>()).x() > 0.5 * o.size.x();
  };
  if (!side.tree) return false;
  for (const auto& g : column.points)
    for (const auto& [j, sq] : side.tree->RadiusUnsorted(Eigen::Vector3f(float(g.x()), float(g.y()), 0.f), float(tol))) {
      const PointXYZI& p = side.at.points[j];
      if (p.z > lo && p.z <= hi && past_end(p)) return true;
    }
  return false;
}

// Per end, how many of its columns in a row from its end are hidden: filled (EndFilled), or not
// sampled by `views` (GapSampled over the map's blockers at `session`; no views: every column not
// filled counts as sampled). Two rounds, each with the map's blockers of its own lines of sight
// only: most ends stop at their first column the changes do not fill, so the first round judges
// those alone, the second the rest of the ends that went on past them.
std::vector<std::size_t> HiddenColumns(const std::vector<EndColumns>& ends, const std::vector<std::vector<bool>>& filled,
                                       const std::vector<Pose>& views, const Store& store, int session,
                                       const Floor& floor, const MapConfig& cfg) {
  std::vector<std::size_t> hidden(ends.size(), 0);  // per end: columns hidden so far
  std::vector<bool> open(ends.size(), true);        // per end: not yet stopped at a sampled column
  for (const bool first : {true, false}) {
    std::vector<std::vector<Eigen::Vector3d>> lines;
    for (std::size_t n = 0; n < ends.size(); ++n) {
      while (open[n] && hidden[n] < ends[n].columns.size() && filled[n][hidden[n]]) ++hidden[n];
      open[n] = open[n] && hidden[n] < ends[n].columns.size();
      for (std::size_t c = hidden[n]; open[n] && c < ends[n].columns.size() && (!first || c == hidden[n]); ++c)
        if (!filled[n][c]) lines.push_back(ends[n].columns[c].points);
    }
    if (lines.empty()) break;
    const std::unique_ptr<geometry::KdTree> tree =
        views.empty() ? nullptr : BlockersOfLines(lines, views, store, session, floor, cfg);
    const auto hidden_column = [&](std::size_t n, std::size_t c) {
      return filled[n][c] || (!views.empty() && !GapSampled(ends[n].columns[c], views, tree.get(), cfg));
    };
    for (std::size_t n = 0; n < ends.size(); ++n) {
      if (!open[n]) continue;
      if (!first)
        while (hidden[n] < ends[n].columns.size() && hidden_column(n, hidden[n])) ++hidden[n];
      else if (hidden_column(n, hidden[n]))  // the first column the changes do not fill
        ++hidden[n];
      else
        open[n] = false;
    }
  }
  return hidden;
}
}  // namespace

void MeasureHiddenEnds(std::deque<MapObject>& objects, const std::vector<double>& upto, const PointCloud& changes,
                       const Store& store, const SessionRecord& step, const Floor& floor, const MapConfig& cfg) {
  for (const bool appeared : {false, true}) {
    const std::vector<EndColumns> ends = EndsToMeasure(objects, upto, appeared, cfg);
    if (ends.empty()) continue;
    const SideChanges side = AllOfSide(changes, appeared);
    std::vector<std::vector<bool>> filled;  // per end, per column: EndFilled
    for (const auto& e : ends) {
      filled.emplace_back();
      for (const Gap& column : e.columns) filled.back().push_back(EndFilled(column, objects[e.object], e.end, side, cfg));
    }
    const std::vector<std::size_t> hidden = HiddenColumns(ends, filled, ViewsOf(store, step, appeared), store,
                                                          appeared ? step.order : step.reference, floor, cfg);
    for (std::size_t n = 0; n < ends.size(); ++n)
      objects[ends[n].object].hidden_length_m += double(hidden[n]) * cfg.object_tolerance_m;
  }
}
}  // namespace ltm::map::detail
