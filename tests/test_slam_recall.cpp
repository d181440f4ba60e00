// LT-SLAM recall on the simulator (issue 15): two sessions of 120 keyframes of the default
// scenario, which the fixed Scan Context threshold (0.4) and the fixed fitness gate (0.1 m^2)
// left unaligned, must align with an inter-session consistency under 0.1 m against the truth;
// no accepted loop may be false. The global-registration fallback aligns them when Scan Context
// gives no candidate at all, and places nothing when the query drove another city.
#include "ltmapper/sim/sim.hpp"
#include "ltmapper/slam/slam.hpp"
#include "test_util.hpp"

#include <cmath>
#include <cstdio>
#include <limits>

using namespace ltm;
using namespace ltm::slam;

namespace {
constexpr double kDeg = M_PI / 180.0;
constexpr int kKeyframes = 120;          // the failing case: 2 sessions x 120 keyframes
constexpr double kNearCentralM = 5.0;    // query keyframes this close to the central path count
constexpr double kConsistencyM = 0.1;    // acceptance: inter-session consistency RMSE
constexpr double kWrongPlaceM = 1.0;     // a placement farther off is wrong (bench/slam_matrix.py)
// A loop farther than this from the truth is false (as bench/slam_check_loops.py counts).
constexpr double kFalseLoopM = 1.0;
constexpr double kFalseLoopDeg = 3.0;

// Sessions in memory from the simulator: drifted odometry poses, scans cast on demand here.
std::vector<Session> SimSessions(sim::Simulator& s) {
  std::vector<Session> out;
  for (int i = 0; i < s.sessions(); ++i) {
    Session ses;
    ses.name = "session_" + std::to_string(i);
    const std::vector<Pose>& odo = s.T_session_sensor_drifted(i);
    for (int k = 0; k < s.keyframes(i); ++k) {
      Keyframe kf;
      kf.index = k;
      kf.T_session_sensor = odo[k];
      kf.cloud = std::make_shared<PointCloud>(s.CastScan(i, k));
      ses.keyframes.push_back(kf);
      if (k > 0) {
        Edge e;
        e.from = k - 1;
        e.to = k;
        e.T_from_to = odo[k - 1].inverse() * odo[k];
        ses.odometry.push_back(e);
      }
    }
    out.push_back(std::move(ses));
  }
  return out;
}

// Relative pose error between each query keyframe and its nearest central keyframe (true
// positions within kNearCentralM), estimated vs true: RMSE of the translation part.
double ConsistencyRmse(const SlamResult& r, sim::Simulator& s, int* pairs) {
  const auto& T0 = s.T_world_sensor(0);
  const auto& T1 = s.T_world_sensor(1);
  double sum = 0.0;
  *pairs = 0;
  for (std::size_t j = 0; j < T1.size(); ++j) {
    double best = std::numeric_limits<double>::infinity();
    std::size_t bi = 0;
    for (std::size_t i = 0; i < T0.size(); ++i) {
      const double d = (T0[i].translation() - T1[j].translation()).norm();
      if (d < best) best = d, bi = i;
    }
    if (best > kNearCentralM) continue;
    const Pose truth = T0[bi].inverse() * T1[j];
    const Pose est = r.sessions[0].T_world_sensor[bi].inverse() * r.sessions[1].T_world_sensor[j];
    sum += (truth.inverse() * est).translation().squaredNorm();
    ++*pairs;
  }
  return *pairs > 0 ? std::sqrt(sum / *pairs) : std::numeric_limits<double>::infinity();
}

// Accepted loops farther than kFalseLoopM / kFalseLoopDeg from the truth.
int FalseLoops(const SlamResult& r, sim::Simulator& s) {
  int false_loops = 0;
  for (const LoopRecord& l : r.loops) {
    if (!l.accepted) continue;
    const Pose truth = s.T_world_sensor(l.a.session)[l.a.keyframe].inverse() *
                       s.T_world_sensor(l.b.session)[l.b.keyframe];
    const Pose err = truth.inverse() * l.T_a_b;
    false_loops += err.translation().norm() > kFalseLoopM ||
                   Eigen::AngleAxisd(err.linear()).angle() / kDeg > kFalseLoopDeg;
  }
  return false_loops;
}

int LoopsFrom(const SlamResult& r, const std::string& source, bool accepted) {
  int n = 0;
  for (const LoopRecord& l : r.loops) n += l.source == source && (!accepted || l.accepted);
  return n;
}
}  // namespace

// Two sessions of `keyframes` of the default scenario (another world with seed_offset).
sim::SimConfig TwoSessions(int keyframes, int seed_offset = 0) {
  sim::SimConfig sc;
  sc.sessions = 2;
  sc.keyframes = keyframes;
  sc.seed += seed_offset;
  return sc;
}

