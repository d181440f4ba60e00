// LT-SLAM front end for N sessions: Scan Context descriptors (read or computed), ring-key
// retrieval per session pair, GICP verification on keyframe submaps (in parallel), the back
// end, then radius-search refinement rounds and the checks of the placements found
// (placements.cpp, with this file's look-alike candidates and registration).
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"

#include <nanoflann.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>

namespace ltm::slam {

namespace {
namespace fs = std::filesystem;

// Keyframes per session whose overlap reach is measured (OverlapReach: their median), and whose
// view round the sensor is (UsePlaceCloudsWhereOneWay): the same ones (SampledKeyframes).
constexpr int kReachSamples = 16;
// A sensor leaving more than half a turn round it without a return sees no place from both sides.
constexpr double kHalfTurnDeg = 180.0;

// Positions of up to kReachSamples keyframes spread evenly over a session of n keyframes.
std::vector<int> SampledKeyframes(int n) {
  const int m = std::min(n, kReachSamples);
  std::vector<int> k;
  for (int i = 0; i < m; ++i) k.push_back(int((long(i) * n) / m));
  return k;
}

std::string KeyframeWhere(const Session& s, const Keyframe& kf) {
  return (kf.cloud_path.empty() ? "session " + s.name : kf.cloud_path) + " (keyframe " +
         std::to_string(kf.index) + ")";
}

std::string ScdPath(const Session& s, const Keyframe& kf) {
  if (s.dir.empty()) return {};
  const std::string stem = kf.cloud_path.empty() ? std::string() : fs::path(kf.cloud_path).stem().string();
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d", kf.index);
  return (fs::path(s.dir) / "SCDs" / ((stem.empty() ? std::string(buf) : stem) + ".scd")).string();
}

// Per-keyframe downsampled clouds, made on first use and kept while they fit in
// registration.cache_mb (least recently used dropped first, made again from the scan when asked
// for again: the same points, so results do not depend on the budget). Thread-safe; two threads
// asking for the same missing keyframe may both make it.
class CloudStore {
 public:
  CloudStore(const std::vector<Session>& sessions, const SlamConfig& cfg)
      : sessions_(sessions), cfg_(cfg), budget_bytes_(std::size_t(cfg.reg_cache_mb * 1e6)) {
    for (const Session& s : sessions) slots_.emplace_back(s.keyframes.size());
    place_reach_m_.assign(sessions.size(), 0.0);
    routes_.resize(sessions.size());
  }
  std::size_t Keyframes(int s) const { return sessions_[std::size_t(s)].keyframes.size(); }
  const Keyframe& KeyframeOf(int s, int k) const { return sessions_[std::size_t(s)].keyframes[std::size_t(k)]; }
  // Loads a keyframe's raw scan; empty scans are an error.
  std::shared_ptr<const PointCloud> Raw(int s, int k) const {
    const Session& ses = sessions_[s];
    const Keyframe& kf = ses.keyframes[k];
    auto cloud = io::KeyframeCloud(kf);
    io::RequireScanPoints(*cloud, KeyframeWhere(ses, kf));
    return cloud;
  }
  // Keeps the downsampled version of an already loaded scan.
  void Put(int s, int k, const PointCloud& raw) {
    if (!Cached(s, k)) Keep(s, k, Prepare(raw));
  }
  std::shared_ptr<const PointCloud> Get(int s, int k) {
    if (auto c = Cached(s, k)) return c;
    return Keep(s, k, Prepare(*Raw(s, k)));
  }
  // From now on, session s's keyframes are registered by their place clouds (PlaceCloud), the
  // keyframes behind each within `reach_m` along the route.
  void UsePlaceClouds(int s, double reach_m) {
    place_reach_m_[std::size_t(s)] = reach_m;
    routes_[std::size_t(s)] = PathLength(sessions_[std::size_t(s)]);
  }
  bool PlaceClouds(int s) const { return place_reach_m_[std::size_t(s)] > 0.0; }
  // What a keyframe is registered by: its place cloud (PlaceClouds) or its submap (Neighbours).
  PointCloud Submap(int s, int k) { return PlaceClouds(s) ? PlaceCloud(s, k) : Neighbours(s, k); }
  // Keyframe k with its neighbours, in k's sensor frame (session-local poses), downsampled.
  PointCloud Neighbours(int s, int k) {
    const Session& ses = sessions_[s];
    const int n = static_cast<int>(ses.keyframes.size());
    const Pose T_k_session = ses.keyframes[k].T_session_sensor.inverse();
    PointCloud merged;
    for (int j = std::max(0, k - cfg_.reg_submap_neighbours);
         j <= std::min(n - 1, k + cfg_.reg_submap_neighbours); ++j) {
      const auto c = Get(s, j);
      merged.append(j == k ? *c
                           : geometry::Transform(*c, T_k_session * ses.keyframes[j].T_session_sensor));
    }
    if (cfg_.reg_submap_neighbours == 0) return merged;
    return geometry::VoxelDownsample(merged, cfg_.reg_voxel_m, 1);
  }
  // Keyframe k's place cloud: k and the keyframes behind it whose route to k is within the place
  // reach, merged in k's sensor frame (session-local poses) and downsampled. A sensor that looks
  // one way (a forward cone) sees where it stands only from the keyframes that approached it:
  // with them, k's cloud holds the street behind it too, which a drive the other way sees ahead.
  PointCloud PlaceCloud(int s, int k) {
    const Session& ses = sessions_[std::size_t(s)];
    const std::vector<double>& route = routes_[std::size_t(s)];
    const Pose T_k_session = ses.keyframes[std::size_t(k)].T_session_sensor.inverse();
    PointCloud merged;
    for (int j = k; j >= 0 && route[std::size_t(k)] - route[std::size_t(j)] <= place_reach_m_[std::size_t(s)]; --j)
      merged.append(geometry::Transform(*Get(s, j), T_k_session * ses.keyframes[std::size_t(j)].T_session_sensor));
    return geometry::VoxelDownsample(merged, cfg_.reg_voxel_m, 1);
  }

