// Automatic parsing of ephemeral objects (paper sec. "Automatic Parsing of Ephemeral Objects"),
// made into objects a user can act on. Per session step:
//  1. Ground: change points within object_ground_height_m above the lowest map point of their
//     xy cell (object_ground_cell_m) are ground, not clustered (they glue objects together).
//  2. Euclidean clustering (geometry::EuclideanClusterMembers) of strong ND (disappeared) and of
//     PD (appeared) separately, far out with the gaps of the sensor's rows and columns at the
//     points' range (SampleGaps); a thin face that runs on past the rest of its cluster is one
//     thing and the rest another (SplitFaces, object_split.cpp).
//  3. Coverage: a change is an object only in space both sessions observed. Strong ND is by
//     definition seen through by the query. PD is weak when the reference saw its space free,
//     strong when it never saw there (new territory, facades newly in view) or its view was
//     blocked: an appeared cluster needs a majority of weak PD (among its points and the step's
//     strong PD beside them that its changes do not hold: UnobservedBeside; a thin face's along
//     its line too: FollowFaces), or a disappeared cluster of the
//     step between it and the nearest reference keyframe and the shape of an object the step
//     removed (that object moved there; anything else revealed behind it is coverage).
//  4. Geometry (Reject()): ghosts of misalignment, height above ground, width across the sensor's sampling at the
//     cluster's range, flat horizontal patches, optional maximum extent.
//     A cluster that floats but stands on another of the same change (HoldUp; not on a thin face
//     that runs on past it on both sides) is a part of it:
//     when both pass the rules they are joined (JoinHeldParts), as are parts inside a larger
//     object's box, one missed line of the sensor's samples from it, or its box's far side
//     (MergeParts; an appeared part rejected for coverage too; never a thing beside a thin face
//     that runs on past it on both sides, FaceRunsPast), and two pieces of one face
//     (their facing ends, one a thin face pointing at the other) across a gap the keyframes
//     looking that way did not sample (JoinHiddenGaps). A cluster
//     also stands on change points of its group under it (StandOnChangesBelow), and on its lower
//     part the other session did not observe; an object keeps that part and the rows the other
//     session did not observe inside its box and over it (UnseenParts: weak ND of a disappeared
//     one, and a disappeared thin face's rest along its line; the step's surface its reference
//     never observed of an appeared one), and every object
//     its foot, the changes of its side in the ground band under it (KeepFeet). Its confidence
//     is rated over all it then holds (Rate). The rules that join parts live in object_parts.cpp;
//     what both files read (the ground band, the sampling at a range) in object_rules.hpp.
// Then over all steps (object_identity.cpp, detail::IdentifyAcrossSteps):
//  5. Once: a disappeared cluster on the unseen parts of an object an earlier step reported gone
//     confirms that object and is no second one (Confirms, SetAsideConfirmations).
//  6. Moved: a disappeared and an appeared object of one step whose box lengths and tops above the
//     ground agree within what the sensor's sampling lets each view fall short (SizesAgree,
//     CouldHaveMoved), a view's length also by how far past its ends its side's changes run on or
//     its sessions never sampled (MeasureHiddenEnds, per step, object_parts.cpp), neither standing
//     among unchanged objects of its shape (AlikeIn, counted per step), nor being an earlier step's
//     move's end seen again; of such pairings, the one that moves the objects least in all
//     (LinkMoved).
//  7. Tracks: rows of different steps that are one object, and a move's two ends (AssignTracks,
//     InheritMoves).
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/detail.hpp"
#include "ltmapper/map/map.hpp"
#include "ltmapper/map/object_rules.hpp"
#include "ltmapper/map/object_shape.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