TEST(SlamRecall, TwoShortSessionsOfTheDefaultScenarioAlign) {
  sim::Simulator s(TwoSessions(kKeyframes), 2);
  const std::vector<Session> sessions = SimSessions(s);
  SlamConfig cfg;
  cfg.refine_rounds = 1;  // one radius round spreads the loops along the overlap (run time)
  const SlamResult r = AlignSessions(sessions, cfg, 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  int pairs = 0;
  const double rmse = ConsistencyRmse(r, s, &pairs);
  const int false_loops = FalseLoops(r, s);
  std::printf("sim 2 x %d: %d loops accepted (%d false), consistency RMSE %.3f m over %d keyframe "
              "pairs, %d GICP, %.2f s\n",
              kKeyframes, r.sessions[1].loops_accepted, false_loops, rmse, pairs, r.registrations,
              r.time_total_s);
  EXPECT_GT(pairs, 0);
  EXPECT_LT(rmse, kConsistencyM);
  EXPECT_EQ(false_loops, 0);
}

// Scan Context gives no candidate (no loop budget): only the global fallback can align the
// query, and must, as accurately, also when one round of placements is too few; without the
// fallback the query stays unaligned.
TEST(SlamRecall, GlobalRegistrationAlignsWithoutScanContext) {
  sim::Simulator s(TwoSessions(kKeyframes), 2);
  const std::vector<Session> sessions = SimSessions(s);
  SlamConfig cfg;
  cfg.sc_max_loops_per_pair = 0;
  cfg.refine_rounds = 1;
  const SlamResult r = AlignSessions(sessions, cfg, 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  EXPECT_EQ(LoopsFrom(r, "sc", false), 0);
  EXPECT_GE(LoopsFrom(r, "global", true), cfg.min_loops);
  int pairs = 0;
  const double rmse = ConsistencyRmse(r, s, &pairs);
  std::printf("global fallback, sim 2 x %d: %d global loops accepted, consistency RMSE %.3f m over %d pairs, %.2f s\n",
              kKeyframes, LoopsFrom(r, "global", true), rmse, pairs, r.time_total_s);
  EXPECT_LT(rmse, kConsistencyM);
  EXPECT_EQ(FalseLoops(r, s), 0);

  // Four placements per round cannot give graph.min_loops = 5 consistent loops: a round that
  // verified some is followed by one placing keyframes between the earlier ones, until it aligns.
  SlamConfig few = cfg;
  few.refine_rounds = 0;
  few.global_queries = 4;
  few.min_loops = 5;
  const SlamResult rf = AlignSessions(sessions, few, 2);
  ASSERT_TRUE(rf.sessions[1].aligned) << rf.sessions[1].reason;
  EXPECT_GE(LoopsFrom(rf, "global", true), few.min_loops);
  EXPECT_GT(LoopsFrom(rf, "global", false), few.global_queries);  // more than one round of placements
  EXPECT_EQ(FalseLoops(rf, s), 0);
  std::printf("global fallback, 4 placements a round: %d placements, %d loops accepted\n",
              LoopsFrom(rf, "global", false), LoopsFrom(rf, "global", true));

  cfg.global_enabled = false;
  cfg.refine_rounds = 0;
  EXPECT_FALSE(AlignSessions(sessions, cfg, 2).sessions[1].aligned);
}

// A VLP-16 pitched 10 deg down (seed 3: its two drives share about a third of their routes, and
// every Scan Context candidate is wrong): the first round of global placements verifies two, the
// second none, the third enough to align. A round without a verified placement ends the fallback
// only while none was ever verified; ending it there left this query unaligned. The placements
// depend on the central's map, so on its poses, and the poses on registration.steps (RANSAC on
// FPFH matches of a sparse, tilted scan: a small change of the map changes which placements
// verify; with the steps the query aligns after two rounds here, without the round that verified
// none). The steps are off here to keep the sequence this rule is about.
TEST(SlamRecall, GlobalFallbackGoesOnOnceAPlacementWasVerified) {
  sim::SimConfig sc = TwoSessions(kKeyframes);
  sc.seed = 3;
  sc.lidar_preset = "vlp16";
  sc.tilt_deg = 10.0;
  sim::Simulator s(sc, 2);
  const std::vector<Session> sessions = SimSessions(s);
  SlamConfig cfg;
  cfg.refine_rounds = 1;
  cfg.reg_steps = false;
  const SlamResult r = AlignSessions(sessions, cfg, 2);
  ASSERT_TRUE(r.sessions[1].aligned) << r.sessions[1].reason;
  int pairs = 0;
  const double rmse = ConsistencyRmse(r, s, &pairs);
  std::printf("tilted VLP-16, seed 3: %d global placements, %d accepted, %d loops in all, consistency RMSE %.3f m "
              "over %d pairs, %.2f s\n",
              LoopsFrom(r, "global", false), LoopsFrom(r, "global", true), r.sessions[1].loops_accepted, rmse, pairs,
              r.time_total_s);
  EXPECT_GT(LoopsFrom(r, "global", false), 2 * cfg.global_queries - 1);  // past the round that verified none
  EXPECT_LT(rmse, kConsistencyM);
  EXPECT_EQ(FalseLoops(r, s), 0);
}

// A Livox-like forward cone (config/scenarios/rosette.yaml) whose query drove the central's
// streets the other way: the two see a street only facing each other, from its two ends, where two
// keyframes' submaps share too little to verify. Registered by place clouds (the keyframes behind
// each that still see what it sees), seed 8's query aligns; on submaps it did not. Seed 9's aligns
// as the global fallback goes on through every round for such a session (its first round placed
// none right). Seeds 3 and 5's views of a far end mirror another street's near end, 120 m away
// (seed 3), or a block the next one (seed 5): on submaps, consecutive loops verified there and
// agreed, and only the checks of the placements dropped them (test_slam_placements.cpp); on place
// clouds no such loop verifies. Seed 4's query keeps its alignment.
TEST(SlamRecall, AForwardConeDrivingTheOtherWayIsRegisteredByPlaceClouds) {
  for (const int seed : {8, 9, 3, 5, 4}) {
    sim::SimConfig sc = TwoSessions(kKeyframes);
    sc.seed = seed;
    sc.lidar_pattern = "rosette";
    sim::Simulator s(sc, 2);
    const SlamResult r = AlignSessions(SimSessions(s), SlamConfig(), 2);
    int pairs = 0;
    const double consistency = r.sessions[1].aligned ? ConsistencyRmse(r, s, &pairs) : -1.0;
    std::printf("rosette, seed %d: %s %s, %d loops accepted (%d false), consistency %.3f m\n", seed,
                r.sessions[1].aligned ? "aligned" : "not aligned:", r.sessions[1].reason.c_str(),
                r.sessions[1].loops_accepted, FalseLoops(r, s), consistency);
    EXPECT_EQ(FalseLoops(r, s), 0) << "seed " << seed;
    if (seed == 3 || seed == 5) {
      EXPECT_FALSE(r.sessions[1].aligned) << "seed " << seed;
    } else {
      ASSERT_TRUE(r.sessions[1].aligned) << "seed " << seed << ": " << r.sessions[1].reason;
      // Seed 4's keyframes look the same way as the central's: its loops come from submaps. Seeds 8
      // and 9 face them: their loops are the place clouds', whose 22 m of odometry drift the
      // consistency carries (0.08-0.33 m over bench/slam_matrix.py's seeds); the test asks that
      // they are placed where they drove, within what the matrix calls a wrong place.
      EXPECT_LT(consistency, seed == 4 ? kConsistencyM : kWrongPlaceM) << "seed " << seed;
    }
  }
}

// A Livox-like forward cone in the city of identical blocks (config/params_sim_repetitive.yaml),
// seed 1: the query drove the central's street the other way, and where the central started, its
// view ahead looks like the central's own view ahead from there. On submaps, six Scan Context loops
// verified there turned 180 deg, and the placement was dropped as ambiguous. The query is not
// placed on a look-alike: no false loop, and placed where it drove if aligned at all.
TEST(SlamRecall, AForwardConeInACityOfIdenticalBlocksIsNotPlacedOnALookAlike) {
  sim::SimConfig sc = TwoSessions(kKeyframes);
  sc.seed = 1;
  sc.scenario = "repetitive";
  sc.lidar_pattern = "rosette";
  sim::Simulator s(sc, 2);
  const SlamResult r = AlignSessions(SimSessions(s), SlamConfig(), 2);
  std::printf("rosette, repetitive city, seed 1: %s %s, %d loops accepted (%d false)\n",
              r.sessions[1].aligned ? "aligned" : "not aligned:", r.sessions[1].reason.c_str(),
              r.sessions[1].loops_accepted, FalseLoops(r, s));
  EXPECT_EQ(FalseLoops(r, s), 0);
  int pairs = 0;
  if (r.sessions[1].aligned) {
    EXPECT_LT(ConsistencyRmse(r, s, &pairs), kConsistencyM);
  }
}

// A query from another city (another seed's world): no placement survives verification and
// consensus, so the query is not aligned (zero false alignments).
TEST(SlamRecall, GlobalRegistrationPlacesNothingInAnotherCity) {
  sim::Simulator home(TwoSessions(kKeyframes / 2), 2), other(TwoSessions(kKeyframes / 2, 1), 2);
  std::vector<Session> sessions = {SimSessions(home)[0], SimSessions(other)[1]};
  SlamConfig cfg;
  cfg.refine_rounds = 0;
  const SlamResult r = AlignSessions(sessions, cfg, 2);
  EXPECT_FALSE(r.sessions[1].aligned);
  EXPECT_GT(LoopsFrom(r, "global", false), 0);  // the fallback ran
  EXPECT_EQ(LoopsFrom(r, "global", true), 0);
}