 private:
  std::shared_ptr<const PointCloud> Prepare(const PointCloud& raw) const {
    PointCloud c = geometry::RangeFilter(raw, cfg_.reg_min_range_m, cfg_.reg_max_range_m);
    // Keep only xyz / intensity: optional arrays are not needed for registration.
    c.cls.clear();
    c.session.clear();
    c.object.clear();
    return std::make_shared<const PointCloud>(geometry::VoxelDownsample(c, cfg_.reg_voxel_m, 1));
  }
  static std::size_t Bytes(const PointCloud& c) { return c.points.size() * sizeof(c.points[0]); }
  // The kept cloud, marked as used now; null when not kept.
  std::shared_ptr<const PointCloud> Cached(int s, int k) {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& slot = slots_[std::size_t(s)][std::size_t(k)];
    if (!slot.cloud) return nullptr;
    used_.splice(used_.begin(), used_, slot.use);
    return slot.cloud;
  }
  // Keeps `c` (or the copy another thread kept first) and drops the least recently used beyond
  // the budget (the newest is always kept).
  std::shared_ptr<const PointCloud> Keep(int s, int k, std::shared_ptr<const PointCloud> c) {
    const std::lock_guard<std::mutex> lock(mutex_);
    Slot& slot = slots_[std::size_t(s)][std::size_t(k)];
    if (slot.cloud) return slot.cloud;
    slot.cloud = std::move(c);
    used_.emplace_front(s, k);
    slot.use = used_.begin();
    bytes_ += Bytes(*slot.cloud);
    while (bytes_ > budget_bytes_ && used_.size() > 1) {
      const auto [ds, dk] = used_.back();
      Slot& old = slots_[std::size_t(ds)][std::size_t(dk)];
      bytes_ -= Bytes(*old.cloud);
      old.cloud.reset();
      used_.pop_back();
    }
    return slot.cloud;
  }
  struct Slot {
    std::shared_ptr<const PointCloud> cloud;
    std::list<std::pair<int, int>>::iterator use;
  };
  const std::vector<Session>& sessions_;
  const SlamConfig& cfg_;
  const std::size_t budget_bytes_;
  std::mutex mutex_;
  std::vector<std::vector<Slot>> slots_;
  std::list<std::pair<int, int>> used_;  // kept keyframes, most recently used first
  std::size_t bytes_ = 0;
  std::vector<double> place_reach_m_;        // per session: 0, or the reach of its place clouds [m]
  std::vector<std::vector<double>> routes_;  // per session with place clouds: distance along its odometry
};

// nanoflann adaptor over the ring keys of one session.
struct RingKeys {
  std::vector<Eigen::VectorXf> keys;
  std::size_t kdtree_get_point_count() const { return keys.size(); }
  float kdtree_get_pt(std::size_t i, std::size_t d) const { return keys[i][d]; }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
using RingTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, RingKeys>, RingKeys, -1,
                                        std::uint32_t>;

// A session's ring keys in a tree: the retrieval's first stage.
struct RingIndex {
  RingKeys keys;
  std::unique_ptr<RingTree> tree;
  RingIndex(RingIndex&&) = delete;  // the tree holds a reference to `keys`
  RingIndex(const std::vector<ScanContext>& sc, const SlamConfig& cfg) {
    for (const auto& d : sc) keys.keys.push_back(d.ring_key);
    tree = std::make_unique<RingTree>(static_cast<std::size_t>(cfg.sc_rings), keys,
                                      nanoflann::KDTreeSingleIndexAdaptorParams(10));
  }
};

// A loop candidate between keyframes a and b from their Scan Context match (its yaw the guess).
LoopRecord ScLoop(const NodeKey& a, const NodeKey& b, const ScMatch& m, const std::string& source) {
  LoopRecord l;
  l.a = a;
  l.b = b;
  l.source = source;
  l.sc_distance = m.distance;
  l.yaw_deg = m.yaw_rad * 180.0 / M_PI;
  l.T_a_b = Pose(Eigen::AngleAxisd(m.yaw_rad, Eigen::Vector3d::UnitZ()));
  return l;
}

// Scan Context candidates of one query keyframe j of session b against session a: the best of
// the ring-key neighbours and the others within (1 + sc_close_ratio) x its distance, at most
// sc_per_query, best first.
std::vector<LoopRecord> QueryCandidates(const std::vector<ScanContext>& sa, const RingTree& tree,
                                        const ScanContext& query, int a, int b, int j,
                                        const SlamConfig& cfg) {
  const std::size_t k = std::min<std::size_t>(cfg.sc_candidates, sa.size());
  std::vector<std::uint32_t> idx(k);
  std::vector<float> d2(k);
  const std::size_t got = tree.knnSearch(query.ring_key.data(), k, idx.data(), d2.data());
  std::vector<LoopRecord> out;
  for (std::size_t c = 0; c < got; ++c) {
    out.push_back(ScLoop({a, int(idx[c])}, {b, j}, CompareScanContexts(sa[idx[c]], query, cfg), "sc"));
  }
  std::stable_sort(out.begin(), out.end(), [](const LoopRecord& x, const LoopRecord& y) {
    return x.sc_distance < y.sc_distance;
  });
  std::size_t keep = 0;
  while (keep < out.size() && int(keep) < cfg.sc_per_query &&
         (keep == 0 || out[keep].sc_distance <= (1.0 + cfg.sc_close_ratio) * out[0].sc_distance)) {
    ++keep;
  }
  out.resize(keep);
  return out;
}

// Ranked Scan Context candidates of one session pair (a < b). The gate follows the pair's own
// descriptor statistics: a candidate must be closer than the median of the pair's best distances
// (one per query keyframe), i.e. stand out of what a typical query keyframe of b finds in a.
// Batches of sc_max_loops_per_pair are handed out lowest distance first.
struct PairCandidates {
  int a = 0, b = 0;
  double gate = 0.0;
  std::vector<LoopRecord> ranked;
  std::size_t next = 0;             // first candidate not handed out yet
  std::vector<int> taken_queries;   // query keyframes of candidates handed out
};

PairCandidates RetrievePair(const std::vector<std::vector<ScanContext>>& sc, const RingTree& tree,
                            int a, int b, const SlamConfig& cfg, int threads) {
  std::vector<std::vector<LoopRecord>> per_query(sc[b].size());
  ParallelFor(sc[b].size(), threads, [&](std::size_t j) {
    per_query[j] = QueryCandidates(sc[a], tree, sc[b][j], a, b, int(j), cfg);
  });
  PairCandidates p;
  p.a = a;
  p.b = b;
  std::vector<double> best;
  for (const auto& q : per_query) {
    if (!q.empty()) best.push_back(q.front().sc_distance);
  }
  if (best.empty()) return p;
  p.gate = UpperMedian(best);
  for (const auto& q : per_query) {
    for (const auto& l : q) {
      if (l.sc_distance < p.gate) p.ranked.push_back(l);
    }
  }
  std::stable_sort(p.ranked.begin(), p.ranked.end(), [](const LoopRecord& x, const LoopRecord& y) {
    return x.sc_distance < y.sc_distance;
  });
  return p;
}

// The next batch of a pair: up to sc_max_loops_per_pair candidates, lowest distance first, whose
// query keyframe is the same as, or at least sc_min_gap_keyframes away from, those taken before.
std::vector<LoopRecord> NextBatch(PairCandidates& p, const SlamConfig& cfg) {
  std::vector<LoopRecord> batch;
  for (; p.next < p.ranked.size() && int(batch.size()) < cfg.sc_max_loops_per_pair; ++p.next) {
    const LoopRecord& h = p.ranked[p.next];
    bool close = false;
    for (int q : p.taken_queries) {
      const int gap = std::abs(q - h.b.keyframe);
      close = close || (gap > 0 && gap < cfg.sc_min_gap_keyframes);
    }
    if (close) continue;
    p.taken_queries.push_back(h.b.keyframe);
    batch.push_back(h);
  }
  return batch;
}

// A loop verified on place clouds, registered again on the two keyframes' submaps from where the
// place clouds put them: a place cloud carries its odometry's drift over the place reach, a submap
// only over its neighbours. Where the submaps verify too (keyframes that look the same way), theirs
// is the loop; where they do not (keyframes that face each other share too little), the place
// clouds' is.
RegistrationResult Finer(const RegistrationResult& placed, const LoopRecord& l, CloudStore& store, const SlamConfig& cfg) {
  const RegistrationResult r = RegisterGicp(store.Neighbours(l.a.session, l.a.keyframe),
                                            store.Neighbours(l.b.session, l.b.keyframe), placed.T_target_source, cfg);
  return r.accepted ? r : placed;
}

// Every candidate goes through the coarse stage, radius ones too: a query that ran far without
// loops has an estimate metres off where it comes back. A verified loop's information is the
// paper's adaptive one (LoopInformation); with registration.steps, the graph adds the registration's
// own on the turn about the vertical, scaled as the loops' cycles show (LoopHeadingScale): the steps
// hold each session's heading, and the loops must then tie the sessions' headings as finely, or
// their residuals (the rotation sigma LD reads) measure the loops' own error.
void Register(std::vector<LoopRecord>& cand, CloudStore& store, const SlamConfig& cfg, int threads,
              const std::string& label) {
  Progress progress(label, cand.size());
  ParallelFor(cand.size(), threads, [&](std::size_t i) {
    LoopRecord& l = cand[i];
    RegistrationResult r = RegisterGicp(store.Submap(l.a.session, l.a.keyframe), store.Submap(l.b.session, l.b.keyframe),
                                        l.T_a_b, cfg);
    if (r.accepted && (store.PlaceClouds(l.a.session) || store.PlaceClouds(l.b.session))) r = Finer(r, l, store, cfg);
    l.T_a_b = r.T_target_source;
    l.fitness = r.fitness;
    l.overlap = r.overlap;
    l.inlier_rms_m = r.inlier_rms_m;
    l.verified = r.accepted;
    l.status = r.accepted ? "verified" : "rejected: " + r.reason;
    l.information = LoopInformation(r.fitness, r.accepted ? r.fisher : Matrix6d::Zero(), cfg);
    l.heading_variance =
        r.accepted && cfg.reg_steps ? HeadingVariance(r.fisher, Up(store.KeyframeOf(l.b.session, l.b.keyframe)), cfg) : 0.0;
    l.translation_covariance =
        r.accepted && cfg.reg_steps ? TranslationCovariance(r.fisher, cfg) : Eigen::Matrix3d::Zero().eval();
    progress.Tick();
  });
  progress.Done();
}

// Time and registrations spent by the stages after the first back-end pass.
struct StageCost {
  int registrations = 0;
  double registration_s = 0.0, optimisation_s = 0.0;
};

// A later round's candidates registered (time and count into `cost`); returns how many verified.
std::size_t RegisterRound(std::vector<LoopRecord>& cand, CloudStore& store, const SlamConfig& cfg, int threads,
                          const std::string& label, StageCost& cost) {
  const Stopwatch sw;
  Register(cand, store, cfg, threads, label);
  cost.registrations += static_cast<int>(cand.size());
  cost.registration_s += sw.Seconds();
  std::size_t ok = 0;
  for (const auto& l : cand) ok += l.verified ? 1 : 0;
  return ok;
}

// The round's candidates join `loops` and the graph is solved again (time into `cost`).
void SolveWith(const std::vector<Session>& sessions, const std::vector<LoopRecord>& cand,
               std::vector<LoopRecord>& loops, SlamResult& res, const SlamConfig& cfg, int threads, StageCost& cost) {
  loops.insert(loops.end(), cand.begin(), cand.end());
  const Stopwatch sw;
  res = OptimizeSessions(sessions, loops, cfg, threads);
  cost.optimisation_s += sw.Seconds();
}

// Retry: a query not aligned after the first pass gets the next-ranked Scan Context candidates
// of every pair linking it to an already aligned session (the central or any aligned query, so
// chains of sessions align), round after round until it aligns or the candidates run out.
void RetryUnaligned(const std::vector<Session>& sessions, std::vector<PairCandidates>& pairs,
                    std::vector<LoopRecord>& loops, SlamResult& res, CloudStore& store,
                    const SlamConfig& cfg, int threads, StageCost& cost) {
  for (int round = 0; round < cfg.sc_retry_rounds; ++round) {
    std::vector<LoopRecord> cand;
    for (PairCandidates& p : pairs) {
      if (res.sessions[p.a].aligned == res.sessions[p.b].aligned) continue;
      const std::vector<LoopRecord> batch = NextBatch(p, cfg);
      cand.insert(cand.end(), batch.begin(), batch.end());
    }
    if (cand.empty()) return;
    const std::size_t ok =
        RegisterRound(cand, store, cfg, threads, "GICP retry, round " + std::to_string(round + 1), cost);
    spdlog::info("slam: retry round {}: {} scan context candidates for unaligned sessions, {} "
                 "verified",
                 round + 1, cand.size(), ok);
    SolveWith(sessions, cand, loops, res, cfg, threads, cost);
  }
}

// Keyframe of the world poses W nearest to p within max_m (the last of equals) among those
// `eligible` accepts (all when empty), or -1.
int NearestKeyframe(const std::vector<Pose>& W, const Eigen::Vector3d& p, double max_m,
                    const std::function<bool(std::size_t)>& eligible = {}) {
  int best = -1;
  double best_d = max_m;
  for (std::size_t i = 0; i < W.size(); ++i) {
    const double d = (W[i].translation() - p).norm();
    if (d <= best_d && (!eligible || eligible(i))) best_d = d, best = int(i);
  }
  return best;
}

// A loop candidate from a world-frame estimate of keyframe j of session b next to keyframe i of
// aligned session a: T_a_b = (A_a x_ai)^-1 * T_world_bj, its yaw as the initial guess's.
LoopRecord WorldLoop(const SlamResult& res, int a, int i, int b, int j, const Pose& T_world_bj,
                     const std::string& source) {
  LoopRecord l;
  l.a = {a, i};
  l.b = {b, j};
  l.source = source;
  l.T_a_b = res.sessions[std::size_t(a)].T_world_sensor[std::size_t(i)].inverse() * T_world_bj;
  l.yaw_deg = Eigen::AngleAxisd(l.T_a_b.linear()).angle() * 180.0 / M_PI;
  return l;
}

// An aligned session's keyframe clouds in the world frame, merged.
PointCloud WorldMap(const SlamResult& res, int a, CloudStore& store) {
  PointCloud map;
  const auto& W = res.sessions[std::size_t(a)].T_world_sensor;
  for (std::size_t k = 0; k < W.size(); ++k) map.append(geometry::Transform(*store.Get(a, int(k)), W[k]));
  return map;
}

// Where in each of the equal parts of a route round r places its query: 1/2, then 1/4, 3/4, 1/8,
// ... (van der Corput), so every round tries keyframes between those of the rounds before.
double PartOffset(int round) {
  double offset = 0.0, bit = 0.5;
  for (int r = round + 1; r > 0; r >>= 1, bit *= 0.5)
    if (r & 1) offset += bit;
  return offset;
}

// Loop candidates of unaligned session b with aligned session a from global placements of
// cfg.global_queries keyframe submaps of b in a's map (`map`, its features built once for every
// round), one in each equal part of b's route at PartOffset(round): each placed keyframe is paired
// with a's keyframe nearest to where it was placed.
std::vector<LoopRecord> GlobalCandidates(const SlamResult& res, int a, int b, const GlobalMap& map, CloudStore& store,
                                         const SlamConfig& cfg, int round) {
  const Stopwatch sw;
  const auto& Wa = res.sessions[std::size_t(a)].T_world_sensor;
  if (Wa.empty()) return {};
  const int n = int(store.Keyframes(b));
  const int tries = std::min(n, cfg.global_queries);
  std::vector<LoopRecord> cand;
  for (int t = 0; t < tries; ++t) {
    const int j = std::min(n - 1, int((t + PartOffset(round)) * n / tries));
    const std::optional<Pose> T_world_j = map.Place(store.Submap(b, j));
    if (!T_world_j) continue;
    const int best = NearestKeyframe(Wa, T_world_j->translation(), std::numeric_limits<double>::infinity());
    cand.push_back(WorldLoop(res, a, best, b, j, *T_world_j, "global"));
  }
  spdlog::info("slam: global registration of {} in {}'s map ({} points): {} of {} query submaps placed in {:.2f} s",
               res.sessions[std::size_t(b)].name, res.sessions[std::size_t(a)].name, map.size(), cand.size(), tries,
               sw.Seconds());
  return cand;
}

// Fallback: a session still unaligned after the Scan Context retries is placed by global
// registration in each aligned session's map (the central first), its placements verified by
// GICP and the anchor consensus like any loop, until it aligns. A round that verified a placement
// but not enough of them to align is followed by one placing keyframes between the earlier ones
// (a route seen from a pitched sensor may match in few places). A round that verified none ends
// it only while no round has verified one: once a placement was verified the routes overlap, and
// a short overlap (a third of a route: four of twelve queries) may miss in one round and match in
// the next. A session that looks one way (place clouds) goes on through every round: its place
// cloud holds one side of a street, which a map seen from the other side matches only now and then
// (the rosette's seed 7: 12 of 12 placed 4-80 m off, with 37 keyframes of its route on the
// central's).
void GlobalFallback(const std::vector<Session>& sessions, std::vector<LoopRecord>& loops, SlamResult& res,
                    CloudStore& store, const SlamConfig& cfg, int threads, StageCost& cost) {
  if (!cfg.global_enabled) return;
  for (std::size_t b = 1; b < sessions.size(); ++b)
    for (std::size_t a = 0; a < sessions.size() && !res.sessions[b].aligned; ++a) {
      if (a == b || !res.sessions[a].aligned) continue;
      Stopwatch sw;
      const GlobalMap map(WorldMap(res, int(a), store), cfg);  // a's world map and its features
      cost.registration_s += sw.Seconds();
      const int rounds = std::max(1, int(store.Keyframes(int(b))) / std::max(1, cfg.global_queries));
      std::size_t verified_so_far = 0;
      for (int round = 0; round < rounds && !res.sessions[b].aligned; ++round) {
        sw = Stopwatch();
        std::vector<LoopRecord> cand = GlobalCandidates(res, int(a), int(b), map, store, cfg, round);
        cost.registration_s += sw.Seconds();  // the placements are registrations too
        if (a > b)  // loops are stored with a.session < b.session: the placement was of b in a's map
          for (LoopRecord& l : cand) std::swap(l.a, l.b), l.T_a_b = l.T_a_b.inverse();
        const std::size_t verified = RegisterRound(cand, store, cfg, threads, "GICP global candidates", cost);
        SolveWith(sessions, cand, loops, res, cfg, threads, cost);
        verified_so_far += verified;
        if (verified_so_far == 0 && !store.PlaceClouds(int(b))) break;
      }
    }
}

// The median over session s's sampled keyframes' clouds, as the registration reads them, of the
// widest turn without a return (WidestBlindArcDeg) [deg]; over half a turn, the sensor looks one
// way: no keyframe sees both sides of where it stands.
double MedianBlindArcDeg(const Session& session, int s, CloudStore& store) {
  std::vector<double> blind;
  for (const int k : SampledKeyframes(int(session.keyframes.size())))
    blind.push_back(WidestBlindArcDeg(*store.Get(s, k)));  // kept since OverlapReach read them
  return UpperMedian(blind);
}

// A session whose sensor looks one way (MedianBlindArcDeg) is registered by place clouds
// (CloudStore::PlaceCloud) reaching `reach_m` back, the overlap reach: the keyframes behind k that
// still see what k sees. A drive the other way sees the same street from its other end; two such
// keyframes facing each other share 0.20-0.29 of their submaps' points at the true pose (under
// registration.min_overlap), and a street turned by half a turn may share more (the rosette's seed
// 16 was placed 64 m off that way). Scan Context stays on single scans: a place cloud's descriptor
// told no true pair from false ones there.
void UsePlaceCloudsWhereOneWay(const std::vector<Session>& sessions, CloudStore& store, double reach_m) {
  for (std::size_t s = 0; s < sessions.size(); ++s) {
    const double median_deg = MedianBlindArcDeg(sessions[s], int(s), store);
    if (median_deg <= kHalfTurnDeg) continue;
    store.UsePlaceClouds(int(s), reach_m);
    spdlog::info("slam: {}'s sensor looks one way ({:.0f} deg around it without a return): its keyframes are registered "
                 "by place clouds (the keyframes behind each within {:.0f} m)", sessions[s].name, median_deg, reach_m);
  }
}

// Scan Context of every keyframe (read from SCDs/ when present and allowed, else computed from
// the scan, whose downsampled copy is then kept for registration); returns the number read.
std::size_t ComputeDescriptors(const std::vector<Session>& sessions, const SlamConfig& cfg, CloudStore& store,
                               int threads, std::vector<std::vector<ScanContext>>* sc) {
  std::size_t read_files = 0;
  std::mutex mu;
  sc->assign(sessions.size(), {});
  for (std::size_t s = 0; s < sessions.size(); ++s) {
    const Session& ses = sessions[s];
    (*sc)[s].resize(ses.keyframes.size());
    Progress progress("scan context " + ses.name, ses.keyframes.size());
    ParallelFor(ses.keyframes.size(), threads, [&](std::size_t k) {
      const std::string scd = ScdPath(ses, ses.keyframes[k]);
      if (cfg.sc_read_files && !scd.empty() && fs::exists(scd)) {
        (*sc)[s][k] = ScanContextFromMatrix(io::ReadScd(scd, cfg.sc_rings, cfg.sc_sectors));
        std::lock_guard<std::mutex> lock(mu);
        ++read_files;
      } else {
        const auto raw = store.Raw(int(s), int(k));
        (*sc)[s][k] = MakeScanContext(*raw, cfg);
        store.Put(int(s), int(k), *raw);
      }
      progress.Tick();
    });
    progress.Done();
  }
  return read_files;
}

// For every pair (a < b), each keyframe of b against the ring-key tree of a: the pair's ranked
// candidates (kept for retries) and its first batch appended to `loops`.
std::vector<PairCandidates> RetrieveCandidates(const std::vector<Session>& sessions,
                                               const std::vector<std::vector<ScanContext>>& sc, const SlamConfig& cfg,
                                               int threads, std::vector<LoopRecord>* loops) {
  std::vector<PairCandidates> pairs;
  for (std::size_t a = 0; a + 1 < sessions.size(); ++a) {
    const RingIndex index(sc[a], cfg);
    for (std::size_t b = a + 1; b < sessions.size(); ++b) {
      pairs.push_back(RetrievePair(sc, *index.tree, int(a), int(b), cfg, threads));
      const std::vector<LoopRecord> batch = NextBatch(pairs.back(), cfg);
      spdlog::info("slam: {} vs {}: {} scan context candidates below the pair's median best "
                   "distance {:.3f}, {} selected",
                   sessions[a].name, sessions[b].name, pairs.back().ranked.size(), pairs.back().gate, batch.size());
      loops->insert(loops->end(), batch.begin(), batch.end());
    }
  }
  return pairs;
}

// How far along its own route a keyframe still overlaps keyframe k's submap by
// registration.min_overlap (at the odometry's relative pose): bisection over the forward offset,
// as the overlap falls with the distance. A route that ends first gives its last distance.
double ReachFrom(const Session& ses, int s, int k, CloudStore& store, const SlamConfig& cfg) {
  const int n = static_cast<int>(ses.keyframes.size());
  const GicpCloud target(store.Submap(s, k), cfg.reg_covariance_neighbours);
  const Pose T_session_k = ses.keyframes[k].T_session_sensor;
  int lo = 0, hi = n - k;  // offset lo overlaps, offset hi does not (or lies past the route's end)
  while (hi - lo > 1) {
    const int mid = (lo + hi) / 2;
    const Pose T_k_mid = T_session_k.inverse() * ses.keyframes[k + mid].T_session_sensor;
    (OverlapRatio(target, *store.Get(s, k + mid), T_k_mid, cfg) >= cfg.reg_min_overlap ? lo : hi) = mid;
  }
  return (ses.keyframes[k + lo].T_session_sensor.translation() - T_session_k.translation()).norm();
}

// How far apart keyframes still overlap enough to pass verification (ReachFrom at kReachSamples
// keyframes spread over each session): it follows the sensor's range and field of view and the
// scene's openness, not a fixed number of metres.
struct Reach {
  double median_m = 0;    // the radius search's radius
  double farthest_m = 0;  // no registration moves a candidate farther (registration's translation gate)
};
Reach OverlapReach(const std::vector<Session>& sessions, CloudStore& store, const SlamConfig& cfg, int threads) {
  std::vector<std::pair<int, int>> samples;
  for (std::size_t s = 0; s < sessions.size(); ++s)
    for (const int k : SampledKeyframes(int(sessions[s].keyframes.size()))) samples.push_back({int(s), k});
  std::vector<double> reach(samples.size(), 0.0);
  ParallelFor(samples.size(), threads, [&](std::size_t i) {
    const auto [s, k] = samples[i];
    reach[i] = ReachFrom(sessions[std::size_t(s)], s, k, store, cfg);
  });
  Reach r;
  if (reach.empty()) return r;
  std::sort(reach.begin(), reach.end());
  r.median_m = reach[reach.size() / 2];
  r.farthest_m = reach.back();
  return r;
}

// Radius-search candidates between aligned sessions a <= b: every refine_stride-th keyframe j of b
// without an accepted loop with a, paired with a's keyframe nearest to it in the world frame
// within `radius_m` (OverlapReach). Within one session (a == b, `route` its distance along
// its odometry) only keyframes whose route from j is longer than that radius qualify: farther
// along the route than keyframes still overlap, yet within that reach in space, so the route
// turned or came back (a corner, a parallel street, a second pass) and only the odometry's drift
// links the two while their scans overlap. Each pair tried once.
void RadiusCandidates(const SlamResult& res, const std::vector<LoopRecord>& loops, std::size_t a, std::size_t b,
                      const SlamConfig& cfg, double radius_m, const std::vector<double>& route,
                      std::set<std::pair<NodeKey, NodeKey>>& tried, std::vector<LoopRecord>* cand) {
  const auto& Wa = res.sessions[a].T_world_sensor;
  const auto& Wb = res.sessions[b].T_world_sensor;
  const bool own = a == b;
  std::vector<bool> has_loop(Wb.size(), false);
  for (const auto& l : loops)
    if (l.accepted && l.a.session == int(a) && l.b.session == int(b)) {
      has_loop[l.b.keyframe] = true;
      if (own) has_loop[l.a.keyframe] = true;
    }
  int eligible = 0, added = 0;
  for (std::size_t j = 0; j < Wb.size() && added < cfg.refine_max_loops_per_pair; ++j) {
    if (has_loop[j] || eligible++ % cfg.refine_stride != 0) continue;
    const int best = own ? NearestKeyframe(Wa, Wb[j].translation(), radius_m,
                                           [&](std::size_t i) { return std::abs(route[i] - route[j]) > radius_m; })
                         : NearestKeyframe(Wa, Wb[j].translation(), radius_m);
    if (best < 0) continue;
    // Within one session the earlier keyframe is the loop's first.
    const int ka = own ? std::min(best, int(j)) : best, kb = own ? std::max(best, int(j)) : int(j);
    const LoopRecord l = WorldLoop(res, int(a), ka, int(b), kb, Wb[std::size_t(kb)], "radius");
    if (!tried.insert({l.a, l.b}).second) continue;
    cand->push_back(l);
    ++added;
  }
}

// ViewShare of every candidate between two sessions at its predicted pose (keyframe scans, slack:
// the inlier radius): whether the alignment says the two sensors looked at the same space.
void MeasureViews(std::vector<LoopRecord>& cand, CloudStore& store, const SlamConfig& cfg, int threads) {
  const double slack_m = InlierRadius(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  ParallelFor(cand.size(), threads, [&](std::size_t i) {
    LoopRecord& l = cand[i];
    if (OwnLoop(l)) return;
    l.view = ViewShare(*store.Get(l.a.session, l.a.keyframe), *store.Get(l.b.session, l.b.keyframe), l.T_a_b, slack_m);
  });
}

// Radius-search refinement: query keyframes without a loop look for keyframes of the other
// session near them in the world frame, and every aligned session's keyframes for its own where
// its route came back (RadiusCandidates with a == b), verified by GICP from the current estimate.
void Refine(const std::vector<Session>& sessions, const std::vector<std::vector<double>>& route,
            std::vector<LoopRecord>& loops, SlamResult& res, CloudStore& store, const SlamConfig& cfg, double radius_m,
            int threads, StageCost& cost) {
  const std::size_t n = sessions.size();
  std::set<std::pair<NodeKey, NodeKey>> tried;
  for (const auto& l : loops) tried.insert({l.a, l.b});
  for (int round = 0; round < cfg.refine_rounds; ++round) {
    std::vector<LoopRecord> cand;
    for (std::size_t a = 0; a + 1 < n; ++a)
      for (std::size_t b = a + 1; b < n; ++b)
        if (res.sessions[a].aligned && res.sessions[b].aligned)
          RadiusCandidates(res, loops, a, b, cfg, radius_m, route[a], tried, &cand);
    for (std::size_t a = 0; a < n; ++a)
      if (res.sessions[a].aligned && (a > 0 || cfg.central_own_loops))
        RadiusCandidates(res, loops, a, a, cfg, radius_m, route[a], tried, &cand);
    if (cand.empty()) break;
    MeasureViews(cand, store, cfg, threads);
    const std::size_t ok =
        RegisterRound(cand, store, cfg, threads, "GICP radius loops, round " + std::to_string(round + 1), cost);
    spdlog::info("slam: refinement round {}: {} radius candidates, {} verified", round + 1, cand.size(), ok);
    SolveWith(sessions, cand, loops, res, cfg, threads, cost);
    if (ok == 0) break;
  }
}

// What this file gives the placements' checks (CheckPlacements) reads: the drives, their Scan
// Contexts, their routes (distance along the odometry), the pairs' Scan Context gates (the
// look-alike candidates), the clouds (their registration), and how far apart keyframes still
// overlap.
struct Drives {
  const std::vector<Session>& sessions;
  const std::vector<std::vector<ScanContext>>& sc;
  const std::vector<std::vector<double>>& routes;
  const std::vector<PairCandidates>& pairs;
  CloudStore& store;
  Reach reach;
};

// Candidates for a look-alike of keyframe n in its own drive (`rings` its session's): of its
// sc_candidates nearest ring keys among the keyframes lying farther than any two keyframes still
// overlap (along the route and at the odometry's poses, so not a revisit), those whose Scan
// Context is as close to n's as a loop candidate of n's session's pairs must be; up to
// sc_per_query, closest first (a = {s, j}, b = n, the Scan Context's yaw as the guess).
std::vector<LoopRecord> LookAlikeCandidates(const NodeKey& n, const Drives& d, const RingIndex& rings,
                                            const SlamConfig& cfg) {
  const std::size_t s = std::size_t(n.session), k = std::size_t(n.keyframe);
  const std::vector<Keyframe>& kfs = d.sessions[s].keyframes;
  const std::vector<double>& route = d.routes[s];
  const double far_m = d.reach.farthest_m;
  std::vector<bool> near(kfs.size());
  std::size_t nears = 0;
  for (std::size_t j = 0; j < kfs.size(); ++j) {
    const double apart = (kfs[j].T_session_sensor.translation() - kfs[k].T_session_sensor.translation()).norm();
    near[j] = std::abs(route[j] - route[k]) <= far_m || apart <= far_m;
    nears += near[j];
  }
  // The nearest ring keys are mostly n's own neighbours: ask for as many more as those.
  const std::size_t want = std::min(kfs.size(), nears + std::size_t(cfg.sc_candidates));
  std::vector<std::uint32_t> idx(want);
  std::vector<float> d2(want);
  idx.resize(rings.tree->knnSearch(d.sc[s][k].ring_key.data(), want, idx.data(), d2.data()));
  double gate = 0.0;
  for (const PairCandidates& p : d.pairs)
    if (p.a == n.session || p.b == n.session) gate = std::max(gate, p.gate);
  std::vector<LoopRecord> out;
  for (const std::uint32_t j : idx) {
    if (near[j]) continue;
    const ScMatch m = CompareScanContexts(d.sc[s][j], d.sc[s][k], cfg);
    if (m.distance < gate) out.push_back(ScLoop({n.session, int(j)}, n, m, "look-alike"));
  }
  std::sort(out.begin(), out.end(), [](const LoopRecord& x, const LoopRecord& y) { return x.sc_distance < y.sc_distance; });
  if (int(out.size()) > cfg.sc_per_query) out.resize(std::size_t(cfg.sc_per_query));
  return out;
}

// The placements' checks (DroppedPlacements, placements.cpp) with this alignment's look-alike
// candidates (each session's ring-key tree built once, when first asked for) and their
// registration; the graph solved again without the dropped sessions' loops.
void CheckPlacements(const Drives& d, std::vector<LoopRecord>& loops, SlamResult& res, const SlamConfig& cfg, int threads,
                     StageCost& cost) {
  std::map<int, RingIndex> built;
  const auto rings = [&](int session) -> const RingIndex& {
    auto it = built.find(session);
    if (it == built.end()) it = built.try_emplace(session, d.sc[std::size_t(session)], cfg).first;
    return it->second;
  };
  const PlacementEvidence evidence{
      d.routes, d.reach.median_m, [&](const NodeKey& n) { return LookAlikeCandidates(n, d, rings(n.session), cfg); },
      [&](std::vector<LoopRecord>& cand) { RegisterRound(cand, d.store, cfg, threads, "GICP look-alike places", cost); }};
  const auto dropped = DroppedPlacements(evidence, loops, res, cfg);
  if (dropped.empty()) return;
  SolveWith(d.sessions, {}, loops, res, cfg, threads, cost);
  for (const auto& [s, why] : dropped) {
    spdlog::warn("slam: {} not aligned: {}", res.sessions[s].name, why);
    if (!res.sessions[s].aligned) res.sessions[s].reason = why;
  }
}

// Per keyframe position k of a session, the variance of the turn about the vertical that its
// odometry edge k -> k + 1 states (TurnVariance; the config's sigmas where the edge is missing).
std::vector<double> StatedOdometry(const Session& s, const SlamConfig& cfg) {
  const std::size_t n = s.keyframes.size() - 1;
  std::vector<double> var(n, TurnVariance(Edge{}, Eigen::Vector3d::UnitZ(), cfg, false));
  ForEachStep(s, s.odometry,
              [&](std::size_t a, const Edge& e) { var[a] = TurnVariance(e, Up(s.keyframes[a + 1]), cfg, false); });
  return var;
}
}  // namespace

StepHeading MeasureStepHeading(const std::vector<std::optional<RegistrationResult>>& steps,
                               const std::vector<std::optional<RegistrationResult>>& skips, const Session& session,
                               const SlamConfig& cfg) {
  const std::vector<Keyframe>& kfs = session.keyframes;
  StepHeading h;
  h.variance.assign(steps.size(), 0.0);
  for (std::size_t k = 0; k < steps.size(); ++k)
    if (steps[k]) h.variance[k] = HeadingVariance(steps[k]->fisher, Up(kfs[k + 1]), cfg);
  std::vector<double> closure, var;
  for (std::size_t k = 0; k + 1 < steps.size(); ++k) {
    if (!steps[k] || !steps[k + 1] || !skips[k]) continue;
    const Eigen::Vector3d up = Up(kfs[k + 2]);
    closure.push_back(TurnAbout(skips[k]->T_target_source, steps[k]->T_target_source * steps[k + 1]->T_target_source, up));
    var.push_back(h.variance[k] + h.variance[k + 1] + HeadingVariance(skips[k]->fisher, up, cfg));
  }
  h.closures = closure.size();
  if (h.closures < 2) return h;
  double sum = 0.0, sum_sq = 0.0;
  for (double c : closure) sum += c;
  h.bias = sum / double(h.closures);
  std::vector<double> ratio;
  for (std::size_t i = 0; i < h.closures; ++i) {
    const double c = closure[i] - h.bias;
    sum_sq += c * c, ratio.push_back(c * c / var[i]);
  }
  h.step_var = sum_sq / double(h.closures - 1) / 3.0;
  h.scale = VarianceScale(std::move(ratio));
  const std::vector<double> stated = StatedOdometry(session, cfg);
  double odom_sum = 0.0, odom_sq = 0.0, stated_sum = 0.0;
  for (std::size_t k = 0; k < steps.size(); ++k) {
    if (!steps[k]) continue;
    const Pose odometry = kfs[k].T_session_sensor.inverse() * kfs[k + 1].T_session_sensor;
    const double d = TurnAbout(odometry, steps[k]->T_target_source, Up(kfs[k + 1])) - h.bias;
    odom_sum += d, odom_sq += d * d, stated_sum += stated[k], ++h.compared;
  }
  const double n = double(h.compared);
  h.odom_var = std::max(0.0, odom_sq / n - h.step_var);
  h.odom_mean = odom_sum / n;
  h.stated_var = stated_sum / n;
  h.finer = h.step_var < h.odom_var;
  h.explained = SquaresWithin(odom_sq, h.compared, h.step_var + h.stated_var);
  return h;
}

namespace {
// The horizontal components of a translation error d in keyframe frame `up`, whitened by its
// covariance C (3 x 3, that frame): one chi-square of one degree each where C states d's spread.
Eigen::Vector2d Whitened(const Eigen::Vector3d& d, const Eigen::Matrix3d& C, const Eigen::Vector3d& up) {
  const Eigen::Matrix<double, 3, 2> H = Horizontal(up);
  const Eigen::Matrix2d C2 = H.transpose() * C * H;
  return Eigen::LLT<Eigen::Matrix2d>(C2).matrixL().solve(H.transpose() * d);
}
// A registration's translation covariance (source frame) in its target's frame.
Eigen::Matrix3d InTarget(const RegistrationResult& r, const Eigen::Matrix3d& C) {
  const Eigen::Matrix3d R = r.T_target_source.linear();
  return R * C * R.transpose();
}
// Per-axis variance from the squares of errors of one degree each: their median over a
// chi-square's (a few gross errors do not move it).
double MedianVariance(std::vector<double> squares) {
  return squares.empty() ? 0.0 : UpperMedian(squares) / kChiSquare1Median;
}
}  // namespace

StepTranslation MeasureStepTranslation(const std::vector<std::optional<RegistrationResult>>& steps,
                                       const std::vector<std::optional<RegistrationResult>>& skips,
                                       const Session& session, const SlamConfig& cfg) {
  const std::vector<Keyframe>& kfs = session.keyframes;
  StepTranslation t;
  t.covariance.assign(steps.size(), Eigen::Matrix3d::Zero());
  for (std::size_t k = 0; k < steps.size(); ++k)
    if (steps[k]) t.covariance[k] = TranslationCovariance(steps[k]->fisher, cfg);
  std::vector<double> squares, ratio;
  for (std::size_t k = 0; k + 1 < steps.size(); ++k) {
    if (!steps[k] || !steps[k + 1] || !skips[k]) continue;
    const RegistrationResult &a = *steps[k], &b = *steps[k + 1], &c = *skips[k];
    const Eigen::Vector3d d = c.T_target_source.translation() - (a.T_target_source * b.T_target_source).translation();
    const Eigen::Matrix3d Ra = a.T_target_source.linear();
    const Eigen::Matrix3d C = InTarget(c, TranslationCovariance(c.fisher, cfg)) + InTarget(a, t.covariance[k]) +
                              Ra * InTarget(b, t.covariance[k + 1]) * Ra.transpose();
    const Eigen::Vector3d up = Up(kfs[k]);
    const Eigen::Vector2d h = Horizontal(up).transpose() * d, w = Whitened(d, C, up);
    for (int i = 0; i < 2; ++i) squares.push_back(h[i] * h[i]), ratio.push_back(w[i] * w[i]);
    t.bias -= Horizontal(up) * h;
    ++t.closures;
  }
  if (t.closures < 2) return t;
  t.bias /= double(t.closures);
  t.step_var = MedianVariance(squares) / 3.0;
  t.scale = VarianceScale(std::move(ratio));
  std::vector<double> diff;
  double sum_sq = 0.0, stated_sum = 0.0;
  ForEachStep(session, session.odometry, [&](std::size_t k, const Edge& e) {
    if (k >= steps.size() || !steps[k]) return;
    const Pose odometry = kfs[k].T_session_sensor.inverse() * kfs[k + 1].T_session_sensor;
    const Eigen::Vector2d h =
        Horizontal(Up(kfs[k])).transpose() * (odometry.translation() - steps[k]->T_target_source.translation() + t.bias);
    for (int i = 0; i < 2; ++i) diff.push_back(h[i] * h[i]), sum_sq += h[i] * h[i];
    stated_sum += StatedHorizontalVariance(e, Up(kfs[k + 1]), cfg), ++t.compared;
  });
  if (t.compared == 0) return t;
  t.odom_var = std::max(0.0, MedianVariance(diff) - t.step_var);
  t.stated_var = stated_sum / double(t.compared);
  t.finer = t.step_var < t.odom_var;
  t.explained = SquaresWithin(sum_sq, 2 * t.compared, t.step_var + t.stated_var);
  return t;
}

// Keyframes whose GICP clouds (kd-tree and the plane of every point: GicpCloud::PrepareAllPlanes)
// are held at once while their steps are registered: each cloud takes part in up to four
// registrations (two steps, two skips), and its planes are made once for all of them.
constexpr std::size_t kPreparedSteps = 32;

// The steps and skips from keyframes [w, we) of the block starting at b (off: its scans off the
// ground), on clouds prepared once for the keyframes w .. we + 1.
void RegisterStepsFrom(const std::vector<Keyframe>& kfs, const std::vector<PointCloud>& off, std::size_t b,
                       std::size_t w, std::size_t we, const SlamConfig& cfg, int threads,
                       std::vector<std::optional<RegistrationResult>>* steps,
                       std::vector<std::optional<RegistrationResult>>* skips) {
  const std::size_t last = std::min(kfs.size() - 1, we + 1);
  std::vector<std::unique_ptr<GicpCloud>> prepared(last - w + 1);
  ParallelFor(prepared.size(), threads, [&](std::size_t i) {
    const PointCloud& c = off[w + i - b];
    if (!Registrable(c.size(), cfg)) return;  // its registrations stay empty, as RegisterGicp's "too few points"
    prepared[i] = std::make_unique<GicpCloud>(c, cfg.reg_covariance_neighbours);
    prepared[i]->PrepareAllPlanes();
  });
  const auto registered = [&](std::size_t from, std::size_t to) -> std::optional<RegistrationResult> {
    if (!prepared[from - w] || !prepared[to - w]) return std::nullopt;
    const Pose guess = kfs[from].T_session_sensor.inverse() * kfs[to].T_session_sensor;
    RegistrationResult r = RegisterGicp(*prepared[from - w], *prepared[to - w], guess, cfg);
    if (!r.accepted) return std::nullopt;
    return r;
  };
  ParallelFor(2 * (we - w), threads, [&](std::size_t i) {
    const std::size_t k = w + i / 2;
    if (i % 2 == 0) (*steps)[k] = registered(k, k + 1);
    else if (k + 2 < kfs.size()) (*skips)[k] = registered(k, k + 2);
  });
}

// Keyframe k + 1 registered onto k (*steps, k < n) and k + 2 onto k (*skips, k < n - 1) of a
// session's keyframes `kfs`, scans from `scan` (downsampled, sensor frame), from the odometry's
// relative pose, off the ground (OffTheGround: the steps measure the heading and the horizontal
// translation; no ring of the ground pulls them toward standing still);
// a registration not accepted is left empty. In blocks of keyframes, each scan's ground found once
// per block; within a block, windows of kPreparedSteps keyframes on clouds prepared once
// (RegisterStepsFrom).
void RegisterSteps(const std::vector<Keyframe>& kfs, const std::function<std::shared_ptr<const PointCloud>(std::size_t)>& scan,
                   const SlamConfig& cfg, int threads, std::vector<std::optional<RegistrationResult>>* steps,
                   std::vector<std::optional<RegistrationResult>>* skips) {
  constexpr std::size_t kBlock = 256;  // keyframes whose scans off the ground are held at once
  const std::size_t n = kfs.size() - 1;
  for (std::size_t b = 0; b < n; b += kBlock) {
    const std::size_t e = std::min(n, b + kBlock), last = std::min(kfs.size() - 1, e + 1);
    std::vector<PointCloud> off(last - b + 1);  // off the ground
    ParallelFor(off.size(), threads, [&](std::size_t i) { off[i] = OffTheGround(*scan(b + i), Up(kfs[b + i]), cfg); });
    for (std::size_t w = b; w < e; w += kPreparedSteps)
      RegisterStepsFrom(kfs, off, b, w, std::min(e, w + kPreparedSteps), cfg, threads, steps, skips);
  }
}

namespace {
const char* Verdict(bool admitted, bool finer) {
  return admitted ? "registered"
         : !finer ? "not finer than the odometry, left out"
                  : "steps and odometry disagree beyond both their variances, left out";
}
// What a session's steps say of their heading and horizontal translation, and whether they join.
void LogSteps(const std::string& name, const std::vector<std::optional<RegistrationResult>>& steps,
              const StepHeading& h, const StepTranslation& tr, bool heading, bool translation) {
  constexpr double kRadToDeg = 180.0 / M_PI;
  spdlog::info("slam: session {}: {} of {} keyframe steps verified; heading sigma {:.4f} deg a step, bias {:.4f} "
               "(two-step closures: {}), the odometry's {:.4f} deg (mean {:.4f}; it states {:.4f}): {}",
               name, std::count_if(steps.begin(), steps.end(), [](const auto& r) { return bool(r); }), steps.size(),
               std::sqrt(h.step_var) * kRadToDeg, h.bias * kRadToDeg, h.closures, std::sqrt(h.odom_var) * kRadToDeg,
               h.odom_mean * kRadToDeg, std::sqrt(h.stated_var) * kRadToDeg, Verdict(heading, h.finer));
  spdlog::info("slam: session {}: horizontal translation sigma {:.4f} m a step, bias ({:.4f}, {:.4f}) m (closures: {}; "
               "{:.2f} x the Fisher information's), the odometry's {:.4f} m (it states {:.4f}): {}",
               name, std::sqrt(tr.step_var), tr.bias.x(), tr.bias.y(), tr.closures, tr.scale, std::sqrt(tr.odom_var),
               std::sqrt(tr.stated_var), heading ? Verdict(translation, tr.finer) : "left out with the heading");
}
// Verified step k (keyframe k + 1 onto k) as a registered edge: its heading, the closures' bias
// turned back, with the information HeadingInformation gives it, scaled as the closures show; with
// `tr`, its horizontal translation too, the closures' mean shift turned back, with the Fisher
// information's covariance (never scaled down: what a step and a two-step share in proportion to
// their length cancels in a closure).
Edge RegisteredEdge(const std::vector<Keyframe>& kfs, std::size_t k, const RegistrationResult& step,
                    const StepHeading& h, const StepTranslation* tr, const SlamConfig& cfg) {
  const Eigen::Vector3d up = Up(kfs[k + 1]);
  Edge e;
  e.from = kfs[k].index;
  e.to = kfs[k + 1].index;
  e.T_from_to = step.T_target_source * Pose(Eigen::AngleAxisd(-h.bias, up));
  e.information = HeadingInformation(h.variance[k] * h.scale, up, cfg);
  if (tr) {
    e.T_from_to.pretranslate(-tr->bias);
    const Eigen::Matrix<double, 3, 2> H = Horizontal(up);
    e.information += HorizontalInformation(H.transpose() * tr->covariance[k] * H * std::max(1.0, tr->scale), up);
  }
  e.has_information = true;
  return e;
}
}  // namespace

// The odometry refined by registration: each keyframe k + 1 of a session registered onto keyframe
// k, single scans off the ground from the odometry's relative pose, fine stage only (the odometry
// is centimetres off, not the metres a loop's guess may be; RegisterSteps). Where the steps are
// admitted (MeasureStepHeading: finer in heading than the odometry, and their turns against it
// within both's variances, the odometry's as it states), each verified step, the closures' bias
// turned back, joins the session's graph beside its odometry edge (Session::registered) with the
// registration's information on the heading (HeadingInformation), its variance scaled as the
// closures show; where the steps' horizontal translation passes the same two tests
// (MeasureStepTranslation), that joins the edge too (RegisteredEdge); height, roll and pitch stay
// the odometry's. A scanner whose consecutive scans share little (a forward cone that samples
// other places each sweep) gives steps no finer than the odometry, or steps whose shared errors
// the closures cancel and the odometry shows: they are left out. Sessions whose poses
// are the world (the add's reference: central_own_loops off) are left as they are. Returns the
// sessions with their steps; the registrations tried are added to *tried.
std::vector<Session> WithRegisteredSteps(const std::vector<Session>& sessions, CloudStore& store, const SlamConfig& cfg,
                                         int threads, int* tried) {
  std::vector<Session> out = sessions;
  if (!cfg.reg_steps) return out;
  SlamConfig fine = cfg;
  fine.reg_coarse_correspondence_m = 0.0;
  for (std::size_t s = 0; s < out.size(); ++s) {
    const auto& kfs = out[s].keyframes;
    if (kfs.size() < 2 || (s == 0 && !cfg.central_own_loops)) continue;
    const std::size_t n = kfs.size() - 1;
    std::vector<std::optional<RegistrationResult>> steps(n), skips(n);
    *tried += int(n + (n - 1));
    RegisterSteps(kfs, [&](std::size_t k) { return store.Get(int(s), int(k)); }, fine, threads, &steps, &skips);
    const StepHeading h = MeasureStepHeading(steps, skips, out[s], cfg);
    const StepTranslation tr = MeasureStepTranslation(steps, skips, out[s], cfg);
    const bool heading = h.finer && h.explained, translation = heading && tr.finer && tr.explained;
    LogSteps(out[s].name, steps, h, tr, heading, translation);
    for (std::size_t k = 0; k < n && heading; ++k)
      if (steps[k]) out[s].registered.push_back(RegisteredEdge(kfs, k, *steps[k], h, translation ? &tr : nullptr, cfg));
  }
  return out;
}

SlamResult AlignSessions(const std::vector<Session>& sessions, const SlamConfig& cfg_in, int threads) {
  ValidateConfig(cfg_in, "slam config");
  ValidateSessionGraphs(sessions);
  const Stopwatch total;
  CloudStore store(sessions, cfg_in);
  Stopwatch sw;
  std::vector<std::vector<ScanContext>> sc;
  const std::size_t read_files = ComputeDescriptors(sessions, cfg_in, store, threads, &sc);
  const double t_desc = sw.Seconds();
  spdlog::info("slam: scan context for {} sessions ({} read from SCDs) in {:.2f} s", sessions.size(), read_files,
               t_desc);
  const Reach reach = OverlapReach(sessions, store, cfg_in, threads);
  UsePlaceCloudsWhereOneWay(sessions, store, reach.median_m);
  spdlog::info("slam: keyframes overlap by {} up to {:.1f} m apart (median), {:.1f} m at most: the radius search's "
               "radius and the registrations' translation gate", cfg_in.reg_min_overlap, reach.median_m, reach.farthest_m);
  SlamConfig cfg = cfg_in;
  cfg.reg_max_translation_m = reach.farthest_m;
  sw = Stopwatch();
  int steps_tried = 0;
  const std::vector<Session> refined = WithRegisteredSteps(sessions, store, cfg, threads, &steps_tried);
  const double t_steps = sw.Seconds();
  sw = Stopwatch();
  std::vector<LoopRecord> loops;
  std::vector<PairCandidates> pairs = RetrieveCandidates(sessions, sc, cfg, threads, &loops);
  const double t_retr = sw.Seconds();
  StageCost cost;  // registration of the Scan Context candidates, back end, retries, refinement
  sw = Stopwatch();
  Register(loops, store, cfg, threads, "GICP scan context loops");
  cost.registrations = static_cast<int>(loops.size()) + steps_tried;
  cost.registration_s = sw.Seconds() + t_steps;
  sw = Stopwatch();
  SlamResult res = OptimizeSessions(refined, loops, cfg, threads);
  cost.optimisation_s = sw.Seconds();
  RetryUnaligned(refined, pairs, loops, res, store, cfg, threads, cost);
  GlobalFallback(refined, loops, res, store, cfg, threads, cost);
  std::vector<std::vector<double>> routes;  // each session's distance along its odometry
  for (const Session& s : sessions) routes.push_back(PathLength(s));
  Refine(refined, routes, loops, res, store, cfg, reach.median_m, threads, cost);
  CheckPlacements(Drives{refined, sc, routes, pairs, store, reach}, loops, res, cfg, threads, cost);
  for (std::size_t s = 0; s < refined.size(); ++s) res.sessions[s].registered = refined[s].registered;
  res.refine_radius_m = reach.median_m;
  res.max_translation_m = reach.farthest_m;
  res.time_descriptors_s = t_desc;
  res.time_retrieval_s = t_retr;
  res.time_registration_s = cost.registration_s;
  res.time_optimisation_s = cost.optimisation_s;
  res.time_total_s = total.Seconds();
  res.registrations = cost.registrations;
  if (res.heading_cycles > 0)
    spdlog::info("slam: the loops' heading, measured on {} cycles of two loops: {:.1f} x the variance their "
                 "registrations' Fisher information gives", res.heading_cycles, res.loop_heading_scale);
  if (res.translation_cycles > 0)
    spdlog::info("slam: the loops' horizontal translation, measured on {} cycles of two loops: {:.2f} x the variance "
                 "their registrations' Fisher information gives", res.translation_cycles, res.loop_translation_scale);
  spdlog::info("slam: time per phase: descriptors {:.2f} s, retrieval {:.2f} s, registration {:.2f} s "
               "({} GICP), optimisation {:.2f} s, total {:.2f} s",
               t_desc, t_retr, cost.registration_s, cost.registrations, cost.optimisation_s, res.time_total_s);
  return res;
}

namespace {

// Why no loop at given poses verified: the drives do not meet, the sensor looks one way (single
// scans facing each other share too little; place clouds, as LT-SLAM registers them, carry their
// odometry's drift: on the rosette 0.2-0.5 deg of residual at true poses, above LD's prior), or
// the pose files may not share one world frame.
const char* NoGivenLoopReason(bool tried, bool one_way) {
  if (!tried) return ": the drives do not meet";
  if (one_way) return ": its sensor looks one way, and single scans facing each other share too little to verify";
  return ": do the pose files share one world frame?";
}

// The loops registered at given poses (`given`: each loop's given relative pose) scored against
// them: a verified loop is accepted with its residual; each later session's rotation_sigma_deg is
// the RMS rotation residual of its loops (none verified: 0, with a warning saying whether keyframe
// pairs within `radius_m` were tried at all, and whether the session's sensor looks one way).
void ScoreGivenLoops(std::vector<LoopRecord>& loops, const std::vector<Pose>& given, double radius_m,
                     const std::vector<bool>& one_way, SlamResult& res) {
  std::vector<double> sum_sq(res.sessions.size(), 0.0);
  std::vector<std::size_t> n(res.sessions.size(), 0), tried_pairs(res.sessions.size(), 0);
  for (std::size_t i = 0; i < loops.size(); ++i) {
    LoopRecord& l = loops[i];
    ++tried_pairs[std::size_t(l.b.session)];
    if (!l.verified) continue;
    l.accepted = true;
    l.status = "accepted: measures the given poses";
    const Pose E = l.T_a_b.inverse() * given[i];  // registration against the given relative pose
    l.residual_t_m = E.translation().norm();
    l.residual_r_deg = AngleDeg(E.linear());
    for (int s : {l.a.session, l.b.session}) {
      ++res.sessions[std::size_t(s)].loops_verified;
      ++res.sessions[std::size_t(s)].loops_accepted;
      ++res.sessions[std::size_t(s)].radius_loops;
    }
    sum_sq[std::size_t(l.b.session)] += l.residual_r_deg * l.residual_r_deg;
    ++n[std::size_t(l.b.session)];
  }
  for (std::size_t s = 1; s < n.size(); ++s) {
    SessionAlignment& a = res.sessions[s];
    if (n[s]) {
      a.rotation_sigma_deg = std::sqrt(sum_sq[s] / double(n[s]));
      spdlog::info("slam: {}: {} loops at the given poses verified, rotation residual {:.3f} deg (RMS)", a.name, n[s],
                   a.rotation_sigma_deg);
    } else {
      spdlog::warn("slam: {}: no loop at the given poses verified ({} keyframe pairs within {:.1f} m tried{}); LD "
                   "keeps its rotation prior (pose_sigma_deg)",
                   a.name, tried_pairs[s], radius_m, NoGivenLoopReason(tried_pairs[s] > 0, one_way[s]));
    }
  }
}

}  // namespace

void MeasureGivenPoses(const std::vector<Session>& sessions, SlamResult& res, const SlamConfig& cfg_in, int threads) {
  ValidateConfig(cfg_in, "slam config");
  const Stopwatch total;
  CloudStore store(sessions, cfg_in);
  const Reach reach = OverlapReach(sessions, store, cfg_in, threads);
  std::vector<bool> one_way;
  for (std::size_t s = 0; s < sessions.size(); ++s)
    one_way.push_back(MedianBlindArcDeg(sessions[s], int(s), store) > kHalfTurnDeg);
  SlamConfig cfg = cfg_in;
  cfg.reg_max_translation_m = reach.farthest_m;
  std::set<std::pair<NodeKey, NodeKey>> tried;
  std::vector<LoopRecord> loops;
  for (std::size_t a = 0; a + 1 < sessions.size(); ++a)
    for (std::size_t b = a + 1; b < sessions.size(); ++b)
      RadiusCandidates(res, {}, a, b, cfg, reach.median_m, {}, tried, &loops);
  std::vector<Pose> given;
  for (const LoopRecord& l : loops) given.push_back(l.T_a_b);
  const Stopwatch sw;
  Register(loops, store, cfg, threads, "GICP loops at the given poses");
  res.time_registration_s = sw.Seconds();
  ScoreGivenLoops(loops, given, reach.median_m, one_way, res);
  res.loops = std::move(loops);
  res.registrations = int(res.loops.size());
  res.refine_radius_m = reach.median_m;
  res.max_translation_m = reach.farthest_m;
  res.given_poses = true;
  res.time_total_s = total.Seconds();
}

}  // namespace ltm::slam