namespace ltm::map {
namespace {

// Confidence margins reach 1 when a measure is this many times its minimum.
constexpr double kFullMargin = 2.0;
// Evidence of a revealed appeared cluster (blocked reference view, no see-through): half.
constexpr double kRevealedEvidence = 0.5;



using detail::AboveGround;
using detail::CellKey;
using detail::CellKeyHash;
using detail::KeyOf;
using detail::NearCells;
using detail::BoxFrame;
using detail::Clearance;
using detail::CouldHaveMoved;
using detail::Describe;
using detail::Floats;
using detail::Floor;
using detail::Grouped;
using detail::GroupPoints;
using detail::HoldUp;
using detail::FaceReach;
using detail::InFaceCorridor;
using detail::InGrownBox;
using detail::InOrientedBox;
using detail::JoinHiddenGaps;
using detail::IsPd;
using detail::JoinHeldParts;
using detail::KeepFeet;
using detail::kDegToRad;
using detail::KeepUnseenParts;
using detail::kCoverage;
using detail::kSmall;
using detail::MergeParts;
using detail::OrientedBox;
using detail::RowSpacing;
using detail::SampleSpacing;
using detail::SeenThrough;
using detail::SegmentHitsBox;
using detail::SensorGapsAt;
using detail::Spread;
using detail::Spread3;
using detail::SplitFaces;
using detail::StandOnChangesBelow;
using detail::ThinFace;
using detail::UnobservedBeside;
using detail::UnobservedSurface;
using detail::Unseen;
using detail::UnseenParts;
using detail::UnseenPool;
using detail::Width;


// The other side of a change: PD (the query's new surfaces) for disappeared clusters, strong ND
// (the reference's surfaces the query saw through) for appeared ones. Not weak ND: the wall
// behind a car that appeared is weak ND (the car hides it from the query), not its twin.
PointCloud OtherSide(const PointCloud& changes, bool appeared) {
  std::vector<bool> mask(changes.size());
  for (std::size_t i = 0; i < changes.size(); ++i) {
    const PointClass c = changes.cls[i];
    mask[i] = appeared ? c == PointClass::kNDStrong : IsPd(c);
  }
  return changes.select(mask);
}


// The points of `other` above ground in the xy cells (`r` wide) around the change points of
// `idx`: the only ones within `r` of them.
PointCloud NearbyAboveGround(const PointCloud& changes, const std::vector<std::uint32_t>& idx, const PointCloud& other,
                             const Floor& floor, const MapConfig& cfg, double r) {
  PointCloud nearby;
  if (r <= 0.0 || idx.empty()) return nearby;
  NearCells near(r);
  for (auto i : idx) near.Add(changes.points[i].xyz());
  for (const auto& p : other.points)
    if (near.Near(p.xyz()) && AboveGround(p.xyz(), floor, cfg)) nearby.push_back(p.x, p.y, p.z);
  return nearby;
}

// Per change point of `idx`: `other` has a point above ground within `radius`.
std::vector<bool> NearMask(const PointCloud& changes, const std::vector<std::uint32_t>& idx, const PointCloud& other,
                           const Floor& floor, const MapConfig& cfg, double r) {
  std::vector<bool> out(changes.size(), false);
  const PointCloud nearby = NearbyAboveGround(changes, idx, other, floor, cfg, r);
  if (nearby.empty()) return out;
  const std::vector<bool> hit = geometry::WithinRadius(changes.select(idx), nearby, r);
  for (std::size_t j = 0; j < idx.size(); ++j) out[idx[j]] = hit[j];
  return out;
}

// `c` without the step's change points of the classes `of` picks (the same store grid points:
// within half a grid step). WithoutUnseen: `unchanged` without the step's weak ND points. The
// query did not observe those places, so they are no surface the step saw unchanged: beside them,
// a disappeared thing's strong part (the panels of a fence the query's beams passed through) is
// not a fragment of a surface that stayed, nor, in its box, what it left behind.
PointCloud WithoutChanges(const PointCloud& c, const PointCloud& changes, bool (*of)(PointClass), const MapConfig& cfg) {
  std::vector<bool> picked(changes.size());
  for (std::size_t i = 0; i < changes.size(); ++i) picked[i] = of(changes.cls[i]);
  std::vector<bool> keep = geometry::WithinRadius(c, changes.select(picked), 0.5 * cfg.resolution_m);
  keep.flip();
  return c.select(keep);
}
PointCloud WithoutUnseen(const PointCloud& unchanged, const PointCloud& changes, const MapConfig& cfg) {
  return WithoutChanges(unchanged, changes, Unseen, cfg);
}

// Whether a map point that existed before the step is a surface the step's reference holds too: a
// point a step after the reference added as a change (PD) is not. A hoarding that came at step 1
// is, at step 3 against the central session, the same appeared object again, not a surface its
// step-3 view is a fragment of (a stress row lost its step-3 hoarding that way and kept a side of
// it alone).
bool StayedSinceReference(std::uint16_t session, PointClass cls, const SessionRecord& step) {
  return int(session) < step.order && (int(session) <= step.reference || !IsPd(cls));
}

// Whether a map point after the step is the step's own surface that its reference never observed:
// its strong PD. Those of keyframes the step created (new territory) are no change of the step
// (Store::StepChanges takes their weak PD only); ReadStepMaps keeps the ones its changes do not
// hold, the surface an appeared cluster there continues into (Describe).
bool UnobservedByReference(std::uint16_t session, PointClass cls, const SessionRecord& step) {
  return int(session) == step.order && cls == PointClass::kPDStrong;
}

// What a step's objects read from the maps before and after it, gathered as the store streams
// them (memory: a batch of keyframes, the floor's cells and the surfaces near the changes, never
// a map):
//  - the local ground: lowest point per xy cell of both maps and of the changes. The cell must be
//    wider than the footprint an object hides from every view (a car's width), so that each cell
//    holds some ground;
//  - the surfaces the step left unchanged (points of the map after the step that existed before
//    it and are no change since its reference: StayedSinceReference, less its weak ND:
//    WithoutUnseen), only those in the xy cells (object_tolerance_m wide)
//    around a change point: the only ones NearbyAboveGround can return for any group of the changes;
//  - the same for the step's surfaces its reference never observed that its changes do not hold
//    (UnobservedByReference).
struct StepMaps {
  Floor floor;
  PointCloud unchanged_near;
  PointCloud unobserved_near;  // the step's own strong PD its changes do not hold (UnobservedByReference)
};
StepMaps ReadStepMaps(const Store& store, const SessionRecord& step, const PointCloud& changes, const MapConfig& cfg) {
  StepMaps m{Floor(cfg.object_ground_cell_m), {}, {}};
  m.floor.Add(changes);
  NearCells near(cfg.object_tolerance_m);
  if (cfg.object_tolerance_m > 0.0)
    for (std::size_t i = 0; i < changes.size(); ++i)
      if (Grouped(changes.cls[i])) near.Add(changes.points[i].xyz());
  // Parts are taken a batch at a time and read on every worker (each part's floor and surfaces),
  // then merged in part order.
  constexpr std::size_t kBatch = detail::kKeyframesPerBatch;
  std::vector<PointCloud> batch;
  auto read_batch = [&](bool after) {
    std::vector<Floor> floors(batch.size(), Floor(cfg.object_ground_cell_m));
    std::vector<PointCloud> kept(batch.size()), unobserved(batch.size());
    ParallelFor(batch.size(), store.threads(), [&](std::size_t k) {
      const PointCloud& part = batch[k];
      floors[k].Add(part);
      if (!after || near.empty()) return;
      const bool labelled = part.session.size() == part.size() && part.cls.size() == part.size();
      for (std::size_t i = 0; i < part.size(); ++i) {
        if (!near.Near(part.points[i].xyz())) continue;
        const auto& p = part.points[i];
        if (!labelled || StayedSinceReference(part.session[i], part.cls[i], step))
          kept[k].push_back(p.x, p.y, p.z);
        else if (UnobservedByReference(part.session[i], part.cls[i], step))
          unobserved[k].push_back(p.x, p.y, p.z);
      }
    });
    for (std::size_t k = 0; k < batch.size(); ++k) {
      m.floor.Add(floors[k]);
      m.unchanged_near.append(kept[k]);
      m.unobserved_near.append(unobserved[k]);
    }
    batch.clear();
  };
  for (const bool after : {false, true}) {
    store.StreamMapAt(after ? step.order : step.reference, {}, [&](PointCloud&& part) {
      batch.push_back(std::move(part));
      if (batch.size() == kBatch) read_batch(after);
    });
    read_batch(after);
  }
  m.unchanged_near = WithoutUnseen(m.unchanged_near, changes, cfg);
  m.unobserved_near = WithoutChanges(m.unobserved_near, changes, IsPd, cfg);
  return m;
}

// Sensor positions (ContextOf: where the sessions that scanned a change were): the nearest to a
// point (Covered's view of it), and its distance, a lower bound of the range the point was scanned
// from (the sampling of a cluster's surface: SampleGaps, MinWidth through MapObject::range_m).
class SensorRanges {
 public:
  SensorRanges() = default;
  explicit SensorRanges(std::vector<Eigen::Vector3d> sensors) : at_(std::move(sensors)) {
    if (at_.empty()) return;
    PointCloud at;
    for (const auto& s : at_) at.push_back(float(s.x()), float(s.y()), float(s.z()), 0.f);
    tree_ = std::make_shared<const geometry::KdTree>(at);
  }
  bool empty() const { return !tree_; }
  // The sensor nearest to p (null without keyframes).
  const Eigen::Vector3d* NearestTo(const Eigen::Vector3f& p) const {
    std::uint32_t j = 0;
    float d2 = 0.f;
    return tree_ && tree_->Nearest(p, &j, &d2) ? &at_[j] : nullptr;
  }
  double To(const Eigen::Vector3f& p) const {  // 0 without keyframes
    std::uint32_t j = 0;
    float d2 = 0.f;
    return tree_ && tree_->Nearest(p, &j, &d2) ? std::sqrt(double(d2)) : 0.0;
  }

