// LT-SLAM front end for N sessions: Scan Context descriptors (read or computed), ring-key
// retrieval per session pair, GICP verification on keyframe submaps (in parallel), the back
// end, then radius-search refinement rounds.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/slam.hpp"

#include <nanoflann.hpp>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <mutex>
#include <set>

namespace ltm::slam {

namespace {
namespace fs = std::filesystem;

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

// Per-keyframe downsampled clouds, loaded once on first use (thread-safe).
class CloudStore {
 public:
  CloudStore(const std::vector<Session>& sessions, const SlamConfig& cfg)
      : sessions_(sessions), cfg_(cfg) {
    for (const Session& s : sessions) {
      clouds_.emplace_back(s.keyframes.size());
      once_.emplace_back(new std::once_flag[s.keyframes.size()]);
    }
  }
  // Loads a keyframe's raw scan; empty scans are an error.
  std::shared_ptr<const PointCloud> Raw(int s, int k) const {
    const Session& ses = sessions_[s];
    const Keyframe& kf = ses.keyframes[k];
    auto cloud = io::KeyframeCloud(kf);
    io::RequireScanPoints(*cloud, KeyframeWhere(ses, kf));
    return cloud;
  }
  // Stores the downsampled version of an already loaded scan.
  void Put(int s, int k, const PointCloud& raw) {
    std::call_once(once_[s][k], [&] { clouds_[s][k] = Prepare(raw); });
  }
  std::shared_ptr<const PointCloud> Get(int s, int k) {
    std::call_once(once_[s][k], [&] { clouds_[s][k] = Prepare(*Raw(s, k)); });
    return clouds_[s][k];
  }
  // Keyframe k with its neighbours, in k's sensor frame (session-local poses), downsampled.
  PointCloud Submap(int s, int k) {
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

 private:
  std::shared_ptr<const PointCloud> Prepare(const PointCloud& raw) const {
    PointCloud c = geometry::RangeFilter(raw, cfg_.reg_min_range_m, cfg_.reg_max_range_m);
    // Keep only xyz / intensity: optional arrays are not needed for registration.
    c.cls.clear();
    c.session.clear();
    c.object.clear();
    return std::make_shared<const PointCloud>(geometry::VoxelDownsample(c, cfg_.reg_voxel_m, 1));
  }
  const std::vector<Session>& sessions_;
  const SlamConfig& cfg_;
  std::vector<std::vector<std::shared_ptr<const PointCloud>>> clouds_;
  std::vector<std::unique_ptr<std::once_flag[]>> once_;
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

template <class F>
void ParallelFor(tbb::task_arena& arena, std::size_t n, F&& f) {
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
                      });
  });
}

void Register(std::vector<LoopRecord>& cand, CloudStore& store, const SlamConfig& cfg_in,
              tbb::task_arena& arena, const std::string& label, bool coarse) {
  SlamConfig cfg = cfg_in;
  // Radius candidates start from the current estimate: the coarse stage is not needed.
  if (!coarse) cfg.reg_coarse_correspondence_m = 0.0;
  Progress progress(label, cand.size());
  ParallelFor(arena, cand.size(), [&](std::size_t i) {
    LoopRecord& l = cand[i];
    const PointCloud target = store.Submap(l.a.session, l.a.keyframe);
    const PointCloud source = store.Submap(l.b.session, l.b.keyframe);
    const RegistrationResult r = RegisterGicp(target, source, l.T_a_b, cfg);
    l.T_a_b = r.T_target_source;
    l.fitness = r.fitness;
    l.verified = r.accepted;
    l.status = r.accepted ? "verified" : "rejected: " + r.reason;
    l.information = LoopInformation(r.fitness, cfg);
    progress.Tick();
  });
  progress.Done();
}

}  // namespace

