// Private to src/ltmapper/map: what an object's cloud says of its shape (object_shape.cpp), as the
// object rules (objects.cpp) read it: centroid and boxes, the oriented box's frame, principal
// spreads, width across the sensor's rows, clearance above the ground, and a segment against a box.
#pragma once

#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/map.hpp"

#include <cmath>

namespace ltm::map::detail {

// Centroid, axis-aligned box, class votes and see-through share (MapObject::observed_fraction).
void Describe(MapObject& o);
// Oriented box: yaw of the longer side of the xy rectangle the points lie closest to, size, centre.
void OrientedBox(MapObject& o);

// An object's oriented box frame: a point's (along, across) offsets from the box centre, along its
// length and width (and back: World), the yaw's sine and cosine taken once for every point asked.
class BoxFrame {
 public:
  explicit BoxFrame(const MapObject& o) : o_(o), c_(std::cos(o.yaw_rad)), s_(std::sin(o.yaw_rad)) {}
  Eigen::Vector2d Local(const Eigen::Vector3d& q) const {
    const double dx = q.x() - o_.box_center.x(), dy = q.y() - o_.box_center.y();
    return {c_ * dx + s_ * dy, -s_ * dx + c_ * dy};
  }
  // The world xy of the offsets (along, across) from the box centre (Local's inverse).
  Eigen::Vector2d World(double along, double across) const {
    return {o_.box_center.x() + c_ * along - s_ * across, o_.box_center.y() + s_ * along + c_ * across};
  }

 private:
  const MapObject& o_;
  double c_, s_;
};

// How far a thin face's corridor reaches along its axis from its centre: its half length and its
// length beyond that (an appeared face's unobserved continuation, FollowFaces; a disappeared one's
// unseen rest, UnseenParts).
inline double FaceReach(const MapObject& o) { return 1.5 * o.size.x(); }

// Is q within a thin face's corridor (`frame`: the face's box frame): along its axis no farther than
// its length beyond either end, across it and in height within the cluster tolerance?
inline bool InFaceCorridor(const MapObject& o, const BoxFrame& frame, const Eigen::Vector3d& q, double tol) {
  if (q.z() < o.lo.z() - tol || q.z() > o.hi.z() + tol) return false;
  const Eigen::Vector2d l = frame.Local(q);
  return std::abs(l.x()) <= FaceReach(o) && std::abs(l.y()) <= tol;
}

// An object's oriented box grown by `margin` across (xy) and `margin_z` in z.
class InOrientedBox {
 public:
  InOrientedBox(const MapObject& o, double margin, double margin_z) : o_(o), frame_(o), margin_(margin), margin_z_(margin_z) {}
  bool operator()(const Eigen::Vector3d& q) const {
    if (q.z() < o_.lo.z() - margin_z_ || q.z() > o_.hi.z() + margin_z_) return false;
    const Eigen::Vector2d l = frame_.Local(q);
    return std::abs(l.x()) <= 0.5 * o_.size.x() + margin_ && std::abs(l.y()) <= 0.5 * o_.size.y() + margin_;
  }

 private:
  const MapObject& o_;
  BoxFrame frame_;
  double margin_, margin_z_;
};

// Principal spreads (std along the 3D principal axes, ascending), the smallest axis and the middle one.
struct Spread3 {
  Eigen::Vector3d sigma, normal, middle;
};
Spread3 Spread(const MapObject& o);
// The extent of the points along `middle` between trimmed quantiles (kWidthTrimShare).
double Width(const MapObject& o, const Eigen::Vector3d& middle);
// The smallest height of a point above the floor of its own cell; sets o.ground_z.
double Clearance(MapObject& o, const geometry::LowestGrid& floor);
// Segment p-q against an axis-aligned box grown by `margin`.
bool SegmentHitsBox(const Eigen::Vector3d& p, const Eigen::Vector3d& q, Eigen::Vector3d lo, Eigen::Vector3d hi,
                    double margin);

}  // namespace ltm::map::detail