 private:
  std::vector<Eigen::Vector3d> at_;
  std::shared_ptr<const geometry::KdTree> tree_;
};


// Per change point idx[k]: its clustering gaps {horizontal, vertical}, the cluster tolerance or,
// farther out, the sensor's sample gaps at its range from the nearest map keyframe (a lower bound
// of the range it was scanned from).
std::vector<Eigen::Vector2f> SampleGaps(const PointCloud& changes, const std::vector<std::uint32_t>& idx,
                                        const SensorRanges& ranges, const MapConfig& cfg) {
  const float tol = float(cfg.object_tolerance_m);
  std::vector<Eigen::Vector2f> gap(idx.size(), Eigen::Vector2f::Constant(tol));
  if (!ranges.empty())
    for (std::size_t k = 0; k < idx.size(); ++k)
      gap[k] = gap[k].cwiseMax(SensorGapsAt(ranges.To(changes.points[idx[k]].xyz()), cfg));
  return gap;
}

// The points idx of changes in clusters (points closer than object_tolerance_m joined,
// transitively; far out up to the sensor's sample gaps at their range, SampleGaps) of
// object_min_points .. object_max_points points; the largest cluster first (ties: the one with
// the lowest point first), each cluster's points in idx order.
std::vector<std::vector<std::uint32_t>> Cluster(const PointCloud& changes, const std::vector<std::uint32_t>& idx,
                                                const SensorRanges& ranges, const MapConfig& cfg, int threads) {
  std::vector<std::vector<std::uint32_t>> out;
  if (idx.size() < std::size_t(cfg.object_min_points)) return out;
  const PointCloud pts = changes.select(idx);
  for (auto& c : geometry::EuclideanClusterMembers(pts, SampleGaps(changes, idx, ranges, cfg), threads)) {
    if (c.size() < std::size_t(cfg.object_min_points) || c.size() > std::size_t(cfg.object_max_points)) continue;
    for (std::uint32_t& k : c) k = idx[k];
    out.push_back(std::move(c));
  }
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.size() > b.size(); });
  return out;
}

// Step context for the rules: sensor positions and the step's accepted disappeared objects.
struct StepContext {
  // Where a change's points were scanned from: appeared (PD) by the step's session, so every map
  // keyframe as of the step; disappeared (strong ND) by the sessions up to the reference, so their
  // keyframes only (a keyframe the step's route created beside a far object never scanned it).
  SensorRanges ranges, reference_ranges;
  const SensorRanges& RangesOf(bool appeared) const { return appeared ? ranges : reference_ranges; }
  std::vector<const MapObject*> disappeared;       // accepted strong-ND objects of the step
};


// How far short of an object's length and height a view's box may fall: its extremes are the
// samples nearest the object's ends, so each edge may miss up to one sample gap at either end: the
// sensor's clustering gap at the view's range (SensorGapsAt: its columns for the length, its rows
// for the height; a side seen obliquely is sampled sparser), at least the map's sample spacing
// (SampleSpacing). A view is never larger than the object.
Eigen::Vector2d ViewShortfall(const MapObject& o, const MapConfig& cfg) {
  constexpr double kEnds = 2.0;  // an edge's two ends
  return kEnds * SensorGapsAt(o.range_m, cfg).cast<double>().cwiseMax(SampleSpacing(cfg));
}



// How far below an object's top a view's highest sample may lie: one row of the sensor at the
// view's range (RowSpacing: the row above it passed over the object), plus the map's sample spacing
// (SampleSpacing: the voxel that kept the highest sample). Not SensorGapsAt's row gap: that is two
// rows, for a surface seen at up to 60 deg from below or above, while a view's top is the edge of an
// upright face whose rows land on it one RowSpacing apart.
double TopShortfall(const MapObject& o, const MapConfig& cfg) {
  return RowSpacing(o.range_m, cfg) + SampleSpacing(cfg);
}

// A view's top above its foot: the floor under it (Clearance's ground_z), or its lowest point where
// that lies lower (a far object's cell may hold no ground sample, its floor then one of its own).
double TopAboveFoot(const MapObject& o) { return o.hi.z() - std::min(o.lo.z(), o.ground_z); }

// How far short of an object's length a view's box may fall: its sampling at both ends
// (ViewShortfall), and what the sessions never sampled past its ends (MapObject::hidden_length_m).
double LengthShortfall(const MapObject& o, const MapConfig& cfg) { return ViewShortfall(o, cfg).x() + o.hidden_length_m; }

// Whether neither view's top above its foot exceeds the other's by more than the other's top may lie
// below the object's (TopShortfall).
bool TopsAgree(const MapObject& a, const MapObject& b, const MapConfig& cfg) {
  const double top = TopAboveFoot(a) - TopAboveFoot(b);
  return top <= TopShortfall(b, cfg) && -top <= TopShortfall(a, cfg);
}

// Whether views a and b can be of one object: neither box's length exceeds the other's by more than
// the other may have fallen short (LengthShortfall), nor its top above its foot the other's by more
// than the other's top may lie below the object's (TopShortfall: one row, not a row at either end,
// as both stand on the ground: a fence 2.1 m tall is no wall of 3.3 m, a structure 3 m tall no
// tree of 7 m); a far view may be much smaller than a near one, not larger. Their widths say
// nothing: a view sees an object's depth only as far as the object lets it (a container's side
// seen across the street is 0.2 m wide, at an angle 1.3 m of its 2.4 m), so both are lower bounds
// of the same width.
bool SizesAgree(const MapObject& a, const MapObject& b, const MapConfig& cfg) {
  const double length = a.size.x() - b.size.x();
  return length <= LengthShortfall(b, cfg) && -length <= LengthShortfall(a, cfg) && TopsAgree(a, b, cfg);
}

// Whether view o shows the shape of object d: it may fall short (ViewShortfall) by less than d's
// length and height. A view that may miss a whole edge of d agrees with d's size without showing it
// (seed 7's VLP-16 saw a patch 58 m out in rows 2 m apart: "the tree 5.6 m tall moved there").
bool ShowsTheShapeOf(const MapObject& o, const MapObject& d, const MapConfig& cfg) {
  return (ViewShortfall(o, cfg).array() < Eigen::Array2d(d.size.x(), d.size.z())).all();
}

