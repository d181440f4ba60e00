// Changed-object evaluation: LT-map's clusters against the simulator's LD objects by point IoU.
#include "ltmapper/eval/objects.hpp"
#include "ltmapper/eval/truth_io.hpp"
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <map>
#include <set>

namespace fs = std::filesystem;

namespace ltm::eval {
namespace {

std::string Join(const std::string& a, const std::string& b) { return (fs::path(a) / b).string(); }

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> out(1);
  for (const char c : line) {
    if (c == ',') out.emplace_back();
    else if (c != '\r' && c != '"') out.back() += c;
  }
  for (auto& s : out) {
    const auto b = s.find_first_not_of(" \t");
    const auto e = s.find_last_not_of(" \t");
    s = b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
  }
  return out;
}

// Reads a CSV with a header line; calls row(fields, line number) with the `required` columns, then
// the `optional` ones ("" when the header lacks them).
template <class F>
void ReadCsv(const std::string& path, const std::vector<std::string>& required, F row,
             const std::vector<std::string>& optional = {}) {
  std::ifstream in(path);
  if (!in) throw Error(path, 0, "cannot open");
  std::string line;
  std::size_t line_no = 0;
  std::vector<std::string> header;
  std::vector<std::size_t> cols;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    auto f = SplitCsv(line);
    if (header.empty()) {
      header = f;
      for (const auto& r : required) {
        const auto it = std::find(header.begin(), header.end(), r);
        if (it == header.end()) throw Error(path, line_no, "header has no column '" + r + "'");
        cols.push_back(std::size_t(it - header.begin()));
      }
      for (const auto& o : optional) {
        const auto it = std::find(header.begin(), header.end(), o);
        cols.push_back(it == header.end() ? std::string::npos : std::size_t(it - header.begin()));
      }
      continue;
    }
    if (f.size() < header.size()) throw Error(path, line_no, "too few columns");
    std::vector<std::string> v;
    for (auto c : cols) v.push_back(c == std::string::npos ? std::string() : f[c]);
    row(v, line_no);
  }
  if (header.empty()) throw Error(path, 0, "empty CSV");
}

int ToInt(const std::string& s, const std::string& path, std::size_t line) {
  try {
    std::size_t used = 0;
    const int v = std::stoi(s, &used);
    if (used != s.size()) throw std::invalid_argument(s);
    return v;
  } catch (const std::logic_error&) {
    throw Error(path, line, "'" + s + "' is not an integer");
  }
}

std::string PairName(int a, int b) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%02d_%02d", a, b);
  return buf;
}

PointCloud Downsample(const PointCloud& c, double voxel_m) {
  return voxel_m > 0.0 ? geometry::VoxelDownsample(c, voxel_m, 1) : c;
}

std::size_t Matched(const PointCloud& q, const geometry::KdTree& tree, double d) {
  if (tree.size() == 0) return 0;
  const float d2 = float(d * d);
  std::size_t n = 0;
  std::uint32_t idx = 0;
  float sq = 0.f;
  for (const auto& p : q.points)
    if (tree.Nearest(p.xyz(), &idx, &sq) && sq <= d2) ++n;
  return n;
}

double Iou(const PointCloud& a, const geometry::KdTree& ta, const PointCloud& b, const geometry::KdTree& tb,
           double d) {
  if (a.empty() || b.empty()) return 0.0;
  const double inter = 0.5 * double(Matched(a, tb, d) + Matched(b, ta, d));
  return inter / (double(a.size()) + double(b.size()) - inter);
}

struct Box {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(1e30f), hi = Eigen::Vector3f::Constant(-1e30f);
  explicit Box(const PointCloud& c) {
    for (const auto& p : c.points) {
      lo = lo.cwiseMin(p.xyz());
      hi = hi.cwiseMax(p.xyz());
    }
  }
  bool Overlaps(const Box& o, float margin) const {
    return (lo.array() <= o.hi.array() + margin).all() && (o.lo.array() <= hi.array() + margin).all();
  }
};

}  // namespace

double PointIoU(const PointCloud& a, const PointCloud& b, const EvalConfig& cfg) {
  const PointCloud va = Downsample(a, cfg.obj_voxel_m), vb = Downsample(b, cfg.obj_voxel_m);
  if (va.empty() || vb.empty()) return 0.0;
  const geometry::KdTree ta(va), tb(vb);
  return Iou(va, ta, vb, tb, cfg.obj_match_dist_m);
}