SlamResult AlignSessions(const std::vector<Session>& sessions, const SlamConfig& cfg,
                         int threads) {
  ValidateConfig(cfg, "slam config");
  ValidateSessionGraphs(sessions);
  const Stopwatch total;
  const std::size_t n = sessions.size();
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  CloudStore store(sessions, cfg);

  // ---- descriptors
  Stopwatch sw;
  std::vector<std::vector<ScanContext>> sc(n);
  std::size_t read_files = 0;
  std::mutex mu;
  for (std::size_t s = 0; s < n; ++s) {
    const Session& ses = sessions[s];
    sc[s].resize(ses.keyframes.size());
    Progress progress("scan context " + ses.name, ses.keyframes.size());
    ParallelFor(arena, ses.keyframes.size(), [&](std::size_t k) {
      const std::string scd = ScdPath(ses, ses.keyframes[k]);
      if (cfg.sc_read_files && !scd.empty() && fs::exists(scd)) {
        sc[s][k] = ScanContextFromMatrix(io::ReadScd(scd, cfg.sc_rings, cfg.sc_sectors));
        std::lock_guard<std::mutex> lock(mu);
        ++read_files;
      } else {
        const auto raw = store.Raw(int(s), int(k));
        sc[s][k] = MakeScanContext(*raw, cfg);
        store.Put(int(s), int(k), *raw);  // the scan is loaded now: keep its downsampled copy
      }
      progress.Tick();
    });
    progress.Done();
  }
  const double t_desc = sw.Seconds();
  spdlog::info("slam: scan context for {} sessions ({} read from SCDs) in {:.2f} s", n, read_files,
               t_desc);

  // ---- retrieval: for every pair (a < b), each keyframe of b against the ring-key tree of a
  sw = Stopwatch();
  std::vector<LoopRecord> loops;
  std::vector<std::vector<LoopRecord>> pair_candidates;
  for (std::size_t a = 0; a + 1 < n; ++a) {
    RingKeys keys;
    for (const auto& d : sc[a]) keys.keys.push_back(d.ring_key);
    RingTree tree(static_cast<std::size_t>(cfg.sc_rings), keys,
                  nanoflann::KDTreeSingleIndexAdaptorParams(10));
    for (std::size_t b = a + 1; b < n; ++b) {
      std::vector<LoopRecord> cand(sc[b].size());
      std::vector<bool> found(sc[b].size(), false);
      ParallelFor(arena, sc[b].size(), [&](std::size_t j) {
        const std::size_t k = std::min<std::size_t>(cfg.sc_candidates, keys.keys.size());
        std::vector<std::uint32_t> idx(k);
        std::vector<float> d2(k);
        const std::size_t got = tree.knnSearch(sc[b][j].ring_key.data(), k, idx.data(), d2.data());
        ScMatch best;
        int best_i = -1;
        for (std::size_t c = 0; c < got; ++c) {
          const ScMatch m = CompareScanContexts(sc[a][idx[c]], sc[b][j], cfg);
          if (best_i < 0 || m.distance < best.distance) {
            best = m;
            best_i = static_cast<int>(idx[c]);
          }
        }
        if (best_i >= 0 && best.distance < cfg.sc_dist_threshold) {
          LoopRecord& l = cand[j];
          l.a = {int(a), best_i};
          l.b = {int(b), int(j)};
          l.source = "sc";
          l.sc_distance = best.distance;
          l.yaw_deg = best.yaw_rad * 180.0 / M_PI;
          l.T_a_b = Pose(Eigen::AngleAxisd(best.yaw_rad, Eigen::Vector3d::UnitZ()));
          found[j] = true;
        }
      });
      std::vector<LoopRecord> hits;
      for (std::size_t j = 0; j < cand.size(); ++j) {
        if (found[j]) hits.push_back(cand[j]);
      }
      // Best distances first, spread along the query trajectory, capped per pair.
      std::stable_sort(hits.begin(), hits.end(), [](const LoopRecord& x, const LoopRecord& y) {
        return x.sc_distance < y.sc_distance;
      });
      std::vector<LoopRecord> chosen;
      for (const auto& h : hits) {
        if (int(chosen.size()) >= cfg.sc_max_loops_per_pair) break;
        bool close = false;
        for (const auto& c : chosen) {
          close = close || std::abs(c.b.keyframe - h.b.keyframe) < cfg.sc_min_gap_keyframes;
        }
        if (!close) chosen.push_back(h);
      }
      spdlog::info("slam: {} vs {}: {} scan context candidates below {:.2f}, {} selected",
                   sessions[a].name, sessions[b].name, hits.size(), cfg.sc_dist_threshold,
                   chosen.size());
      loops.insert(loops.end(), chosen.begin(), chosen.end());
    }
  }
  const double t_retr = sw.Seconds();

  // ---- registration of the Scan Context candidates
  sw = Stopwatch();
  Register(loops, store, cfg, arena, "GICP scan context loops", true);
  int registrations = static_cast<int>(loops.size());
  double t_reg = sw.Seconds();

  // ---- back end
  sw = Stopwatch();
  SlamResult res = OptimizeSessions(sessions, loops, cfg, threads);
  double t_opt = sw.Seconds();

  // ---- radius-search refinement: query keyframes without a loop look for keyframes of the
  // other session near them in the world frame, verified by GICP from the current estimate.
  std::set<std::pair<NodeKey, NodeKey>> tried;
  for (const auto& l : loops) tried.insert({l.a, l.b});
  for (int round = 0; round < cfg.refine_rounds; ++round) {
    std::vector<LoopRecord> cand;
    for (std::size_t a = 0; a + 1 < n; ++a) {
      if (!res.sessions[a].aligned) continue;
      const auto& Wa = res.sessions[a].T_world_sensor;
      for (std::size_t b = a + 1; b < n; ++b) {
        if (!res.sessions[b].aligned) continue;
        const auto& Wb = res.sessions[b].T_world_sensor;
        std::vector<bool> has_loop(Wb.size(), false);
        for (const auto& l : loops) {
          if (l.accepted && l.a.session == int(a) && l.b.session == int(b)) {
            has_loop[l.b.keyframe] = true;
          }
        }
        int eligible = 0, added = 0;
        for (std::size_t j = 0; j < Wb.size() && added < cfg.refine_max_loops_per_pair; ++j) {
          if (has_loop[j]) continue;
          if (eligible++ % cfg.refine_stride != 0) continue;
          int best = -1;
          double best_d = cfg.refine_radius_m;
          for (std::size_t i = 0; i < Wa.size(); ++i) {
            const double d = (Wa[i].translation() - Wb[j].translation()).norm();
            if (d <= best_d) {
              best_d = d;
              best = int(i);
            }
          }
          if (best < 0) continue;
          LoopRecord l;
          l.a = {int(a), best};
          l.b = {int(b), int(j)};
          if (tried.count({l.a, l.b})) continue;
          tried.insert({l.a, l.b});
          l.source = "radius";
          l.T_a_b = Wa[best].inverse() * Wb[j];
          l.yaw_deg = Eigen::AngleAxisd(l.T_a_b.linear()).angle() * 180.0 / M_PI;
          cand.push_back(l);
          ++added;
        }
      }
    }
    if (cand.empty()) break;
    sw = Stopwatch();
    Register(cand, store, cfg, arena, "GICP radius loops, round " + std::to_string(round + 1),
             false);
    registrations += static_cast<int>(cand.size());
    t_reg += sw.Seconds();
    std::size_t ok = 0;
    for (const auto& l : cand) ok += l.verified ? 1 : 0;
    spdlog::info("slam: refinement round {}: {} radius candidates, {} verified", round + 1,
                 cand.size(), ok);
    loops.insert(loops.end(), cand.begin(), cand.end());
    sw = Stopwatch();
    res = OptimizeSessions(sessions, loops, cfg, threads);
    t_opt += sw.Seconds();
    if (ok == 0) break;
  }

  res.time_descriptors_s = t_desc;
  res.time_retrieval_s = t_retr;
  res.time_registration_s = t_reg;
  res.time_optimisation_s = t_opt;
  res.time_total_s = total.Seconds();
  res.registrations = registrations;
  spdlog::info(
      "slam: time per phase: descriptors {:.2f} s, retrieval {:.2f} s, registration {:.2f} s "
      "({} GICP), optimisation {:.2f} s, total {:.2f} s",
      t_desc, t_retr, t_reg, registrations, t_opt, res.time_total_s);
  return res;
}

}  // namespace ltm::slam