// Coverage rule (step 3 above) for an appeared cluster: its space was observed free by the
// reference (majority of weak PD), or the reference's view of it was blocked by an object the
// step removed (the segment from the nearest reference sensor to the centroid crosses the box of
// a disappeared object, grown by the cluster tolerance) and it shows the shape of an object the
// step removed (CouldHaveMoved, ShowsTheShapeOf): that object moved there (LinkMoved pairs them).
// Anything else behind a blocked view the reference never observed: a facade or fence revealed
// behind a car that left is a coverage difference, not an object (it was a false object on
// HDL-64E, OS1-128, Pandar64 and VLP-32C).
bool Covered(const MapObject& o, const StepContext& ctx, const MapConfig& cfg) {
  if (o.change == "disappeared" || o.observed_fraction >= cfg.object_min_observed_fraction) return true;
  const Eigen::Vector3d* s = ctx.reference_ranges.NearestTo(o.centroid.cast<float>());
  if (!s) return false;
  const auto blocks = [&](const MapObject* d) { return SegmentHitsBox(*s, o.centroid, d->lo, d->hi, cfg.object_tolerance_m); };
  const auto moved_here = [&](const MapObject* d) { return CouldHaveMoved(*d, o, cfg) && ShowsTheShapeOf(o, *d, cfg); };
  return std::any_of(ctx.disappeared.begin(), ctx.disappeared.end(), blocks) &&
         std::any_of(ctx.disappeared.begin(), ctx.disappeared.end(), moved_here);
}

// Geometric rules (step 4 above); "" = an object. A ghost is the same surface in both sessions,
// displaced by the residual misalignment beyond LD's neighbour radius, so it is both an ND and a
// PD: most of the cluster has an above-ground change of the other side within
// object_twin_radius_m (a removed car leaves only ground there; a misaligned pole leaves its
// displaced copy a few decimetres away). A fragment is a piece of a surface the step left
// unchanged: most of its points lie within the cluster tolerance of unchanged above-ground map
// points that are not its own lower part (AttachedFraction), so clustered with them it would be
// one object that did not change (a strip of a pole or trunk seen through by grazing rays); a
// removed or new object is surrounded by free space and ground, and stands on its own remnants
// (its lower part, under the seen-through body). Nor is a thing that left or came still there:
// of what the other session observed in its oriented box above its own lower part, less than
// object_min_observed_fraction it saw changed (BoxSeenFraction), the rest it saw stay (rows of a
// far facade between the rows grazing rays passed, farther apart than the cluster tolerance, so
// no fragment), and the cluster "stayed". The sensor samples a surface at range r every
// r * object_sensor_step_deg (and the map every output_voxel_m); a sliver or rim (a coverage
// edge, one scan row wide) spans fewer than object_min_samples rows across its middle
// principal axis (Width, MinWidth) and lies along one surface: a thin face (ThinFace). A row
// whose box is wider than the cluster tolerance went around a body's corner (a container's side
// and end, seen in one row of a VLP-16 from 36 m and 88 m), which no edge of coverage draws; nor
// is a row whose top stands lower above the ground than the sensor's next row down lies below it
// (OneRowIsAll: a far fence's only row). A cluster whose top is
// below object_min_height_m above the local ground is a ground bump (curb, misregistered
// ground), and one flat to object_flat_sigma_m with a normal within object_flat_tilt_deg of
// vertical is a ground patch at any height. Objects that change (vehicles, containers, fences,
// kiosks, trees) stand on the ground: a cluster whose lowest point is more than
// object_max_clearance_m above the ground of its cell, and that no cluster of the same change
// holds up (HoldUp), floats, a piece of a permanent surface
// (canopy, facade above an occluder) whose lower part both sessions saw the same. Clusters whose
// longest horizontal edge is below object_min_length_m are smaller than the objects the map
// tracks: at a pedestrian's footprint they are most likely residues of moving actors that HD
// removal missed in one session (WalkerSized).
// The width (Width) below which a cluster at `range_m` spans fewer than object_min_samples rows of
// the sensor's samples (r * object_sensor_step_deg, at least the output voxel). n rows a sample s
// apart span (n - 1) s. The bound lies halfway between n - 1 and n rows, (n - 1.5) s, so noise does
// not decide an n-row cluster (a car seen in two rows of a VLP-16 is kept, a one-row rim is not).
double MinWidth(double range_m, const MapConfig& cfg) {
  return std::max(cfg.output_voxel_m, RowSpacing(range_m, cfg)) * std::max(0.0, cfg.object_min_samples - 1.5);
}

// A cluster too narrow for object_min_samples rows (MinWidth) is all a thing standing on the
// ground could show when its top is lower above the ground than one row of the sensor at its range
// (RowSpacing): the row below went under the ground's level before it reached the thing, and met
// the ground in front of it. A far fence seen in one row (seed 23's HDL-32E, 63 m out, rows 1.46 m
// apart, its row 1.1-1.3 m up) is that; a rim high on a facade, a pole, or a row of a thing near
// the sensor (rows closer than its height) is not. Nor is a row that touches a surface the step
// left unchanged (attached_fraction above 0): that surface's row drawn again where the poses
// drifted (the stress row vlp16_drift3x, pair 00_02: a band 0.25-0.67 m up, 7 % of it within the
// cluster tolerance of a surface that stayed).
bool OneRowIsAll(const MapObject& o, const MapConfig& cfg) {
  return o.attached_fraction <= 0.0 && o.height_above_ground < RowSpacing(o.range_m, cfg);
}


// A cluster a walker's residue could be: under object_min_length_m across (a pedestrian's, a
// cyclist's footprint), and no taller than that either unless it is a thin face (a pole, a facade's
// edge: no object the map tracks, but a surface two sessions sampled differently). A thing that fits
// a walker's footprint and stands higher than one is no walker: seed 3's and 7's HDL-64E saw a young
// tree that left in part (1.5 x 1.3 m and 1.5 x 0.6 m, 3.7 and 3.4 m high), rejected as small.
bool WalkerSized(const MapObject& o, const MapConfig& cfg) {
  const bool taller_than_a_walker = o.height_above_ground >= cfg.object_min_length_m;
  return o.size.x() < cfg.object_min_length_m && (!taller_than_a_walker || ThinFace(o, cfg));
}

std::string Reject(MapObject& o, const StepContext& ctx, const MapConfig& cfg, double width_m, const Spread3& sp) {
  if (!Covered(o, ctx, cfg)) return kCoverage;
  if (o.twin_fraction >= cfg.object_twin_max_fraction) return "ghost";
  if (o.attached_fraction >= cfg.object_max_attached_fraction) return "fragment";
  if (o.box_seen_fraction < cfg.object_min_observed_fraction) return "stayed";
  if (o.height_above_ground < cfg.object_min_height_m) return "low";
  if (Floats(o, cfg)) return "floating";
  if (width_m < MinWidth(o.range_m, cfg) && ThinFace(o, cfg) && !OneRowIsAll(o, cfg)) return "sliver";
  if (sp.sigma.x() < cfg.object_flat_sigma_m && std::abs(sp.normal.z()) > std::cos(cfg.object_flat_tilt_deg * kDegToRad))
    return "flat";
  if (WalkerSized(o, cfg)) return kSmall;
  if (cfg.object_max_extent_m > 0.0 && o.size.x() > cfg.object_max_extent_m) return "extent";
  return "";
}

