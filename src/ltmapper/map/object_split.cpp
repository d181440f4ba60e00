// Two things of one change that touch, told apart before the rules judge them (step 2 of
// objects.cpp's list): a thin upright face (a fence, a hoarding) that runs on past the rest of its
// cluster (a tree that left with the fence it stood by) is one thing and the rest another.
#include "ltmapper/map/object_rules.hpp"
#include "ltmapper/map/object_shape.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ltm::map::detail {
namespace {

constexpr int kDirections = 360;             // line directions tried, every 0.5 deg over 180 deg: a
                                             // 14 m fence's ends within 0.06 m of the best one's
constexpr std::size_t kSearchPoints = 1000;  // at most this many points (evenly taken) find the line
                                             // (4000 found the same splits on 12 kept rows at 3x the cost)

// A line in xy: its direction u, its normal n and offset (n . p of its points).
struct Line {
  Eigen::Vector2d u, n;
  double offset = 0.0;
  std::size_t support = 0;
};

// The xy line that most points lie within half of `width` of: every direction, the densest window
// of the points' offsets along its normal, centred on the window's median (the face's own points,
// not a thing beside it that the window's edge took in).
Line DensestLine(const std::vector<Eigen::Vector2d>& xy, double width) {
  const std::size_t step = std::max<std::size_t>(1, xy.size() / kSearchPoints);
  Line best;
  std::vector<double> d;
  for (int k = 0; k < kDirections; ++k) {
    const double a = M_PI * k / kDirections;
    const Eigen::Vector2d u(std::cos(a), std::sin(a)), n(-u.y(), u.x());
    d.clear();
    for (std::size_t i = 0; i < xy.size(); i += step) d.push_back(n.dot(xy[i]));
    std::sort(d.begin(), d.end());
    for (std::size_t lo = 0, hi = 0; hi < d.size(); ++hi) {
      while (d[hi] - d[lo] > width) ++lo;
      if (hi - lo + 1 > best.support) best = {u, n, d[(lo + hi) / 2], hi - lo + 1};  // the window's median
    }
  }
  return best;
}

// The points `sel` of `changes` as a described object (centroid, boxes) to read its shape.
MapObject Shape(const PointCloud& changes, const std::vector<std::uint32_t>& sel) {
  MapObject o;
  o.cloud = changes.select(sel);
  Describe(o);
  OrientedBox(o);
  return o;
}

// The face and the rest of one cluster (FaceAndRest), or nothing when the cluster is no such pair.
struct Split {
  std::vector<std::uint32_t> face, rest;
};

// The cluster's densest xy line (the most points within an object_tolerance_m wide band) is a
// face where its slab (the points within the tolerance of it: the face's thickness and the two
// sessions' samplings of it) runs on past the rest of the cluster (the points off the slab) by
// object_min_length_m or more on both sides: a thing standing beside a long face. The face is the
// slab's points within half the tolerance of the line (a thin face's width, ThinFace) up to the
// height the slab reaches past the rest (and half the tolerance), wherever along it; the rest is
// the other thing. Not where the rest is itself a thin face (the other leg of an L), nor where it
// holds fewer than object_min_points (posts, a stray row). A car's or a container's side has the
// rest of it at its ends (the end face, the roof: a corner of one thing), a walled lot's wall the
// other walls all along it.
Split FaceAndRest(const PointCloud& changes, const std::vector<std::uint32_t>& sel, const MapConfig& cfg) {
  const std::size_t min_points = std::size_t(cfg.object_min_points);
  if (sel.size() < 2 * min_points) return {};  // no two pieces of object_min_points
  const double tol = cfg.object_tolerance_m;
  std::vector<Eigen::Vector2d> xy(sel.size());
  Eigen::AlignedBox2d box;
  for (std::size_t k = 0; k < sel.size(); ++k) box.extend(xy[k] = changes.points[sel[k]].xyz().head<2>().cast<double>());
  // The face runs on past the rest on both sides: the cluster spans twice object_min_length_m.
  if (box.diagonal().norm() < 2.0 * cfg.object_min_length_m) return {};
  const Line line = DensestLine(xy, tol);
  // Each point's offset along the line and across it; the extents along it of the slab's points
  // (within tol of the line: [0]) and of the rest ([1]).
  std::vector<double> along(sel.size()), across(sel.size());
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (std::size_t k = 0; k < sel.size(); ++k) {
    along[k] = line.u.dot(xy[k]), across[k] = std::abs(line.n.dot(xy[k]) - line.offset);
    const int side = across[k] <= tol ? 0 : 1;
    lo[side] = std::min(lo[side], along[k]), hi[side] = std::max(hi[side], along[k]);
  }
  if (lo[1] > hi[1] || !RunsOnPastBothEnds(lo[0], hi[0], lo[1], hi[1], cfg)) return {};  // no rest, or not past it
  double top = -std::numeric_limits<double>::infinity();  // the slab's height beyond the rest
  for (std::size_t k = 0; k < sel.size(); ++k)
    if (across[k] <= tol && (along[k] < lo[1] - tol || along[k] > hi[1] + tol))
      top = std::max(top, double(changes.points[sel[k]].z));
  Split out;
  for (std::size_t k = 0; k < sel.size(); ++k) {
    const bool on_face = across[k] <= 0.5 * tol && double(changes.points[sel[k]].z) <= top + 0.5 * tol;
    (on_face ? out.face : out.rest).push_back(sel[k]);
  }
  if (out.rest.size() < min_points || out.face.size() < min_points || ThinFace(Shape(changes, out.rest), cfg)) return {};
  return out;
}

}  // namespace

std::vector<Piece> SplitFaces(const PointCloud& changes, std::vector<std::vector<std::uint32_t>> clusters,
                              const MapConfig& cfg) {
  std::vector<Piece> out;
  for (std::size_t k = 0; k < clusters.size(); ++k) {
    Split s = FaceAndRest(changes, clusters[k], cfg);
    if (s.face.empty()) {
      out.push_back({std::move(clusters[k]), -1});
      continue;
    }
    out.push_back({std::move(s.face), int(k)});
    out.push_back({std::move(s.rest), int(k)});
  }
  std::stable_sort(out.begin(), out.end(), [](const Piece& a, const Piece& b) { return a.sel.size() > b.sel.size(); });
  return out;
}

}  // namespace ltm::map::detail
