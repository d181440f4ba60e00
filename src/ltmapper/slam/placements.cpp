// LT-SLAM's checks of the placements it found (after the refinement): a placement whose predicted
// overlaps failed verification at as many places as its loops hold at (DropContradicted), and one
// that a single move to look-alike places of the drives would explain as well (DropAmbiguous), is
// dropped: its session is not aligned. Pure bookkeeping over the loops, the routes and the
// placements; the alignment (multi_session.cpp) supplies look-alike candidates and their
// verification (PlacementEvidence).
#include "ltmapper/slam/internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace ltm::slam {
namespace {

// The place of each of `at` (positions along a route [m]), numbered from the route's start:
// positions closer than `radius_m` to the first of their place are one place.
std::vector<int> PlaceOf(const std::vector<double>& at, double radius_m) {
  std::vector<std::size_t> order(at.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) { return at[x] < at[y]; });
  std::vector<int> place(at.size(), 0);
  int n = 0;
  double start = 0.0;
  for (std::size_t i : order) {
    if (n == 0 || at[i] - start > radius_m) ++n, start = at[i];
    place[i] = n - 1;
  }
  return place;
}

// How many places `at` covers (PlaceOf).
int Places(const std::vector<double>& at, double radius_m) {
  const std::vector<int> place = PlaceOf(at, radius_m);
  return place.empty() ? 0 : *std::max_element(place.begin(), place.end()) + 1;
}

// Whether loop l ties session s to another session.
bool Between(const LoopRecord& l, std::size_t s) {
  return !OwnLoop(l) && (l.a.session == int(s) || l.b.session == int(s));
}
// The end of loop l in session s (l between s and another session).
const NodeKey& EndIn(const LoopRecord& l, std::size_t s) { return l.b.session == int(s) ? l.b : l.a; }

// Drops session s's placement: its verified loops between sessions rejected with `why`.
void RejectPlacement(std::vector<LoopRecord>& loops, std::size_t s, const std::string& why) {
  for (LoopRecord& l : loops)
    if (Between(l, s) && l.verified) l.verified = false, l.status = "rejected: alignment " + why;
}

// An alignment predicts where its session's scans overlap the others'; the radius search tested
// those predictions. A candidate whose scans looked at the same space at the predicted pose (view
// >= registration.min_overlap) and failed verification contradicts the placement there; one that
// was accepted confirms it. A placement is dropped (its session's loops between sessions
// rejected, the session not aligned) when both balances go against it:
//  - predictions: more of the tested ones failed than held;
//  - places: loops whose keyframes lie within the overlap reach (`radius_m`) of each other along
//    the session's route see one scene, one place of evidence however many loops (consecutive
//    keyframes that match a repeated scene all agree); the predictions failed at as many places
//    as the accepted loops hold at.
// A scene repeated elsewhere (mirrored blocks seen by a narrow forward cone) verifies where it
// repeats and fails wherever else the placement predicts overlap; a true placement over a short
// shared stretch may fail at a place as often as it holds there, but its tested predictions hold.
// Returns the sessions dropped with their reasons.
std::vector<std::pair<std::size_t, std::string>> DropContradicted(const std::vector<std::vector<double>>& routes,
                                                                  std::vector<LoopRecord>& loops, const SlamResult& res,
                                                                  const SlamConfig& cfg, double radius_m) {
  std::vector<std::pair<std::size_t, std::string>> dropped;
  for (std::size_t s = 1; s < res.sessions.size(); ++s) {
    if (!res.sessions[s].aligned) continue;
    const std::vector<double>& route = routes[s];
    std::vector<double> support, contra;
    std::size_t confirmed = 0;
    for (const LoopRecord& l : loops) {
      if (!Between(l, s)) continue;
      const double at = route[std::size_t(EndIn(l, s).keyframe)];
      const bool tested = l.source == "radius" && l.view >= cfg.reg_min_overlap;
      if (l.accepted) support.push_back(at);
      if (tested && !l.verified) contra.push_back(at);
      confirmed += tested && l.accepted;
    }
    const int held = Places(support, radius_m), failed = Places(contra, radius_m);
    if (contra.size() <= confirmed || failed < held) continue;
    const std::string why = "contradicted: " + std::to_string(contra.size()) + " keyframe pair(s) its placement shows looking "
                            "at the same space failed verification (" + std::to_string(confirmed) + " held), at " +
                            std::to_string(failed) + " place(s) of its route; its " + std::to_string(support.size()) +
                            " loops hold at " + std::to_string(held);
    RejectPlacement(loops, s, why);
    dropped.push_back({s, why});
  }
  return dropped;
}