// Confidence in [0, 1]: geometric mean of the see-through evidence (observed fraction; a revealed
// cluster counts half) and of how far width and height clear their minimum (1 at kFullMargin
// times it).
double Confidence(const MapObject& o, const MapConfig& cfg, double width_m, double min_width_m) {
  const double evidence = o.change == "appeared" && o.observed_fraction < cfg.object_min_observed_fraction
                              ? kRevealedEvidence : o.observed_fraction;
  auto margin = [](double v, double min) { return min > 0.0 ? std::clamp(v / (kFullMargin * min), 0.0, 1.0) : 1.0; };
  return std::cbrt(evidence * margin(width_m, min_width_m) * margin(o.height_above_ground, cfg.object_min_height_m));
}


double Share(const std::vector<bool>& mask, const std::vector<std::uint32_t>& sel) {
  const auto n = std::count_if(sel.begin(), sel.end(), [&](std::uint32_t i) { return bool(mask[i]); });
  return double(n) / double(std::max<std::size_t>(sel.size(), 1));
}

// What each cluster is judged against: per change point, whether it has a twin (other side within
// object_twin_radius_m); the unchanged surfaces above ground near the change points
// (NearbyAboveGround at the cluster tolerance), for each cluster's attached share and
// box share; the group's change points seen changed (SeenChanged), for the box share
// (BoxSeenFraction).

struct Masks {
  std::vector<bool> twin;
  PointCloud unchanged;
  PointCloud seen;
  UnobservedSurface unobserved;  // appeared: the step's surfaces its reference never observed near the group
};

// The group's change points (`idx`, above ground) the other session saw changed: strong ND for
// the disappeared group (all of it), weak PD for the appeared one.
PointCloud SeenChanged(const PointCloud& changes, const std::vector<std::uint32_t>& idx) {
  std::vector<std::uint32_t> seen;
  for (auto i : idx)
    if (SeenThrough(changes.cls[i])) seen.push_back(i);
  return changes.select(seen);
}

// The object's own lower part (AttachedFraction, BoxSeenFraction): points below the cluster's
// lowest point in their column (xy cells `r` wide, with their eight neighbours), or less than
// `margin` above it (Holds). A disappeared car's points within LD's neighbour radius of the new session's
// ground matched that ground and stayed in the map, under the body that was seen through.
class OwnLowerPart {
 public:
  OwnLowerPart(const MapObject& o, double r) : r_(r) {
    for (const auto& p : o.cloud.points) {
      auto [it, fresh] = bottom_.try_emplace(KeyOf(p.xyz(), r), p.z);
      if (!fresh) it->second = std::min(it->second, p.z);
    }
  }
  bool Holds(const Eigen::Vector3f& q, double margin) const {
    const CellKey k = KeyOf(q, r_);
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        const auto it = bottom_.find({k.x + dx, k.y + dy});
        if (it != bottom_.end() && q.z() < it->second + float(margin)) return true;
      }
    return false;
  }

 private:
  double r_;
  std::unordered_map<CellKey, float, CellKeyHash> bottom_;  // lowest cluster point per xy cell
};


// The points of `c` in o's axis-aligned box grown by r: what AttachedFraction (at the cluster
// tolerance) and BoxSeenFraction (inside the box) read of the unchanged map, gathered once per object.
PointCloud InGrownBox(const MapObject& o, const PointCloud& c, double r) {
  PointCloud out;
  for (const auto& p : c.points)
    if (InGrownBox(o, p.xyz(), r)) out.push_back(p.x, p.y, p.z);
  return out;
}

// Share of the cluster's points within the cluster tolerance r of an unchanged surface that is
// not the object's own lower part (`unchanged`: the unchanged points in its box grown by r).
// Unchanged points inside its oriented xy box (grown by `edge`, SampleSpacing) that are its lower
// part (OwnLowerPart, within r above its lowest point in their column) are not counted. A fragment's surface lies beside it (the rest of a pole
// or trunk a grazing ray cut a strip from), above it (a wall whose lower band was seen through) or
// between its points up the same columns (a wall whose rows were seen through and unchanged by
// turns): an object's lower part lies under it, not interleaved with it.
double AttachedFraction(const MapObject& o, const OwnLowerPart& lower, const PointCloud& unchanged, double r,
                        double edge) {
  const InOrientedBox in_box(o, edge, r);
  PointCloud other;
  for (const auto& p : unchanged.points)
    if (!in_box(p.xyz().cast<double>()) || !lower.Holds(p.xyz(), r)) other.push_back(p.x, p.y, p.z);
  if (other.empty()) return 0.0;
  const std::vector<bool> hit = geometry::WithinRadius(o.cloud, other, r);
  return double(std::count(hit.begin(), hit.end(), true)) / double(std::max<std::size_t>(o.points, 1));
}

// Of what the other session observed inside the object's oriented box above its own lower part
// (OwnLowerPart: below its lowest point in their column), the share it saw changed (`seen`: strong
// ND for a disappeared object, weak PD for an appeared one) against the unchanged map points
// (`unchanged`, at least those in its box: it saw them stay); 1 when it observed
// nothing there. A thing that left or came is gone (new) wherever its box was observed; a strip of
// a facade or crown that a few grazing rays passed lies among rows of that surface the other
// session saw stay, above and between its points (a wall's lower band is its own lower part).
double BoxSeenFraction(const MapObject& o, const OwnLowerPart& lower, const PointCloud& seen,
                       const PointCloud& unchanged) {
  const InOrientedBox in_box(o, 0.0, 0.0);
  const auto count = [&](const PointCloud& c) {
    std::size_t n = 0;
    for (const auto& p : c.points)
      if (InGrownBox(o, p.xyz(), 0.0) && in_box(p.xyz().cast<double>()) && !lower.Holds(p.xyz(), 0.0)) ++n;
    return n;
  };
  const std::size_t n_seen = count(seen), total = n_seen + count(unchanged);
  return total == 0 ? 1.0 : double(n_seen) / double(total);
}


// An appeared thin face (a fence, a hoarding, a wall: its oriented box no wider than the cluster
// tolerance) is followed beyond its ends into the step's surface its reference never observed, as
// far as its own length on either side (InFaceCorridor): a face that goes on unobserved that far was
// mostly never observed, and the cells around the step's changes (ReadStepMaps) end a tolerance
// from them. The reference saw free 72 points of a hoarding that goes on for 18 m in territory it
// never observed (vlp16_drift3x): those cells gave it a see-through share of 0.60, an object with
// IoU 0.03; followed along its face, 0.33 (its 70 points seen, before its foot and unseen rows
// joined): coverage. No other row's objects changed (docs/RESULTS.md). How far a thin face's
// corridor reaches: FaceReach (object_shape.hpp).

