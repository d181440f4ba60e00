// The checks of the placements LT-SLAM found (slam/placements.cpp: DroppedPlacements) on
// bookkeeping alone: two straight drives 4 m apart, the query placed beside the central, loops
// between them at two places of the route, and the verdicts the checks give. The end-to-end cases
// that made them (forward cones in mirrored and repeated streets) no longer reach them: place
// clouds no longer verify the wrong loops there (test_slam_recall.cpp).
#include "ltmapper/slam/internal.hpp"
#include "test_slam_synth.hpp"

#include <gtest/gtest.h>

#include <vector>

using namespace ltm;
using namespace ltm::slam;
using ltm::test::MakePose;

namespace {
constexpr int kKeyframes = 100;   // 1 m apart along x
constexpr double kLaneM = 4.0;    // the query drives beside the central
constexpr double kPlaceM = 20.0;  // loops this close along the route are one place

// The central (session 0) along y = 0 and the query (session 1) along y = kLaneM, both aligned
// with the world, and each one's distance along its route.
struct TwoDrives {
  SlamResult res;
  std::vector<std::vector<double>> routes;
  TwoDrives() {
    res.sessions.resize(2);
    for (int s = 0; s < 2; ++s) {
      SessionAlignment& a = res.sessions[std::size_t(s)];
      a.aligned = true;
      std::vector<double> route;
      for (int k = 0; k < kKeyframes; ++k) {
        a.T_world_sensor.push_back(MakePose(k, s * kLaneM, 0, 0));
        a.T_session_sensor.push_back(a.T_world_sensor.back());
        route.push_back(k);
      }
      routes.push_back(route);
    }
  }
  // A loop between central keyframe k and query keyframe j at their world poses.
  LoopRecord Loop(int k, int j, const std::string& source, bool verified) const {
    LoopRecord l;
    l.a = {0, k};
    l.b = {1, j};
    l.source = source;
    l.T_a_b = res.sessions[0].T_world_sensor[std::size_t(k)].inverse() * res.sessions[1].T_world_sensor[std::size_t(j)];
    l.verified = l.accepted = verified;
    l.view = 0.5;
    return l;
  }
};

// Loops accepted at two places of the route (keyframes 10-12 and 60-62).
std::vector<LoopRecord> LoopsAtTwoPlaces(const TwoDrives& d) {
  std::vector<LoopRecord> loops;
  for (int k : {10, 11, 12, 60, 61, 62}) loops.push_back(d.Loop(k, k, "sc", true));
  return loops;
}

// Evidence whose look-alikes put each central keyframe k at k + shift(k) of its own drive, all
// verifying (shift 0: no look-alike).
PlacementEvidence LookAlikes(const TwoDrives& d, const std::function<int(int)>& shift) {
  return PlacementEvidence{d.routes, kPlaceM,
                           [shift](const NodeKey& n) {
                             std::vector<LoopRecord> out;
                             if (n.session != 0 || shift(n.keyframe) == 0) return out;
                             LoopRecord e;
                             e.a = {0, n.keyframe + shift(n.keyframe)};
                             e.b = n;
                             e.source = "look-alike";
                             out.push_back(e);
                             return out;
                           },
                           [](std::vector<LoopRecord>& cand) {
                             for (LoopRecord& c : cand) c.verified = true;
                           }};
}

bool AnyAccepted(const std::vector<LoopRecord>& loops) {
  for (const LoopRecord& l : loops)
    if (l.verified) return true;
  return false;
}
}  // namespace

// The radius search tested the placement's predictions: more failed than held, at as many places
// as its loops hold at: the placement is dropped, its loops rejected with the reason.
TEST(SlamPlacements, APlacementItsPredictedOverlapsContradictIsDropped) {
  TwoDrives d;
  std::vector<LoopRecord> loops = LoopsAtTwoPlaces(d);
  for (int k : {30, 33, 36, 80, 83, 86}) loops.push_back(d.Loop(k, k, "radius", false));
  const auto dropped = DroppedPlacements(LookAlikes(d, [](int) { return 0; }), loops, d.res, SlamConfig());
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_EQ(dropped[0].first, 1u);
  EXPECT_NE(dropped[0].second.find("contradicted"), std::string::npos) << dropped[0].second;
  EXPECT_FALSE(AnyAccepted(loops));
}

// The same failures at fewer places than the loops hold at (one), or predictions that held as
// often as they failed, leave the placement.
TEST(SlamPlacements, FailuresAtFewerPlacesOrAsManyHeldLeaveThePlacement) {
  TwoDrives d;
  std::vector<LoopRecord> one_place = LoopsAtTwoPlaces(d);
  for (int k : {30, 31, 32}) one_place.push_back(d.Loop(k, k, "radius", false));
  EXPECT_TRUE(DroppedPlacements(LookAlikes(d, [](int) { return 0; }), one_place, d.res, SlamConfig()).empty());
  std::vector<LoopRecord> held = LoopsAtTwoPlaces(d);
  for (int k : {30, 80}) held.push_back(d.Loop(k, k, "radius", false));
  for (int k : {40, 90}) {
    held.push_back(d.Loop(k, k, "radius", true));
  }
  EXPECT_TRUE(DroppedPlacements(LookAlikes(d, [](int) { return 0; }), held, d.res, SlamConfig()).empty());
  EXPECT_TRUE(AnyAccepted(held));
}

// Every place the loops hold at looks like the place 30 m on along the central's drive: one move
// of the placement explains all the loops as well, and the placement is dropped as ambiguous.
// Look-alikes that move it by different amounts (30 m at one place, 45 m at the other) are no
// repeated scene: it stays.
TEST(SlamPlacements, APlacementOnePlacementMoveExplainsIsDroppedAsAmbiguous) {
  TwoDrives d;
  std::vector<LoopRecord> loops = LoopsAtTwoPlaces(d);
  const auto dropped = DroppedPlacements(LookAlikes(d, [](int) { return 30; }), loops, d.res, SlamConfig());
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_NE(dropped[0].second.find("ambiguous: another placement (30.0 m"), std::string::npos) << dropped[0].second;
  EXPECT_FALSE(AnyAccepted(loops));

  std::vector<LoopRecord> apart = LoopsAtTwoPlaces(d);
  EXPECT_TRUE(DroppedPlacements(LookAlikes(d, [](int k) { return k < 50 ? 30 : -45; }), apart, d.res, SlamConfig())
                  .empty());
  EXPECT_TRUE(AnyAccepted(apart));
}
