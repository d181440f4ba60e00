// Truth placement in the estimated world (global rigid or per keyframe) and the live / meta map
// content check (new and removed objects).
#include "ltmapper/eval/livemeta.hpp"
#include "ltmapper/eval/objects.hpp"
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/eval/internal.hpp"
#include "ltmapper/eval/truth_mapping.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <mutex>

namespace fs = std::filesystem;

namespace ltm::eval {
namespace {

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

using detail::CountMatched;
using detail::MakeArena;

}  // namespace

PointCloud MapTruthByKeyframes(const PointCloud& truth_world, const std::vector<Pose>& true_poses,
                               const std::vector<Pose>& est_poses, int threads) {
  if (true_poses.size() != est_poses.size())
    throw Error("truth mapping: " + std::to_string(true_poses.size()) + " true keyframe poses but " +
                std::to_string(est_poses.size()) + " estimated ones");
  if (true_poses.empty()) throw Error("truth mapping: no keyframe poses");
  PointCloud keyframes;
  keyframes.reserve(true_poses.size());
  std::vector<Pose> correction(true_poses.size());
  for (std::size_t k = 0; k < true_poses.size(); ++k) {
    const Eigen::Vector3d t = true_poses[k].translation();
    keyframes.push_back(float(t.x()), float(t.y()), float(t.z()));
    correction[k] = est_poses[k] * true_poses[k].inverse();
  }
  const geometry::KdTree tree(std::move(keyframes));
  PointCloud out = truth_world;
  ParallelForChunks(out.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
    std::uint32_t k = 0;
    float sq = 0.f;
    for (std::size_t i = begin; i != end; ++i) {
      auto& p = out.points[i];
      tree.Nearest(p.xyz(), &k, &sq);
      const Eigen::Vector3d q = correction[k] * Eigen::Vector3d(p.x, p.y, p.z);
      p.x = float(q.x());
      p.y = float(q.y());
      p.z = float(q.z());
    }
  });
  return out;
}

PointCloud TruthMapping::Map(const PointCloud& truth_world, std::size_t session, int threads) const {
  if (mode == "global") return geometry::Transform(truth_world, T_est_truth);
  if (session >= sessions.size())
    throw Error("truth mapping: no sim session " + std::to_string(session) + " (" + std::to_string(sessions.size()) +
                " sessions)");
  const SessionTrajectory& s = sessions[session];
  if (s.est.empty())
    throw Error("truth mapping: session " + s.name + " has no estimated poses (not aligned); use --truth-mapping global");
  return MapTruthByKeyframes(truth_world, s.truth, s.est, threads);
}

Pose TruthMapping::ScanPose(std::size_t session, std::size_t k, const Pose& T_world_sensor) const {
  if (mode == "global") return T_est_truth * T_world_sensor;
  if (session >= sessions.size() || sessions[session].est.empty())
    throw Error("truth mapping: sim session " + std::to_string(session) +
                " has no estimated poses (not aligned); use --truth-mapping global");
  const auto& est = sessions[session].est;
  if (k >= est.size())
    throw Error("truth mapping: session " + sessions[session].name + " has " + std::to_string(est.size()) +
                " estimated poses, keyframe " + std::to_string(k) + " asked");
  return est[k];
}

TruthMapping GlobalTruthMapping(const Pose& T_est_truth, const std::string& description) {
  TruthMapping m;
  m.mode = "global";
  m.T_est_truth = T_est_truth;
  m.description = description;
  return m;
}

TruthMapping KeyframeTruthMapping(const std::string& sim_dir, const std::string& aligned_dir) {
  if (aligned_dir.empty()) throw Error("truth mapping: per-keyframe mapping needs the LT-SLAM output (--aligned)");
  TruthMapping m;
  m.mode = "keyframe";
  m.description = "keyframe: p_est = T_est_k T_true_k^-1 p, k = nearest true keyframe of the observing session (" +
                  aligned_dir + ")";
  for (const auto& name : SimSessionNames(sim_dir)) {
    SessionTrajectory s;
    s.name = name;
    s.truth = ReadPoses(Join(Join(Join(sim_dir, "truth"), name), "poses_world.txt"));
    const std::string est = io::layout::PosesWorldFile(aligned_dir, name);
    if (fs::exists(est)) {
      s.est = ReadPoses(est);
      if (s.est.size() != s.truth.size())
        throw Error(est, 0, std::to_string(s.est.size()) + " poses but the truth has " + std::to_string(s.truth.size()) +
                                " keyframes");
    }
    m.sessions.push_back(std::move(s));
  }
  return m;
}