// The step's own surface its reference never observed (UnobservedByReference, less its changes,
// above ground) in the corridors of the group's thin appeared faces, streamed from the map after
// the step (one pass, the corridors' bounding box).
PointCloud AlongFaces(const std::vector<MapObject>& group, const Store& store, const SessionRecord& step,
                      const PointCloud& changes, const Floor& floor, const MapConfig& cfg) {
  const double tol = cfg.object_tolerance_m;
  std::vector<const MapObject*> faces;
  std::vector<BoxFrame> frames;  // each face's, its yaw's sine and cosine taken once
  Region box;
  box.use_box = true;
  box.lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), box.hi = -box.lo;
  for (const MapObject& o : group) {
    if (o.change != "appeared" || !ThinFace(o, cfg)) continue;
    faces.push_back(&o);
    frames.emplace_back(o);
    const Eigen::Vector3d reach(FaceReach(o) + tol, FaceReach(o) + tol, tol);
    box.lo = box.lo.cwiseMin(Eigen::Vector3d(o.box_center.x(), o.box_center.y(), o.lo.z()) - reach);
    box.hi = box.hi.cwiseMax(Eigen::Vector3d(o.box_center.x(), o.box_center.y(), o.hi.z()) + reach);
  }
  PointCloud along;
  if (faces.empty()) return along;
  store.StreamMapAt(step.order, box, [&](PointCloud&& part) {
    if (part.session.size() != part.size() || part.cls.size() != part.size()) return;
    for (std::size_t i = 0; i < part.size(); ++i) {
      const auto& p = part.points[i];
      if (!UnobservedByReference(part.session[i], part.cls[i], step) || !AboveGround(p.xyz(), floor, cfg)) continue;
      const Eigen::Vector3d q = p.xyz().cast<double>();
      for (std::size_t f = 0; f < faces.size(); ++f)
        if (InFaceCorridor(*faces[f], frames[f], q, tol)) {
          along.push_back(p.x, p.y, p.z);
          break;
        }
    }
  });
  return WithoutChanges(along, changes, IsPd, cfg);
}

// `near` with the points of `along` it does not hold: the same store grid points are within half a
// grid step (as WithoutChanges tells them).
PointCloud Joined(const PointCloud& near, const PointCloud& along, const MapConfig& cfg) {
  std::vector<bool> fresh = geometry::WithinRadius(along, near, 0.5 * cfg.resolution_m);
  fresh.flip();
  PointCloud out = near;
  out.append(along.select(fresh));
  return out;
}

MapObject BuildObject(const PointCloud& changes, const std::vector<std::uint32_t>& sel, bool appeared,
                      const SessionRecord& step, const Floor& floor, const Masks& masks,
                      const StepContext& ctx, const MapConfig& cfg) {
  MapObject o;
  o.twin_fraction = Share(masks.twin, sel);
  o.session = step.order;
  o.reference = step.reference;
  o.change = appeared ? "appeared" : "disappeared";
  o.exists_in = appeared ? step.order : step.reference;
  o.cloud = changes.select(sel);
  o.unobserved_beside = UnobservedBeside(o.cloud, masks.unobserved, cfg.object_tolerance_m);
  Describe(o);
  OrientedBox(o);
  const OwnLowerPart lower(o, cfg.object_tolerance_m);
  const PointCloud unchanged = InGrownBox(o, masks.unchanged, cfg.object_tolerance_m);
  o.attached_fraction =
      AttachedFraction(o, lower, unchanged, cfg.object_tolerance_m, SampleSpacing(cfg));
  o.box_seen_fraction = BoxSeenFraction(o, lower, masks.seen, unchanged);
  o.ground_z = o.lo.z();
  o.clearance_m = floor.empty() ? 0.0 : Clearance(o, floor);
  o.height_above_ground = o.hi.z() - o.ground_z;
  o.range_m = ctx.RangesOf(appeared).To(o.centroid.cast<float>());
  return o;
}

// The group's unobserved surface with its thin faces' continuations (AlongFaces); when they add to
// it, each cluster's surface beside it is counted again over the whole.
UnobservedSurface FollowFaces(std::vector<MapObject>& group, const Store& store, const SessionRecord& step,
                              const PointCloud& changes, const Floor& floor, const UnobservedSurface& near,
                              const MapConfig& cfg) {
  const PointCloud along = AlongFaces(group, store, step, changes, floor, cfg);
  PointCloud joined = along.empty() ? PointCloud() : Joined(near.cloud, along, cfg);
  if (joined.size() <= near.cloud.size()) return near;
  UnobservedSurface all(std::move(joined));
  for (MapObject& o : group) {
    o.unobserved_beside = UnobservedBeside(o.cloud, all, cfg.object_tolerance_m);
    Describe(o);
  }
  return all;
}

// Objects of one shape standing together (a row of parked cars, a container yard): that one of them
// left and one of that shape came elsewhere tells nothing of which went where, nor that one moved
// at all (a car that left and another that parked are two changes, not one move). Of what the
// step's map holds around object o, the things of its shape: clusters at the cluster tolerance of
// the surfaces the step left unchanged (StayedSinceReference) above the ground (`near`: read by
// CountAlikeBeside far enough to hold whole any thing of o's size beside it), that come within o's
// own length of its box, stand on the ground (Floats), do not touch o's box (o itself, its
// remnants) and whose sizes agree with o's (SizesAgree, each view at its range).
std::size_t AlikeIn(const MapObject& o, const PointCloud& near, const Floor& floor, const StepContext& ctx,
                    const MapConfig& cfg) {
  std::size_t alike = 0;
  for (const auto& members : geometry::EuclideanClusterMembers(near, cfg.object_tolerance_m)) {
    if (members.size() < std::size_t(cfg.object_min_points)) continue;
    MapObject like;
    like.cloud = near.select(members);
    like.cloud.cls.assign(like.cloud.size(), PointClass::kUnknown);  // Describe's votes: unchanged
    const auto& pts = like.cloud.points;
    const auto beside = [&](const auto& p) { return InGrownBox(o, p.xyz(), o.size.x()); };
    if (std::none_of(pts.begin(), pts.end(), beside) ||
        std::any_of(pts.begin(), pts.end(), [&](const auto& p) { return InGrownBox(o, p.xyz(), cfg.object_tolerance_m); }))
      continue;
    Describe(like);
    OrientedBox(like);
    like.range_m = ctx.ranges.To(like.centroid.cast<float>());
    like.clearance_m = Clearance(like, floor);
    if (!Floats(like, cfg) && SizesAgree(o, like, cfg)) ++alike;
  }
  return alike;
}

// The step's objects that could be a move's end: some object of the other side of the change
// could be the same thing (CouldHaveMoved), as LinkMoved will ask.
std::vector<std::size_t> MoveEnds(const std::deque<MapObject>& objects, const MapConfig& cfg) {
  std::vector<bool> end(objects.size(), false);
  for (std::size_t d = 0; d < objects.size(); ++d)
    for (std::size_t a = 0; a < objects.size(); ++a)
      if (objects[d].change == "disappeared" && objects[a].change == "appeared" &&
          CouldHaveMoved(objects[d], objects[a], cfg))
        end[d] = end[a] = true;
  std::vector<std::size_t> ends;
  for (std::size_t k = 0; k < objects.size(); ++k)
    if (end[k]) ends.push_back(k);
  return ends;
}

