// Identity across steps (objects.cpp head comment, steps 5-7): the rows of all steps of a store,
// each computed by its step alone, become one list a user can follow: an earlier step's object
// confirmed by a later view is no second object, every row gets a stable id, a disappeared and an
// appeared object of one step that could be one are a move, and the rows that are one object share a
// track.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/map/detail.hpp"
#include "ltmapper/map/map.hpp"

#include <algorithm>
#include <limits>
#include <map>
#include <numeric>
#include <tuple>

namespace ltm::map {
namespace {

using detail::CouldHaveMoved;
using detail::IsPd;
using detail::SeenPoints;
using detail::UnseenPoints;
using detail::Unseen;

// Does disappeared object `o` confirm `e`, one an earlier step reported gone from the same session's
// scans? An object is reported whole at its step, with the rows its query never saw through
// (UnseenParts: weak ND, which the map keeps); a later session that sees those rows gone confirms
// it: a majority of o's seen points lies within the cluster tolerance of e's unseen parts.
// (vlp16_drift3x: the wall that left, reported at step 1 with 1354 unseen points, came again at
// step 2 as 1323 points, 99 % of its seen ones on those: a second report, of half the wall.)
bool Confirms(const MapObject& o, const MapObject& e, const MapConfig& cfg) {
  if (o.change != "disappeared" || e.change != "disappeared" || e.session >= o.session || e.exists_in != o.exists_in)
    return false;
  const double tol = cfg.object_tolerance_m;
  if ((o.lo.array() > e.hi.array() + tol).any() || (e.lo.array() > o.hi.array() + tol).any()) return false;
  const PointCloud seen = SeenPoints(o.cloud), unseen = UnseenPoints(e.cloud);
  if (seen.empty() || unseen.empty()) return false;
  const std::vector<bool> near = geometry::WithinRadius(seen, unseen, tol);
  return 2 * std::size_t(std::count(near.begin(), near.end(), true)) > near.size();
}

// Objects that confirm one an earlier step reported (Confirms) are no new change: they join
// `rejected` as "reported".
void SetAsideConfirmations(std::vector<MapObject>& objects, std::vector<MapObject>& rejected, const MapConfig& cfg) {
  std::vector<bool> confirms(objects.size(), false);
  for (std::size_t i = 0; i < objects.size(); ++i)
    for (const MapObject& e : objects) confirms[i] = confirms[i] || Confirms(objects[i], e, cfg);
  std::vector<MapObject> kept;
  for (std::size_t i = 0; i < objects.size(); ++i) {
    if (!confirms[i]) {
      kept.push_back(std::move(objects[i]));
      continue;
    }
    objects[i].rejected = "reported";
    rejected.push_back(std::move(objects[i]));
  }
  objects.swap(kept);
}

// Stable ids: objects ordered by step, change and centroid (x, then y).
void AssignIds(std::vector<MapObject>& objects) {
  std::sort(objects.begin(), objects.end(), [](const MapObject& a, const MapObject& b) {
    return std::make_tuple(a.session, a.change, a.centroid.x(), a.centroid.y()) <
           std::make_tuple(b.session, b.change, b.centroid.x(), b.centroid.y());
  });
  for (std::size_t k = 0; k < objects.size(); ++k) {
    objects[k].id = int(k);
    objects[k].cloud.object.assign(objects[k].cloud.size(), objects[k].id);
  }
}

// Rows a and b are one object at one place: found by different steps on the same side of the
// change (PD: appeared, strong ND: disappeared; a move's end by its class), with a majority of the
// smaller one's points within object_tolerance_m of the other's.
bool SameObject(const MapObject& a, const MapObject& b, const MapConfig& cfg) {
  if (a.session == b.session || IsPd(a.cls) != IsPd(b.cls) || a.cloud.empty() || b.cloud.empty()) return false;
  const double tol = cfg.object_tolerance_m;
  if ((a.lo.array() > b.hi.array() + tol).any() || (b.lo.array() > a.hi.array() + tol).any()) return false;
  const MapObject &small = a.points <= b.points ? a : b, &large = a.points <= b.points ? b : a;
  const std::vector<bool> near = geometry::WithinRadius(small.cloud, large.cloud, tol);
  return 2 * std::size_t(std::count(near.begin(), near.end(), true)) > near.size();
}

// Moved: a disappeared and an appeared object of the same step that could be one (CouldHaveMoved),
// each object in at most one pair. Objects alike in shape (two containers, or cars) are told apart
// by nothing their boxes hold: the size differences of one object's two views and of two such
// objects overlap. So of the pairings with the most moves, the one that moves the objects least in
// all (LeastCostPairs over the centroids' displacement): the likeliest, as moves are more often
// short than long. An end that stands among unchanged objects of its shape (alike_beside: a row of
// parked cars) is paired with none: there, one that left and one that came are as likely two
// things as one that moved. Each still lists the other in move_candidates. A row that is an end
// of a move an earlier step linked against the same reference, seen again (SameObject, the same
// side of the change), is that end (InheritMoves), no end of a move of its own step: the container
// that came at step 2 is no candidate for the one that left at step 3.
void LinkMoved(std::vector<MapObject>& objects, const MapConfig& cfg) {
  std::map<int, std::pair<std::vector<std::size_t>, std::vector<std::size_t>>> ends;  // step -> gone, came
  for (std::size_t i = 0; i < objects.size(); ++i) {
    auto& [gone, came] = ends[objects[i].session];
    if (objects[i].change == "disappeared") gone.push_back(i);
    if (objects[i].change == "appeared") came.push_back(i);
  }
  std::vector<std::size_t> linked;  // the ends of the moves of the steps done
  const auto seen_again = [&](std::size_t i) {
    return std::any_of(linked.begin(), linked.end(), [&](std::size_t j) {
      return objects[j].reference == objects[i].reference && SameObject(objects[j], objects[i], cfg);
    });
  };
  const double forbidden = std::numeric_limits<double>::infinity();
  for (auto& [step, e] : ends) {
    auto& [gone, came] = e;
    for (auto* side : {&gone, &came}) side->erase(std::remove_if(side->begin(), side->end(), seen_again), side->end());
    std::vector<std::vector<double>> cost(gone.size(), std::vector<double>(came.size(), forbidden));
    for (std::size_t r = 0; r < gone.size(); ++r)
      for (std::size_t c = 0; c < came.size(); ++c) {
        MapObject &d = objects[gone[r]], &a = objects[came[c]];
        if (!CouldHaveMoved(d, a, cfg)) continue;
        d.move_candidates.push_back(a.id);  // gone and came are in id order: each list ascends
        a.move_candidates.push_back(d.id);
        if (d.alike_beside == 0 && a.alike_beside == 0) cost[r][c] = (d.centroid - a.centroid).norm();
      }
    for (const auto& [r, c] : detail::LeastCostPairs(cost)) {
      objects[gone[r]].partner = objects[came[c]].id;
      objects[came[c]].partner = objects[gone[r]].id;
      linked.push_back(gone[r]), linked.push_back(came[c]);
    }
  }
  for (auto& o : objects)
    if (o.partner >= 0) o.change = "moved";
}

// Identity across steps (MapObject::track): rows that are one object (SameObject) and a move's two
// ends are joined (union-find over the row ids, which AssignIds made their positions).
void AssignTracks(std::vector<MapObject>& objects, const MapConfig& cfg) {
  std::vector<std::size_t> root(objects.size());
  std::iota(root.begin(), root.end(), std::size_t(0));
  const auto find = [&](std::size_t i) {
    while (root[i] != i) i = root[i] = root[root[i]];
    return i;
  };
  const auto join = [&](std::size_t i, std::size_t j) {
    const std::size_t a = find(i), b = find(j);
    root[std::max(a, b)] = std::min(a, b);  // the lowest id leads
  };
  for (std::size_t i = 0; i < objects.size(); ++i) {
    if (objects[i].partner >= 0) join(i, std::size_t(objects[i].partner));
    for (std::size_t j = i + 1; j < objects.size(); ++j)
      if (SameObject(objects[i], objects[j], cfg)) join(i, j);
  }
  std::map<std::size_t, std::vector<int>> sessions;  // track -> its rows' exists_in
  for (std::size_t i = 0; i < objects.size(); ++i) sessions[find(i)].push_back(objects[i].exists_in);
  for (auto& [t, s] : sessions) {
    std::sort(s.begin(), s.end());
    s.erase(std::unique(s.begin(), s.end()), s.end());
  }
  for (std::size_t i = 0; i < objects.size(); ++i) {
    objects[i].track = int(find(i));
    objects[i].track_sessions = sessions[find(i)];
  }
}

// A later step's view of a moved object's end is that end too: a row of the same track, on the
// same side of the change (PD: the place it came to, strong ND: the place it left) and against
// the same reference session, as a row LinkMoved paired, is "moved" with that row's partner and
// move candidates (the container that came at step 1 seen from its other side at step 2: against
// the reference it was still elsewhere, so at step 2 too it is a move's end, not a new object).
void InheritMoves(std::vector<MapObject>& objects) {
  std::map<std::tuple<int, bool, int>, const MapObject*> moved_end;  // (track, PD side, reference) -> row
  for (const auto& o : objects)
    if (o.change == "moved") moved_end.emplace(std::make_tuple(o.track, IsPd(o.cls), o.reference), &o);
  for (auto& o : objects) {
    if (o.change == "moved") continue;
    const auto it = moved_end.find(std::make_tuple(o.track, IsPd(o.cls), o.reference));
    if (it == moved_end.end()) continue;
    o.change = "moved";
    o.partner = it->second->partner;
    o.move_candidates = it->second->move_candidates;
  }
}

}  // namespace

namespace detail {
void IdentifyAcrossSteps(std::vector<MapObject>& objects, std::vector<MapObject>& rejected, const MapConfig& cfg) {
  SetAsideConfirmations(objects, rejected, cfg);
  AssignIds(objects);
  LinkMoved(objects, cfg);
  AssignTracks(objects, cfg);
  InheritMoves(objects);
}
}  // namespace detail

}  // namespace ltm::map