namespace {

// Voxelised clouds with their boxes and trees (clusters or truth objects).
struct Prepared {
  std::vector<PointCloud> cloud;
  std::vector<std::unique_ptr<geometry::KdTree>> tree;
  std::vector<Box> box;
  explicit Prepared(std::size_t n) : cloud(n), tree(n), box(n, Box(PointCloud{})) {}
  void Set(std::size_t k, const PointCloud& c, double voxel_m) {
    cloud[k] = Downsample(c, voxel_m);
    box[k] = Box(cloud[k]);
    tree[k] = std::make_unique<geometry::KdTree>(cloud[k]);
  }
};

bool Eligible(const ObjectTruth& t, const std::string& cluster_pair) {
  return t.match_pairs.empty() ? cluster_pair == t.pair
                               : std::count(t.match_pairs.begin(), t.match_pairs.end(), cluster_pair) > 0;
}

// IoU of truth i and cluster k when eligible and their grown boxes overlap, else -1.
double PairIou(const ObjectTruth& t, std::size_t i, const Prepared& tp, const ObjectCluster& c, std::size_t k,
               const Prepared& cp, const EvalConfig& cfg) {
  if (tp.cloud[i].empty() || cp.cloud[k].empty() || !Eligible(t, c.pair) ||
      !tp.box[i].Overlaps(cp.box[k], float(cfg.obj_match_dist_m)))
    return -1.0;
  return Iou(tp.cloud[i], *tp.tree[i], cp.cloud[k], *cp.tree[k], cfg.obj_match_dist_m);
}

std::string TruthChange(const ObjectTruth& t) {
  int a = -1, b = -1;
  std::sscanf(t.pair.c_str(), "%d_%d", &a, &b);
  return t.session == b ? "appeared" : "disappeared";
}

ObjectsPrf Slice(const std::string& name, const ObjectsResult& r, const std::vector<ObjectTruth>& truth,
                 const std::function<bool(const ObjectTruth&)>& in_truth,
                 const std::function<bool(const ClusterScore&)>& in_clusters) {
  ObjectsPrf s;
  s.name = name;
  for (std::size_t i = 0; i < truth.size(); ++i)
    if (r.objects[i].scored && in_truth(truth[i])) ++s.truth_objects, s.found += r.objects[i].found ? 1 : 0;
  for (const auto& c : r.cluster_scores)
    if (in_clusters(c)) ++s.clusters, s.true_clusters += c.true_object ? 1 : 0;
  if (s.clusters) s.precision = double(s.true_clusters) / double(s.clusters);
  if (s.truth_objects) s.recall = double(s.found) / double(s.truth_objects);
  if (s.precision + s.recall > 0.0) s.f1 = 2.0 * s.precision * s.recall / (s.precision + s.recall);
  else if (s.clusters && s.truth_objects) s.f1 = 0.0;
  return s;
}

// Whether a cluster's partner `partner` names cluster `c`: it is c, or a row of c's track (a later
// step's view of a move's end is that end: the partner a row inherited is the first view's id).
bool Names(const std::map<int, const ClusterScore*>& cluster, int partner, int c) {
  if (partner == c) return true;
  const auto p = cluster.find(partner), q = cluster.find(c);
  return p != cluster.end() && q != cluster.end() && p->second->track >= 0 && p->second->track == q->second->track;
}

// The moves of the truth objects and clusters of pair `pair` ("" = every pair), MovedPrf's rules.
MovedPrf Moves(const std::string& pair, const ObjectsResult& r, const std::vector<ObjectTruth>& truth) {
  MovedPrf m;
  m.name = pair.empty() ? "all" : pair;
  std::map<std::pair<std::string, int>, std::size_t> at;  // (pair, truth id) -> index
  std::set<int> ends;                                      // truth ids that are an end of a move
  for (std::size_t i = 0; i < truth.size(); ++i) {
    at[{truth[i].pair, truth[i].id}] = i;
    if (truth[i].partner >= 0) ends.insert(truth[i].id);
  }
  std::map<int, const ClusterScore*> cluster;  // cluster id -> score
  for (const auto& c : r.cluster_scores) cluster[c.id] = &c;
  const auto moved = [&](const ObjectScore& o) {
    const auto it = cluster.find(o.best_cluster);
    return o.found && it != cluster.end() && it->second->moved;
  };
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const ObjectTruth& t = truth[i];
    if (t.partner < t.id || (!pair.empty() && t.pair != pair)) continue;  // each move once, from its lower id
    const auto j = at.find({t.pair, t.partner});
    if (j == at.end() || !r.objects[i].scored || !r.objects[j->second].scored) continue;
    ++m.truth_moves;
    const ObjectScore &a = r.objects[i], &b = r.objects[j->second];
    if (!moved(a) || !moved(b)) continue;
    ++m.found;
    if (Names(cluster, cluster.at(a.best_cluster)->partner, b.best_cluster) &&
        Names(cluster, cluster.at(b.best_cluster)->partner, a.best_cluster))
      ++m.linked;
  }
  for (const auto& c : r.cluster_scores) {
    if (!c.moved || (!pair.empty() && c.pair != pair)) continue;
    ++m.reported;
    if (c.true_object && ends.count(c.best_truth)) ++m.true_reported;
  }
  if (m.reported) m.precision = double(m.true_reported) / double(m.reported);
  if (m.truth_moves) m.recall = double(m.found) / double(m.truth_moves);
  return m;
}

