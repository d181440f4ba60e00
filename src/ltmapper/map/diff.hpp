// ltmapper map: diff of two map states, agreement with an LT-removert pair, radius masks.
#pragma once

#include "ltmapper/map/store.hpp"

#include <string>
#include <vector>

namespace ltm::map {

// What changed between the map as of session `from` and as of session `to` (any two, either
// order), from the stored deltas alone (the paper's virtual LD): PD = points of the `to` state
// the `from` state lacks (strong / weak as the step that added them said), ND = points of the
// `from` state the `to` state lacks (removed as seen through). Weak ND are not changes of the
// map (they stay in it; stored only in the columns of strong ND unless store_weak_nd), so they are not listed.
// cls and session set (session = the state the point is in).
struct MapDiff {
  PointCloud pd_strong, pd_weak, nd;
  double seconds = 0.0;
};
MapDiff Diff(const Store& store, int from, int to, const Region& region = {}, int threads = 0);
// Point-wise agreement of `got` with `want`: precision = share of `got` points with a `want`
// point within radius_m, recall = share of `want` points with a `got` point within radius_m.
struct Agreement {
  std::size_t got = 0, want = 0;
  double precision = 0.0, recall = 0.0;
};
Agreement Agree(const PointCloud& got, const PointCloud& want, double radius_m);
// A diff against an LT-removert pair folder of the same two sessions: PD (strong + weak) against
// the pair's pd_strong + pd_weak + pd_unobserved (new territory enters the map as strong PD), ND
// against its nd_strong.
struct PairAgreement {
  Agreement pd, nd;
};
PairAgreement CompareWithLdPair(const MapDiff& diff, const std::string& pair_dir, double radius_m);

}  // namespace ltm::map
