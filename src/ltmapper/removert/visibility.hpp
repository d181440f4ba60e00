// ltmapper removert: visibility votes (see through / hit per point and resolution), the
// building block of HD removal and of the weak / strong decisions.
#pragma once

#include "ltmapper/removert/keyframes.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace ltm::removert {

namespace detail {
class HitSurfaces;  // images.hpp
}

// For each point (world frame) and each resolution, how many keyframes see through it (scan
// range > point range + tolerance) and how many hit it (|scan range - point range| <=
// tolerance), counting keyframes within submap_radius_m of the point. The building block of HD
// removal and of the weak/strong decisions; exposed for tests and ablations.
struct VisibilityVotes {
  std::size_t points = 0;
  int levels = 0;
  std::vector<std::uint16_t> see;  // [level * points + i]
  std::vector<std::uint16_t> hit;
  std::vector<std::uint16_t> occ;  // occluded (nearer return); only when count_occluded
  std::vector<std::uint16_t> see_own;  // the own pixel's return beyond the point; only when count_own_see
  std::vector<std::uint16_t> beam_hits;  // [i] keyframes that observed the point's surface by the BeamTest
  std::vector<std::uint16_t> beam_around;  // [i] keyframes whose beams around it met its surface farther away;
                                           // only with the beam test and count_own_see (its one reader)
  std::vector<std::uint16_t> beam_passed;  // [i] keyframes a beam of which passed it without a return
                                           // (ColumnImage::PassedWithoutReturn); as beam_around
  std::vector<std::uint16_t> beam_through;  // [i] keyframes a beam of which went through its place (or, with
                                            // VisibilityOptions::passed_at, passed it without a return)
                                            // and none ended near it; with through_at or passed_at
  std::uint16_t See(int level, std::size_t i) const { return see[std::size_t(level) * points + i]; }
  std::uint16_t Hit(int level, std::size_t i) const { return hit[std::size_t(level) * points + i]; }
  std::uint16_t Occ(int level, std::size_t i) const { return occ[std::size_t(level) * points + i]; }
  std::uint16_t SeeOwn(int level, std::size_t i) const { return see_own[std::size_t(level) * points + i]; }
};

// How far a point's upright surface goes on from it in its plane [m]: up, down (along `up`, the
// plane's steepest direction) and to either side (along up x normal). `up` is in the points' frame
// (world); ColumnImage::PassedInside reads it rotated into the sensor's.
struct SurfaceExtent {
  Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  float above = 0.f, below = 0.f, left = 0.f, right = 0.f;
};

// Optional per-point unit normals (world frame) enable surface hits: a point also counts as hit
// when the nearest return of its own pixel lies on the point's surface plane (distance to the
// plane within the tolerance) and at most surface_max_m from it in range: a surface seen at a
// grazing angle (far ground) is sampled metres apart in range, so the plain range test misses
// it, while an occluder in front of the point is off its plane (LD "same surface" test, revert).
struct VisibilityOptions {
  bool count_occluded = false;
  // Also count, per level, the keyframes whose own pixel of the point has a return beyond it
  // (VisibilityVotes::see_own), whatever the beams above and below met: the beam that passed the
  // point went on (LD's strength of PD).
  bool count_own_see = false;
  // Judge a point only within the beams' span (the outermost beams widened by their scatter):
  // beyond it only one beam passes near the point and that is no evidence (HD removal, revert).
  // LD's occlusion test judges anywhere in the images' FOV (a change above the top beam).
  bool within_beams = true;
  const std::vector<Eigen::Vector3f>* normals = nullptr;
  double surface_max_m = 0.0;  // [m]
  // With normals: per point, whether its plane is used (surface hits, the beam test); a point
  // without one is judged by its returns alone (null: every point's plane is used).
  const std::vector<bool>* surface_at = nullptr;
  // With normals: the beam test per keyframe (BeamTest; VisibilityVotes::beam_hits).
  const BeamTest* beams = nullptr;
  // With the beam test, without count_own_see: per point, whether a beam may have gone through its
  // place (a point inside a plane of its map); only those are asked (VisibilityVotes::beam_through).
  const std::vector<bool>* through_at = nullptr;
  // Likewise: per point, how far its upright surface goes on around it (world frame; all extents 0 =
  // not asked): a beam that passed it without a return (it went on to the sky or beyond the
  // sensor's range) and crossed its plane within that extent went through its place
  // (ColumnImage::PassedInside; a level surface is passed at a grazing angle). Counts in beam_through.
  const std::vector<SurfaceExtent>* passed_at = nullptr;
  // Likewise: per point, whether it lies on a scan line of its map (no plane) over its map's surface:
  // a beam that passed it without a return, where the scan met nothing near it nor at its distance
  // above or below it (ColumnImage::Observed's line_up), went through its place. Counts in beam_through.
  const std::vector<bool>* line_at = nullptr;
  // With the beam test: the keyframes' own surfaces (their session's map) where their beams ended,
  // whose incidence also bounds how far along its ray a return may lie from the point
  // (HitSurfaces; null: the point's plane alone).
  const detail::HitSurfaces* hit_surfaces = nullptr;
  bool AsksThrough() const { return through_at != nullptr || passed_at != nullptr || line_at != nullptr; }
};
VisibilityVotes CountVisibility(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                                const std::vector<double>& resolutions_deg,
                                const RemovertConfig& cfg, int threads = 0,
                                const VisibilityOptions& options = {});

}  // namespace ltm::removert