// IdentityScore over the true clusters of different steps (pairs).
IdentityScore Identity(const ObjectsResult& r, const std::vector<ObjectTruth>& truth) {
  std::set<std::pair<int, int>> moves;  // (truth id, its move's other end)
  for (const auto& t : truth)
    if (t.partner >= 0) moves.insert({t.id, t.partner});
  IdentityScore s;
  const auto& c = r.cluster_scores;
  for (std::size_t i = 0; i < c.size(); ++i)
    for (std::size_t j = i + 1; j < c.size(); ++j) {
      if (!c[i].true_object || !c[j].true_object || c[i].pair == c[j].pair) continue;
      const bool tracked = c[i].track >= 0 && c[i].track == c[j].track;
      if (c[i].best_truth == c[j].best_truth) ++s.same, s.same_tracked += tracked ? 1 : 0;
      if (!tracked) continue;
      ++s.tracked;
      if (c[i].best_truth != c[j].best_truth && !moves.count({c[i].best_truth, c[j].best_truth})) ++s.tracked_wrong;
    }
  return s;
}

void Summarise(ObjectsResult& r, const std::vector<ObjectTruth>& truth, const std::set<std::string>& pairs,
               const EvalConfig& cfg) {
  for (const auto& s : r.objects)
    if (s.scored) ++r.truth_objects, r.found += s.found ? 1 : 0;
  r.found_fraction = r.truth_objects ? double(r.found) / double(r.truth_objects) : kNaN;
  r.all = Slice("all", r, truth, [](const ObjectTruth&) { return true; }, [](const ClusterScore&) { return true; });
  const double share = cfg.obj_min_observed_share;
  r.observable = Slice("observable", r, truth, [&](const ObjectTruth& t) { return t.observed_share >= share; },
                       [](const ClusterScore&) { return true; });
  for (const auto& p : pairs) {
    const auto in_pair = [&](const ClusterScore& c) { return c.pair == p; };
    r.per_pair.push_back(Slice(p, r, truth, [&](const ObjectTruth& t) { return t.pair == p; }, in_pair));
    r.observable_per_pair.push_back(Slice(
        p + " observable", r, truth, [&](const ObjectTruth& t) { return t.pair == p && t.observed_share >= share; },
        in_pair));
  }
  r.identity = Identity(r, truth);
  r.moved.push_back(Moves("", r, truth));
  for (const auto& p : pairs) r.moved.push_back(Moves(p, r, truth));
  for (const std::string ch : {"appeared", "disappeared"})
    r.per_change.push_back(Slice(ch, r, truth, [&](const ObjectTruth& t) { return TruthChange(t) == ch; },
                                 [&](const ClusterScore& c) { return c.change == ch; }));
  // Per truth class: a cluster counts for the class of the truth object it overlaps most; a
  // cluster that overlaps none has no class and counts in the other rows only.
  std::map<int, std::string> class_of;  // LD object id -> class
  std::set<std::string> classes;
  for (const auto& t : truth) class_of[t.id] = t.cls, classes.insert(t.cls);
  for (const auto& cls : classes)
    r.per_class.push_back(Slice("class " + cls, r, truth, [&](const ObjectTruth& t) { return t.cls == cls; },
                                [&](const ClusterScore& c) {
                                  const auto it = class_of.find(c.best_truth);
                                  return it != class_of.end() && it->second == cls;
                                }));
}