// A place session s's accepted loops between sessions hold at (PlaceOf along its route, the
// overlap reach apart): its loop keyframes (both ends), each with its best loop there (highest
// inlier ratio), the place's position along s's route and a world position of it.
struct LoopPlace {
  std::map<NodeKey, const LoopRecord*> best;
  double route_m = 0.0;
  Eigen::Vector3d where = Eigen::Vector3d::Zero();
};
std::vector<LoopPlace> LoopPlaces(const PlacementEvidence& e, const std::vector<LoopRecord>& loops, const SlamResult& res,
                                  std::size_t s) {
  std::vector<double> at;
  std::vector<const LoopRecord*> which;
  for (const LoopRecord& l : loops)
    if (l.accepted && Between(l, s)) at.push_back(e.routes[s][std::size_t(EndIn(l, s).keyframe)]), which.push_back(&l);
  const std::vector<int> place = PlaceOf(at, e.place_m);
  std::vector<LoopPlace> out(std::size_t(Places(at, e.place_m)));
  for (std::size_t i = 0; i < which.size(); ++i) {
    LoopPlace& p = out[std::size_t(place[i])];
    if (p.best.empty())
      p.route_m = at[i], p.where = res.sessions[s].T_world_sensor[std::size_t(EndIn(*which[i], s).keyframe)].translation();
    for (const NodeKey& n : {which[i]->a, which[i]->b}) {
      const LoopRecord*& best = p.best[n];
      if (!best || which[i]->overlap > best->overlap) best = which[i];
    }
  }
  return out;
}

// Where a look-alike `e` of an end of loop l (e.b that end, e.a its look-alike) would put session
// s: the world transform from where the placement puts s's keyframes to where they would be if
// that end were its look-alike. The other session's keyframe o looking like o': s's keyframe m of
// l would sit at W(o') T_o'o T_om instead of W(m). s's own m looking like m': m' would sit where
// the loop put m, at W(m) T_m'm^-1 instead of W(m').
Pose Shift(const SlamResult& res, const LoopRecord& l, std::size_t s, const LoopRecord& e) {
  const bool own_b = l.b.session == int(s);
  const NodeKey& m = EndIn(l, s);
  const NodeKey& o = own_b ? l.a : l.b;
  const Pose T_o_m = own_b ? l.T_a_b : l.T_a_b.inverse();
  const auto W = [&](const NodeKey& k) { return res.sessions[std::size_t(k.session)].T_world_sensor[std::size_t(k.keyframe)]; };
  if (e.b == o) return W(e.a) * e.T_a_b * T_o_m * W(m).inverse();
  return W(m) * e.T_a_b.inverse() * W(e.a).inverse();
}