namespace {
// truth/<name> of sim session `session`, or ltm::Error naming the truth folder.
std::string SessionTruthDir(const std::string& sim_dir, std::size_t session) {
  const auto names = SimSessionNames(sim_dir);
  if (session >= names.size())
    throw Error(Join(sim_dir, "truth"), 0, "no sim session " + std::to_string(session));
  return Join(Join(sim_dir, "truth"), names[session]);
}
}  // namespace

std::string StaticWorldFile(const std::string& sim_dir, std::size_t session) {
  return Join(SessionTruthDir(sim_dir, session), "static_world.pcd");
}

PointCloud SensorPositions(const std::string& sim_dir, std::size_t session, const TruthMapping& mapping) {
  const std::vector<Pose> T_true = ReadPoses(Join(SessionTruthDir(sim_dir, session), "poses_world.txt"));
  PointCloud c;
  c.reserve(T_true.size());
  for (std::size_t k = 0; k < T_true.size(); ++k) {
    const Eigen::Vector3d t = mapping.ScanPose(session, k, T_true[k]).translation();
    c.push_back(float(t.x()), float(t.y()), float(t.z()));
  }
  return c;
}

std::vector<PointCloud> ChangesFromLabelledScans(const std::string& sim_dir, std::size_t session,
                                                 const std::vector<const PointCloud*>& changes,
                                                 const TruthMapping& mapping, double voxel_m, int threads,
                                                 bool sampled_surfaces) {
  const std::string tdir = SessionTruthDir(sim_dir, session);
  const std::vector<Pose> T_true = ReadPoses(Join(tdir, "poses_world.txt"));
  const auto files = LabelledScanPaths(tdir, T_true.size());
  // Which static-world points are changes of which clouds (each change point is one of them, at
  // distance 0): one bit per cloud, so clouds may overlap (a pair's changes and its objects' part).
  using Label = std::uint8_t;
  constexpr std::size_t kMaxClouds = std::numeric_limits<Label>::digits;
  if (changes.size() > kMaxClouds)
    throw Error("ChangesFromLabelledScans: " + std::to_string(changes.size()) + " change clouds, at most " +
                std::to_string(kMaxClouds));
  auto world = std::make_shared<const PointCloud>(io::ReadCloud(StaticWorldFile(sim_dir, session)));
  const geometry::KdTree tree(world);
  std::vector<Label> label(world->size(), 0);
  // LD object truth is voxelised apart from the static world (a car's voxel there may also hold
  // ground points), so a change point marks its nearest static-world point within voxel_m / 2.
  const float same2 = float(0.25 * voxel_m * voxel_m);
  for (std::size_t c = 0; c < changes.size(); ++c)
    for (const PointXYZI& p : changes[c]->points) {
      std::uint32_t j = 0;
      float d2 = 0.f;
      if (tree.Nearest(p.xyz(), &j, &d2) && d2 <= same2) label[j] |= Label(1u << c);
    }
  const std::size_t n_out = changes.size() + (sampled_surfaces ? 1 : 0);
  std::vector<PointCloud> out(n_out);
  std::mutex out_mutex;
  ParallelForChunks(files.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k != end; ++k) {
      const PointCloud scan = ReadLabelledScan(files[k]);
      const Pose T_est = mapping.ScanPose(session, k, T_true[k]);
      const Eigen::Matrix3f R = T_true[k].linear().cast<float>();
      const Eigen::Vector3f t = T_true[k].translation().cast<float>();
      std::vector<PointCloud> part(n_out);
      for (std::size_t i = 0; i < scan.size(); ++i) {
        if (scan.cls[i] != PointClass::kStatic) continue;
        if (sampled_surfaces) part.back().points.push_back(scan.points[i]);
        std::uint32_t j = 0;
        float d2 = 0.f;
        if (!tree.Nearest(R * scan.points[i].xyz() + t, &j, &d2) || label[j] == 0) continue;
        for (std::size_t c = 0; c < changes.size(); ++c)
          if (label[j] >> c & 1u) part[c].points.push_back(scan.points[i]);
      }
      for (PointCloud& p : part) {
        geometry::TransformInPlace(p, T_est);
        p = geometry::VoxelDownsample(p, voxel_m, 1);
      }
      const std::lock_guard<std::mutex> lock(out_mutex);
      for (std::size_t c = 0; c < n_out; ++c) out[c].append(part[c]);
    }
  });
  for (PointCloud& c : out) {
    c = geometry::VoxelDownsample(c, voxel_m, threads);
    c.cls.clear();
  }
  return out;
}