void ScoreTruth(ObjectsResult& r, const std::vector<ObjectTruth>& truth, const std::vector<ObjectCluster>& clusters,
                const std::vector<std::size_t>& used, const Prepared& tp, const Prepared& cp, const EvalConfig& cfg,
                int threads) {
  r.objects.resize(truth.size());
  ParallelFor(truth.size(), threads, [&](std::size_t i) {
    const ObjectTruth& t = truth[i];
    ObjectScore& s = r.objects[i];
    s.pair = t.pair;
    s.id = t.id;
    s.cls = t.cls;
    s.placement = t.placement;
    s.session = t.session;
    s.points = tp.cloud[i].size();
    s.change_points = t.change_points;
    s.observed_share = t.observed_share;
    s.scored = s.points >= std::size_t(std::max(cfg.obj_min_truth_points, 1)) &&
               (t.change_points < 0 || t.change_points >= long(cfg.obj_min_change_points));
    for (const std::size_t k : used) {
      const double iou = PairIou(t, i, tp, clusters[k], k, cp, cfg);
      if (iou > s.best_iou) s.best_iou = iou, s.best_cluster = clusters[k].id, s.cluster_points = cp.cloud[k].size();
    }
    s.found = s.scored && s.best_iou >= cfg.obj_min_iou;
  });
}

void ScoreClusters(ObjectsResult& r, const std::vector<ObjectTruth>& truth, const std::vector<ObjectCluster>& clusters,
                   const std::vector<std::size_t>& used, const Prepared& tp, const Prepared& cp, const EvalConfig& cfg,
                   int threads) {
  r.cluster_scores.resize(used.size());
  ParallelFor(used.size(), threads, [&](std::size_t u) {
    const std::size_t k = used[u];
    ClusterScore& s = r.cluster_scores[u];
    s.pair = clusters[k].pair;
    s.change = clusters[k].change;
    s.id = clusters[k].id;
    s.moved = clusters[k].moved;
    s.partner = clusters[k].partner;
    s.track = clusters[k].track;
    s.points = cp.cloud[k].size();
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const double iou = PairIou(truth[i], i, tp, clusters[k], k, cp, cfg);
      if (iou > s.best_iou) s.best_iou = iou, s.best_truth = truth[i].id;
    }
    s.true_object = s.best_iou >= cfg.obj_min_iou;
  });
}

}  // namespace

ObjectsResult EvaluateObjects(const std::vector<ObjectTruth>& truth, const std::vector<ObjectCluster>& clusters,
                              const EvalConfig& cfg, int threads) {
  ObjectsResult r;
  r.match_dist_m = cfg.obj_match_dist_m;
  r.voxel_m = cfg.obj_voxel_m;
  r.min_iou = cfg.obj_min_iou;
  std::set<std::string> pairs;
  for (const auto& t : truth) {
    pairs.insert(t.pair);
    pairs.insert(t.match_pairs.begin(), t.match_pairs.end());
  }
  std::vector<std::size_t> used;  // clusters of the scored pairs
  for (std::size_t k = 0; k < clusters.size(); ++k)
    if (pairs.count(clusters[k].pair)) used.push_back(k);
  r.clusters = used.size();
  Prepared cp(clusters.size()), tp(truth.size());
  ParallelFor(used.size(), threads, [&](std::size_t u) { cp.Set(used[u], clusters[used[u]].cloud, cfg.obj_voxel_m); });
  ParallelFor(truth.size(), threads, [&](std::size_t i) { tp.Set(i, truth[i].cloud, cfg.obj_voxel_m); });
  ScoreTruth(r, truth, clusters, used, tp, cp, cfg, threads);
  ScoreClusters(r, truth, clusters, used, tp, cp, cfg, threads);
  Summarise(r, truth, pairs, cfg);
  return r;
}