// Measures how far past its ends each of the step's objects may run unseen (MeasureHiddenEnds), up
// to what a move's other end would need: the longest object of the other side of the change, far
// enough away and of a top that agrees (TopsAgree), less its own length and sampling shortfall.
void MeasureHiddenEndsForMoves(std::deque<MapObject>& objects, const PointCloud& changes, const Store& store,
                               const SessionRecord& step, const Floor& floor, const MapConfig& cfg) {
  std::vector<double> upto(objects.size(), 0.0);
  for (std::size_t d = 0; d < objects.size(); ++d)
    for (std::size_t a = 0; a < objects.size(); ++a) {
      const MapObject &gone = objects[d], &came = objects[a];
      if (gone.change != "disappeared" || came.change != "appeared" || !TopsAgree(gone, came, cfg) ||
          (gone.centroid - came.centroid).norm() < cfg.object_moved_min_dist_m)
        continue;
      upto[a] = std::max(upto[a], gone.size.x() - came.size.x() - ViewShortfall(came, cfg).x());
      upto[d] = std::max(upto[d], came.size.x() - gone.size.x() - ViewShortfall(gone, cfg).x());
    }
  detail::MeasureHiddenEnds(objects, upto, changes, store, step, floor, cfg);
}

// Sets alike_beside (AlikeIn) of each of the step's objects that could be a move's end (MoveEnds),
// reading the step's map once (the bounding box of their reaches) when there is one.
void CountAlikeBeside(std::deque<MapObject>& objects, const Store& store, const SessionRecord& step, const Floor& floor,
                      const StepContext& ctx, const MapConfig& cfg) {
  const std::vector<std::size_t> ends = MoveEnds(objects, cfg);
  if (ends.empty()) return;
  const double tol = cfg.object_tolerance_m;
  std::vector<Eigen::AlignedBox3d> reach;
  Region box;
  box.use_box = true;
  box.lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), box.hi = -box.lo;
  for (const std::size_t k : ends) {
    // A thing within o's length of its box, up to o's length and twice its height, lies inside.
    const MapObject& o = objects[k];
    const Eigen::Vector3d grow(2.0 * o.size.x() + tol, 2.0 * o.size.x() + tol, tol);
    reach.emplace_back(o.lo - grow, o.hi + grow + Eigen::Vector3d(0.0, 0.0, o.hi.z() - o.lo.z()));
    box.lo = box.lo.cwiseMin(reach.back().min()), box.hi = box.hi.cwiseMax(reach.back().max());
  }
  std::vector<PointCloud> near(ends.size());
  store.StreamMapAt(step.order, box, [&](PointCloud&& part) {
    if (part.session.size() != part.size() || part.cls.size() != part.size()) return;
    for (std::size_t i = 0; i < part.size(); ++i) {
      const auto& p = part.points[i];
      const Eigen::Vector3d q = p.xyz().cast<double>();
      const auto in = [&](const Eigen::AlignedBox3d& r) { return r.contains(q); };
      if (std::none_of(reach.begin(), reach.end(), in) || !StayedSinceReference(part.session[i], part.cls[i], step) ||
          !AboveGround(p.xyz(), floor, cfg))
        continue;  // the box tests first: the map's labels and floor only for points some end reaches
      for (std::size_t e = 0; e < ends.size(); ++e)
        if (in(reach[e])) near[e].push_back(p.x, p.y, p.z);
    }
  });
  ParallelFor(ends.size(), store.threads(), [&](std::size_t e) {
    objects[ends[e]].alike_beside = AlikeIn(objects[ends[e]], near[e], floor, ctx, cfg);
  });
}


// The rules (Reject) of a built cluster, on what was seen of it (its confidence is Rate's).
void Judge(MapObject& o, const StepContext& ctx, const MapConfig& cfg) {
  const Spread3 sp = Spread(o);
  o.rejected = Reject(o, ctx, cfg, Width(o, sp.middle), sp);
}

// A cluster's confidence over its final cloud: the parts an object took after the rules judged
// what was seen (the unseen parts of a disappeared one, parts joined, its feet) count in its
// see-through evidence. A disappeared object the query saw through over a few rows at a facade's
// foot, and that took the rows of the facade above it that the query never saw, is 2 % evidence.
void Rate(MapObject& o, const MapConfig& cfg) {
  o.confidence = Confidence(o, cfg, Width(o, Spread(o).middle), MinWidth(o.range_m, cfg));
}


// One step's objects (disappeared first: they can reveal appeared ones) and rejected clusters.
void StepObjects(const Store& store, const SessionRecord& step, StepContext ctx, std::vector<MapObject>& kept,
                 std::vector<MapObject>& rejected) {
  const MapConfig& cfg = store.config();
  const PointCloud changes = store.StepChanges(step.order);
  const StepMaps maps = ReadStepMaps(store, step, changes, cfg);
  const Floor& floor = maps.floor;
  const PointCloud& unchanged = maps.unchanged_near;
  std::deque<MapObject> step_kept;  // pointers in ctx.disappeared stay valid
  std::vector<MapObject> step_rejected;
  for (const bool appeared : {false, true}) {
    const std::vector<std::uint32_t> idx = GroupPoints(changes, appeared, floor, cfg);
    const Masks masks{NearMask(changes, idx, OtherSide(changes, appeared), floor, cfg, cfg.object_twin_radius_m),
                      NearbyAboveGround(changes, idx, unchanged, floor, cfg, cfg.object_tolerance_m),
                      SeenChanged(changes, idx),
                      UnobservedSurface(appeared ? NearbyAboveGround(changes, idx, maps.unobserved_near, floor, cfg,
                                                                     cfg.object_tolerance_m)
                                                 : PointCloud())};
    std::vector<MapObject> group;
    for (const auto& piece : SplitFaces(changes, Cluster(changes, idx, ctx.RangesOf(appeared), cfg, store.threads()), cfg)) {
      group.push_back(BuildObject(changes, piece.sel, appeared, step, floor, masks, ctx, cfg));
      group.back().cut_from = piece.cut_from;
    }
    const UnobservedSurface unobserved = FollowFaces(group, store, step, changes, floor, masks.unobserved, cfg);
    const std::vector<int> holder = HoldUp(group, cfg);
    const PointCloud pool = UnseenPool(changes, appeared, unobserved.cloud, step);
    const auto unseen = UnseenParts(group, pool, floor, cfg);
    StandOnChangesBelow(group, changes, idx, floor, cfg);
    for (MapObject& o : group) Judge(o, ctx, cfg);
    for (std::size_t k = 0; k < group.size(); ++k)
      if (group[k].rejected.empty() && !unseen[k].empty())
        KeepUnseenParts(group[k], pool.select(unseen[k]), unobserved, cfg);
    const std::vector<bool> keep = JoinHeldParts(group, holder);
    for (std::size_t k = 0; k < group.size(); ++k) {
      MapObject& o = group[k];
      if (!keep[k]) continue;
      if (!o.rejected.empty()) {
        step_rejected.push_back(std::move(o));
        continue;
      }
      step_kept.push_back(std::move(o));
      if (!appeared) ctx.disappeared.push_back(&step_kept.back());
    }
  }
  MergeParts(step_kept, step_rejected, cfg);
  JoinHiddenGaps(step_kept, changes, store, step, floor, cfg);
  KeepFeet(step_kept, changes, floor, cfg);
  MeasureHiddenEndsForMoves(step_kept, changes, store, step, floor, cfg);
  CountAlikeBeside(step_kept, store, step, floor, ctx, cfg);
  for (auto& o : step_kept) {
    Rate(o, cfg);
    kept.push_back(std::move(o));
  }
  for (auto& o : step_rejected) {
    Rate(o, cfg);
    rejected.push_back(std::move(o));
  }
}

}  // namespace