// ------------------------------------------------------------------------------ live / meta
LiveMetaResult EvaluateLiveMeta(const std::vector<LiveMetaObject>& truth, const PointCloud& live,
                                const PointCloud& meta, const EvalConfig& cfg, int threads) {
  LiveMetaResult r;
  r.match_dist_m = cfg.ld_match_dist_m;
  r.min_fraction = cfg.livemeta_min_fraction;
  r.live_points = live.size();
  r.meta_points = meta.size();
  const geometry::KdTree live_tree(live), meta_tree(meta);
  tbb::task_arena arena = MakeArena(threads);
  for (const auto& t : truth) {
    LiveMetaScore s;
    s.id = t.id;
    s.cls = t.cls;
    s.placement = t.placement;
    s.added = t.added;
    for (const auto& v : t.views) {
      s.points = std::max(s.points, v.size());
      if (v.empty()) continue;
      const double live_f = double(CountMatched(v, live_tree, cfg.ld_match_dist_m, arena)) / double(v.size());
      const double meta_f = double(CountMatched(v, meta_tree, cfg.ld_match_dist_m, arena)) / double(v.size());
      s.live_fraction = std::isnan(s.live_fraction) ? live_f : std::max(s.live_fraction, live_f);
      s.meta_fraction = std::isnan(s.meta_fraction) ? meta_f : std::max(s.meta_fraction, meta_f);
    }
    s.scored = s.points > 0 && s.points >= std::size_t(cfg.obj_min_truth_points);
    s.in_live = s.live_fraction >= cfg.livemeta_min_fraction;  // false for NaN
    s.in_meta = s.meta_fraction >= cfg.livemeta_min_fraction;
    if (s.scored) {
      (s.added ? r.added : r.removed) += 1;
      if (s.in_live) (s.added ? r.added_in_live : r.removed_in_live) += 1;
      if (s.in_meta) (s.added ? r.added_in_meta : r.removed_in_meta) += 1;
    }
    r.objects.push_back(std::move(s));
  }
  return r;
}

std::vector<LiveMetaObject> LoadSimLiveMetaTruth(const std::string& sim_dir, const std::vector<std::string>& classes,
                                                 const TruthMapping& mapping, int threads) {
  const auto names = SimSessionNames(sim_dir);
  const std::size_t last = names.size() - 1;
  const std::string truth_dir = Join(sim_dir, "truth");
  std::vector<LiveMetaObject> out;
  std::vector<std::vector<int>> present;  // per object in out: sessions where it exists
  for (const auto& o : ReadSimObjects(Join(truth_dir, "objects.csv"))) {
    if (!classes.empty() && std::find(classes.begin(), classes.end(), o.cls) == classes.end()) continue;
    const bool in0 = std::count(o.present_in.begin(), o.present_in.end(), 0) > 0;
    const bool in_last = std::count(o.present_in.begin(), o.present_in.end(), int(last)) > 0;
    if (in0 == in_last) continue;
    LiveMetaObject t;
    t.id = o.id;
    t.cls = o.cls;
    t.placement = o.placement;
    t.added = in_last;
    out.push_back(std::move(t));
    present.push_back(o.present_in);
  }
  for (std::size_t s = 0; s < names.size(); ++s) {
    std::map<int, std::size_t> slot;  // object id -> position in out
    for (std::size_t i = 0; i < out.size(); ++i)
      if (std::count(present[i].begin(), present[i].end(), int(s))) slot[out[i].id] = i;
    if (slot.empty()) continue;
    const std::string ply = Join(Join(truth_dir, names[s]), "static_world.ply");
    const PointCloud world = io::ReadPly(ply);
    if (world.object.size() != world.size()) throw Error(ply, 0, "no 'object' field");
    std::vector<bool> keep(world.size());
    for (std::size_t i = 0; i < world.size(); ++i) keep[i] = slot.count(world.object[i]) > 0;
    const PointCloud mapped = mapping.Map(world.select(keep), s, threads);
    std::map<int, PointCloud> view;
    for (std::size_t i = 0; i < mapped.size(); ++i) {
      const auto& p = mapped.points[i];
      view[mapped.object[i]].push_back(p.x, p.y, p.z, p.intensity);
    }
    for (auto& [id, c] : view) out[slot[id]].views.push_back(std::move(c));
  }
  return out;
}

}  // namespace ltm::eval