std::vector<SimObject> ReadSimObjects(const std::string& path) {
  std::vector<SimObject> out;
  ReadCsv(path, {"id", "class", "present_in", "placement"}, [&](const std::vector<std::string>& f, std::size_t line) {
    SimObject o;
    o.id = ToInt(f[0], path, line);
    o.cls = f[1];
    o.placement = f[3];
    o.partner = f[4].empty() ? -1 : ToInt(f[4], path, line);
    std::string cur;
    for (const char c : f[2] + ";") {
      if (c == ';') {
        if (!cur.empty()) o.present_in.push_back(ToInt(cur, path, line));
        cur.clear();
      } else if (c != ' ') {
        cur += c;
      }
    }
    out.push_back(std::move(o));
  }, {"partner"});
  return out;
}

namespace {
// The objects present in exactly one of sessions a and b (truth/objects.csv), without points yet;
// each matches the step pairs (a, j) whose session j already agrees with b about it.
std::vector<ObjectTruth> ChangedObjects(const std::string& truth_dir, int a, int b) {
  std::vector<ObjectTruth> out;
  std::map<int, int> partner;  // id -> truth/objects.csv's partner
  for (const auto& o : ReadSimObjects(Join(truth_dir, "objects.csv"))) {
    const auto in = [&](int s) { return std::count(o.present_in.begin(), o.present_in.end(), s) > 0; };
    const bool in_a = in(a), in_b = in(b);
    if (in_a == in_b) continue;
    ObjectTruth t;
    t.pair = PairName(a, b);
    t.id = o.id;
    t.cls = o.cls;
    t.placement = o.placement;
    t.session = in_a ? a : b;
    t.match_pairs.push_back(t.pair);
    // The map may have applied the change at an earlier step j (a < j < b) whose session
    // already agrees with b about the object (removed / added there).
    for (int j = std::min(a, b) + 1; j < std::max(a, b); ++j)
      if (in(j) == in_b) t.match_pairs.push_back(PairName(a, j));
    partner[t.id] = o.partner;
    out.push_back(std::move(t));
  }
  // A move's ends: both changed, on opposite sides of the pair.
  for (auto& t : out)
    for (const auto& u : out)
      if (u.id == partner[t.id] && u.session != t.session) t.partner = u.id;
  return out;
}

// The points of the objects of `out` that exist in session s, from its labelled scans (every
// objects.keyframe_stride-th) placed by `mapping`; merged in scan order.
void AddObjectPoints(const std::string& sdir, int s, const TruthMapping& mapping, const EvalConfig& cfg, int threads,
                     std::vector<ObjectTruth>* out) {
  std::map<int, std::size_t> slot;  // object id -> position in out
  for (std::size_t i = 0; i < out->size(); ++i)
    if ((*out)[i].session == s) slot[(*out)[i].id] = i;
  if (slot.empty()) return;
  const auto poses = ReadPoses(Join(sdir, "poses_world.txt"));
  const auto files = LabelledScanPaths(sdir, poses.size());
  std::vector<std::size_t> scans;
  for (std::size_t k = 0; k < files.size(); k += std::size_t(cfg.obj_keyframe_stride)) scans.push_back(k);
  std::vector<std::map<int, PointCloud>> parts(scans.size());
  ParallelFor(scans.size(), threads, [&](std::size_t j) {
    const std::size_t k = scans[j];
    const PointCloud scan = ReadLabelledScan(files[k]);
    if (scan.object.size() != scan.size()) throw Error(files[k], 0, "labelled scan needs an 'object' field");
    const Pose T = mapping.ScanPose(std::size_t(s), k, poses[k]);
    for (std::size_t i = 0; i < scan.size(); ++i) {
      if (scan.cls[i] != PointClass::kStatic || !slot.count(scan.object[i])) continue;
      const Eigen::Vector3f p = (T * scan.points[i].xyz().cast<double>()).cast<float>();
      parts[j][scan.object[i]].push_back(p.x(), p.y(), p.z(), scan.points[i].intensity);
    }
  });
  for (auto& m : parts)
    for (auto& [id, c] : m) (*out)[slot[id]].cloud.append(c);
}

// Per object, from the pair's truth changes.ply: the change points the clustering can see (PD,
// strong ND: change_points) and the share of all its change points (PD, ND) that the other
// session observed changed (weak PD, strong ND: observed_share).
void CountChangePoints(const std::string& ply, std::vector<ObjectTruth>* out) {
  const PointCloud ch = io::ReadPly(ply);
  if (ch.cls.size() != ch.size() || ch.object.size() != ch.size()) throw Error(ply, 0, "needs 'class' and 'object' fields");
  std::map<int, long> count, observed, all;
  for (std::size_t i = 0; i < ch.size(); ++i) {
    const PointClass c = ch.cls[i];
    const bool pd = c == PointClass::kPDStrong || c == PointClass::kPDWeak;
    const bool nd = c == PointClass::kNDStrong || c == PointClass::kNDWeak;
    if (!pd && !nd) continue;
    ++all[ch.object[i]];
    if (pd || c == PointClass::kNDStrong) ++count[ch.object[i]];
    if (c == PointClass::kPDWeak || c == PointClass::kNDStrong) ++observed[ch.object[i]];
  }
  for (auto& t : *out) {
    t.change_points = count.count(t.id) ? count[t.id] : 0;
    t.observed_share = all.count(t.id) ? double(observed[t.id]) / double(all[t.id]) : 0.0;
  }
}
}  // namespace