namespace detail {
// Disappeared object d and appeared object a could be one object that moved: their sizes agree
// (SizesAgree) and their centroids are at least object_moved_min_dist_m apart.
bool CouldHaveMoved(const MapObject& d, const MapObject& a, const MapConfig& cfg) {
  return SizesAgree(d, a, cfg) && (d.centroid - a.centroid).norm() >= cfg.object_moved_min_dist_m;
}
}  // namespace detail

MapConfig WithSensorStep(MapConfig cfg, const geometry::SensorModel& sensor) {
  if (cfg.object_sensor_step_deg <= 0.0)
    cfg.object_sensor_step_deg = sensor.CoarserStepDeg();
  if (cfg.object_sensor_azimuth_step_deg <= 0.0) cfg.object_sensor_azimuth_step_deg = sensor.azimuth_step_deg;
  if (cfg.object_sensor_azimuth_half_fov_deg <= 0.0) {
    cfg.object_sensor_azimuth_center_deg = sensor.azimuth_center_deg;
    cfg.object_sensor_azimuth_half_fov_deg = sensor.azimuth_half_fov_deg;
  }
  return cfg;
}

namespace {
// What a step's stored objects were made with: the code (its id: any change to the rules makes a
// store's earlier objects be computed again instead of read) and every map config value.
std::string ObjectsKey(const MapConfig& cfg) {
  MapConfig c = cfg;
  return std::string("objects of code ") + CodeId() + "\n" + FieldsToString(FieldsOf(c));
}

void RequireSensorStep(const MapConfig& cfg) {
  if (!(cfg.object_sensor_step_deg > 0.0))
    throw Error("map config: object_sensor_step_deg is 0 (take it from the sensor): `ltmapper run` and `ltmapper map "
                "objects --session DIR` derive it from the scans; elsewhere set it (the sensor's coarser angular step)");
}

// Where the sessions `from` .. `to` scanned from: each one's trajectory (Store::Trajectory), or,
// for one the store has none of, the map keyframes it created.
std::vector<Eigen::Vector3d> ScannedFrom(const Store& store, const std::vector<KeyframeRecord>& keyframes, int from,
                                         int to) {
  std::vector<Eigen::Vector3d> at;
  for (int s = from; s <= to; ++s) {
    const std::vector<Pose> trajectory = store.Trajectory(s);
    for (const Pose& T : trajectory) at.push_back(T.translation());
    if (trajectory.empty())
      for (const auto& k : keyframes)
        if (k.session == s) at.push_back(k.T_world_sensor.translation());
  }
  return at;
}

// Where the step's changes were scanned from (a later step's keyframes were not there yet: a
// step's objects depend on the store up to that step only, so they can be kept). Appeared (PD):
// by the step's session, along its trajectory (a car it saw 70 m out lies 20 m from a keyframe
// its route created farther on: seed 7's car 4 fell into two "small" pieces); without one (a store
// written before schema 4), wherever the sessions up to the step scanned from (ScannedFrom: their
// map keyframes). Disappeared (strong ND): by the sessions up to the reference.
StepContext ContextOf(const Store& store, const SessionRecord& step, const std::vector<KeyframeRecord>& keyframes) {
  StepContext ctx;
  std::vector<Eigen::Vector3d> appeared;
  for (const Pose& T : store.Trajectory(step.order)) appeared.push_back(T.translation());
  if (appeared.empty()) appeared = ScannedFrom(store, keyframes, 0, step.order);
  ctx.ranges = SensorRanges(std::move(appeared));
  ctx.reference_ranges = SensorRanges(ScannedFrom(store, keyframes, 0, step.reference));
  return ctx;
}

struct StepResult {
  std::vector<MapObject> kept, rejected;
};
StepResult ComputeStep(const Store& store, const SessionRecord& step, const std::vector<KeyframeRecord>& keyframes) {
  StepResult r;
  StepObjects(store, step, ContextOf(store, step, keyframes), r.kept, r.rejected);
  for (auto& o : r.rejected) o.cloud.clear();  // rows only (rejected.csv)
  return r;
}
}  // namespace

std::vector<MapObject> Store::Objects(std::vector<MapObject>* rejected) const {
  RequireSensorStep(config());
  const std::string key = ObjectsKey(config());
  const auto keyframes = Keyframes();
  std::vector<MapObject> out, dropped;
  for (const auto& step : Sessions()) {
    if (step.order == 0) continue;  // the central session changes nothing
    const std::string record = StepRecord(step.order, key);
    StepResult r;
    if (record.empty())
      r = ComputeStep(*this, step, keyframes);
    else
      detail::DecodeObjects(record, path() + ": objects of step " + std::to_string(step.order), &r.kept, &r.rejected);
    std::move(r.kept.begin(), r.kept.end(), std::back_inserter(out));
    std::move(r.rejected.begin(), r.rejected.end(), std::back_inserter(dropped));
  }
  detail::IdentifyAcrossSteps(out, dropped, config());
  if (rejected) {
    for (std::size_t k = 0; k < dropped.size(); ++k) dropped[k].id = int(k);
    *rejected = std::move(dropped);
  }
  return out;
}

std::size_t Store::CacheObjects() {
  RequireSensorStep(config());
  const std::string key = ObjectsKey(config());
  const auto keyframes = Keyframes();
  std::size_t computed = 0;
  for (const auto& step : Sessions()) {
    if (step.order == 0 || HasStepRecord(step.order, key)) continue;
    const StepResult r = ComputeStep(*this, step, keyframes);
    PutStepRecord(step.order, key, detail::EncodeObjects(r.kept, r.rejected));
    ++computed;
  }
  return computed;
}

}  // namespace ltm::map