// Why session s's placement is ambiguous, "" when it is not. A placement rests on the places its
// loops hold at (LoopPlaces). A loop keyframe that verifies against another place of its own drive
// (a row of identical blocks; a street that looks the same both ways to a forward cone) could as
// well be at that look-alike, which would move the placement (Shift). When one such move fits every
// place (the placements it implies agree as the consensus's must: PlacementsAgree, over the route
// between the places), another placement explains all the loops as well, and nothing fixes this one. It takes two
// places at least: one look-alike alone may be chance (scans mostly of flat ground verify
// anywhere flat), one move that fits independent places is a repeated scene. Places without
// candidates settle it at no cost; the others are registered fewest candidates first.
std::string Ambiguity(const PlacementEvidence& e, const std::vector<LoopRecord>& loops, const SlamResult& res,
                      std::size_t s, const SlamConfig& cfg) {
  struct Place {
    LoopPlace at;
    std::vector<LoopRecord> cand;
    std::vector<Pose> shifts;  // of the verified look-alikes
  };
  std::vector<LoopPlace> held = LoopPlaces(e, loops, res, s);
  if (held.size() < 2) return "";
  std::vector<Place> places;
  for (LoopPlace& at : held) {
    Place p{std::move(at), {}, {}};
    for (const auto& [n, best] : p.at.best) {
      const std::vector<LoopRecord> mine = e.look_alikes(n);
      p.cand.insert(p.cand.end(), mine.begin(), mine.end());
    }
    if (p.cand.empty()) return "";
    places.push_back(std::move(p));
  }
  std::sort(places.begin(), places.end(), [](const Place& x, const Place& y) { return x.cand.size() < y.cand.size(); });
  for (Place& p : places) {
    e.verify(p.cand);
    for (const LoopRecord& c : p.cand)
      if (c.verified) p.shifts.push_back(Shift(res, *p.at.best.at(c.b), s, c));
    if (p.shifts.empty()) return "";
  }
  const Pose& A = res.sessions[s].anchor;
  const auto agree = [&](const Pose& x, const Place& px, const Pose& y, const Place& py) {
    return PlacementsAgree(x * A, y * A, std::abs(px.at.route_m - py.at.route_m), cfg);
  };
  for (const Pose& x : places.front().shifts) {
    const bool fits = std::all_of(places.begin() + 1, places.end(), [&](const Place& p) {
      return std::any_of(p.shifts.begin(), p.shifts.end(), [&](const Pose& y) { return agree(x, places.front(), y, p); });
    });
    if (!fits) continue;
    char moved[96];
    std::snprintf(moved, sizeof moved, "%.1f m, %.0f deg", (x * places.front().at.where - places.front().at.where).norm(),
                  AngleDeg(x.linear()));
    return "ambiguous: another placement (" + std::string(moved) + " away) fits all " + std::to_string(places.size()) +
           " place(s) its loops hold at, where keyframes look like other places of their own drives";
  }
  return "";
}

// Ambiguity of every aligned session not in `skip`; an ambiguous one's loops between sessions are
// rejected, as DropContradicted does. Returns the sessions dropped with their reasons.
std::vector<std::pair<std::size_t, std::string>> DropAmbiguous(const PlacementEvidence& e, std::vector<LoopRecord>& loops,
                                                               const SlamResult& res, const std::set<std::size_t>& skip,
                                                               const SlamConfig& cfg) {
  std::vector<std::pair<std::size_t, std::string>> dropped;
  for (std::size_t s = 1; s < res.sessions.size(); ++s) {
    if (!res.sessions[s].aligned || skip.count(s)) continue;
    const std::string why = Ambiguity(e, loops, res, s, cfg);
    if (why.empty()) continue;
    RejectPlacement(loops, s, why);
    dropped.push_back({s, why});
  }
  return dropped;
}

}  // namespace

std::vector<std::pair<std::size_t, std::string>> DroppedPlacements(const PlacementEvidence& e, std::vector<LoopRecord>& loops,
                                                                   const SlamResult& res, const SlamConfig& cfg) {
  auto dropped = DropContradicted(e.routes, loops, res, cfg, e.place_m);
  std::set<std::size_t> skip;
  for (const auto& x : dropped) skip.insert(x.first);
  const auto ambiguous = DropAmbiguous(e, loops, res, skip, cfg);
  dropped.insert(dropped.end(), ambiguous.begin(), ambiguous.end());
  return dropped;
}

}  // namespace ltm::slam