std::vector<ObjectTruth> LoadSimObjectTruth(const std::string& sim_dir, const std::string& pair,
                                            const TruthMapping& mapping, const EvalConfig& cfg, int threads) {
  int a = -1, b = -1;
  if (std::sscanf(pair.c_str(), "%d_%d", &a, &b) != 2 || a < 0 || b < 0)
    throw Error("eval objects: pair '" + pair + "' is not CC_QQ");
  const auto names = SimSessionNames(sim_dir);
  if (std::size_t(std::max(a, b)) >= names.size())
    throw Error(sim_dir, 0, "pair " + pair + ": the simulator has " + std::to_string(names.size()) + " sessions");
  const std::string truth_dir = Join(sim_dir, "truth");
  std::vector<ObjectTruth> out = ChangedObjects(truth_dir, a, b);
  for (const int s : {a, b}) AddObjectPoints(Join(truth_dir, names[std::size_t(s)]), s, mapping, cfg, threads, &out);
  for (auto& t : out) t.cloud = Downsample(t.cloud, cfg.obj_voxel_m);
  // Change points per object from the pair's truth changes.ply, when the sim wrote one (older
  // outputs have none: change_points stays -1, observed_share NaN, and every object is scored).
  std::string ply;
  try {
    ply = Join(FindPairDir(truth_dir, PairName(a, b)), "changes.ply");
  } catch (const Error&) {
  }
  if (!ply.empty() && fs::exists(ply)) CountChangePoints(ply, &out);
  return out;
}

std::vector<ObjectCluster> ReadObjectClusters(const std::string& dir) {
  const std::string csv = Join(dir, "objects.csv"), ply = Join(dir, "objects.ply");
  std::map<int, std::size_t> slot;
  std::vector<ObjectCluster> out;
  ReadCsv(csv, {"id", "session", "reference"}, [&](const std::vector<std::string>& f, std::size_t line) {
    ObjectCluster c;
    c.id = ToInt(f[0], csv, line);
    c.pair = PairName(ToInt(f[2], csv, line), ToInt(f[1], csv, line));
    c.change = f[3].rfind("pd", 0) == 0 ? "appeared" : f[3].rfind("nd", 0) == 0 ? "disappeared" : "";
    c.moved = f[4] == "moved";
    c.partner = f[5].empty() ? -1 : ToInt(f[5], csv, line);
    c.track = f[6].empty() ? -1 : ToInt(f[6], csv, line);
    if (slot.count(c.id)) throw Error(csv, line, "duplicate object id " + f[0]);
    slot[c.id] = out.size();
    out.push_back(std::move(c));
  }, {"class", "change", "partner", "track"});
  if (out.empty()) return out;
  const PointCloud all = io::ReadPly(ply);
  if (all.object.size() != all.size()) throw Error(ply, 0, "no 'object' field");
  for (std::size_t i = 0; i < all.size(); ++i) {
    const auto it = slot.find(all.object[i]);
    if (it == slot.end()) throw Error(ply, 0, "point " + std::to_string(i) + ": object " + std::to_string(all.object[i]) + " not in objects.csv");
    const auto& p = all.points[i];
    out[it->second].cloud.push_back(p.x, p.y, p.z, p.intensity);
  }
  return out;
}

}  // namespace ltm::eval
