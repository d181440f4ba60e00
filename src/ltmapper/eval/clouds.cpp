// Point-wise cloud metrics: HD removal (SA/DA/AA), LD changes (P/R/F1), restoration (Chamfer).
#include "ltmapper/eval/hd.hpp"
#include "ltmapper/eval/ld.hpp"
#include "ltmapper/eval/restore.hpp"
#include "ltmapper/eval/internal.hpp"
#include "ltmapper/geometry/geometry.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <unordered_map>

namespace ltm::eval {

void EvalConfig::Validate(const std::string& where) const {
  ValidateConfig(*this, where);
  if (std::adjacent_find(ld_bands_m.begin(), ld_bands_m.end(), std::greater_equal<double>()) != ld_bands_m.end())
    throw Error(where + ": ld.bands_m must be strictly increasing");
}
tbb::task_arena detail::MakeArena(int threads) {
  return threads > 0 ? tbb::task_arena(threads) : tbb::task_arena();
}

std::size_t detail::CountMatched(const PointCloud& queries, const geometry::KdTree& tree, double dist,
                                 tbb::task_arena& arena) {
  if (queries.empty() || tree.size() == 0) return 0;
  const float d2 = float(dist * dist);
  return arena.execute([&] {
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, queries.size(), 1024), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::size_t acc) {
          std::uint32_t idx = 0;
          float sq = 0.f;
          for (std::size_t i = r.begin(); i != r.end(); ++i)
            if (tree.Nearest(queries.points[i].xyz(), &idx, &sq) && sq <= d2) ++acc;
          return acc;
        },
        [](std::size_t a, std::size_t b) { return a + b; });
  });
}

namespace {

using detail::CountMatched;
using detail::MakeArena;

double Ratio(std::size_t num, std::size_t den) {
  return den == 0 ? kNaN : double(num) / double(den);
}

PrfStats Prf(const PointCloud& truth, const PointCloud& pred, const geometry::KdTree& truth_tree,
             const geometry::KdTree& pred_tree, double dist, tbb::task_arena& arena) {
  PrfStats s;
  s.predicted = pred.size();
  s.truth = truth.size();
  s.predicted_matched = CountMatched(pred, truth_tree, dist, arena);
  s.truth_matched = CountMatched(truth, pred_tree, dist, arena);
  s.precision = Ratio(s.predicted_matched, s.predicted);
  s.recall = Ratio(s.truth_matched, s.truth);
  if (!std::isnan(s.precision) && !std::isnan(s.recall))
    s.f1 = s.precision + s.recall > 0.0 ? 2.0 * s.precision * s.recall / (s.precision + s.recall) : 0.0;
  return s;
}

// Recall alone: the truth points with a predicted point within `dist`.
PrfStats Recall(const PointCloud& truth, const geometry::KdTree& pred_tree, double dist, tbb::task_arena& arena) {
  PrfStats s;
  s.truth = truth.size();
  s.truth_matched = CountMatched(truth, pred_tree, dist, arena);
  s.recall = Ratio(s.truth_matched, s.truth);
  return s;
}

PointCloud Concat(const PointCloud& a, const PointCloud& b) {
  PointCloud c;
  c.points.reserve(a.size() + b.size());
  c.points.insert(c.points.end(), a.points.begin(), a.points.end());
  c.points.insert(c.points.end(), b.points.begin(), b.points.end());
  return c;
}

// Among predicted points (strong then weak) within `dist` of the truth union (strong then
// weak), how many have the nearest truth point's strength.
void Strength(const PointCloud& pred_strong, const PointCloud& pred_weak,
              const geometry::KdTree& truth_union, std::size_t truth_strong_count, double dist,
              tbb::task_arena& arena, std::size_t* matched, std::size_t* correct) {
  *matched = 0;
  *correct = 0;
  if (truth_union.size() == 0) return;
  const float d2 = float(dist * dist);
  using Acc = std::pair<std::size_t, std::size_t>;
  for (int pass = 0; pass < 2; ++pass) {
    const PointCloud& pred = pass == 0 ? pred_strong : pred_weak;
    const bool strong = pass == 0;
    const Acc acc = arena.execute([&] {
      return tbb::parallel_reduce(
          tbb::blocked_range<std::size_t>(0, pred.size(), 1024), Acc{0, 0},
          [&](const tbb::blocked_range<std::size_t>& r, Acc a) {
            std::uint32_t idx = 0;
            float sq = 0.f;
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
              if (!truth_union.Nearest(pred.points[i].xyz(), &idx, &sq) || sq > d2) continue;
              ++a.first;
              if ((idx < truth_strong_count) == strong) ++a.second;
            }
            return a;
          },
          [](Acc a, Acc b) { return Acc{a.first + b.first, a.second + b.second}; });
    });
    *matched += acc.first;
    *correct += acc.second;
  }
}

// Patch grid cell of a point.
struct Cell {
  std::int64_t x, y, z;
  bool operator==(const Cell& o) const { return x == o.x && y == o.y && z == o.z; }
  bool operator<(const Cell& o) const {
    return x != o.x ? x < o.x : (y != o.y ? y < o.y : z < o.z);
  }
};
struct CellHash {
  std::size_t operator()(const Cell& c) const {
    return std::size_t(c.x * 73856093) ^ std::size_t(c.y * 19349663) ^ std::size_t(c.z * 83492791);
  }
};
using CellMap = std::unordered_map<Cell, std::vector<std::uint32_t>, CellHash>;

CellMap Bucket(const PointCloud& cloud, double edge) {
  CellMap m;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.points[i];
    const Cell c{std::int64_t(std::floor(double(p.x) / edge)),
                 std::int64_t(std::floor(double(p.y) / edge)),
                 std::int64_t(std::floor(double(p.z) / edge))};
    m[c].push_back(std::uint32_t(i));
  }
  return m;
}

// Mean over `from` of the (squared, when `squared`) distance to the nearest point of `to`.
double DirectedMean(const PointCloud& from, const geometry::KdTree& to, bool squared) {
  double sum = 0.0;
  std::uint32_t idx = 0;
  float sq = 0.f;
  for (const auto& p : from.points) {
    to.Nearest(p.xyz(), &idx, &sq);
    sum += squared ? double(sq) : std::sqrt(double(sq));
  }
  return sum / double(from.size());
}

}  // namespace

// ------------------------------------------------------------------------------------- HD
struct HdEvaluator::Impl {
  geometry::KdTree tree;
  EvalConfig cfg;
  std::map<int, std::string> object_classes;
  int threads = 0;
  // (class code, object id) -> (total, preserved)
  std::map<std::pair<int, std::int32_t>, std::pair<std::size_t, std::size_t>> tally;
  std::size_t out_of_range = 0;
  std::unique_ptr<geometry::KdTree> static_ref;
  Impl(PointCloud out, const EvalConfig& c, std::map<int, std::string> oc, int t)
      : tree(std::move(out)), cfg(c), object_classes(std::move(oc)), threads(t) {}
};

HdEvaluator::HdEvaluator(PointCloud output, const EvalConfig& cfg,
                         std::map<int, std::string> object_classes, int threads) {
  cfg.Validate();
  impl_ = std::make_unique<Impl>(std::move(output), cfg, std::move(object_classes), threads);
}
HdEvaluator::~HdEvaluator() = default;

void HdEvaluator::SetStaticReference(PointCloud static_truth) {
  impl_->static_ref = std::make_unique<geometry::KdTree>(std::move(static_truth));
}

// Tally key of HD points near static truth (object ids of HD points are pooled otherwise).
constexpr std::int32_t kNearStatic = -2;

void HdEvaluator::Add(const PointCloud& truth, const Eigen::Vector3d& sensor) {
  if (truth.empty()) return;
  if (truth.cls.size() != truth.size())
    throw Error("HD truth cloud has no per-point class (need a labelled PLY with field 'class')");
  truth.CheckConsistent("HD truth cloud");
  const float d2 = float(impl_->cfg.hd_match_dist_m * impl_->cfg.hd_match_dist_m);
  const double max_range = impl_->cfg.hd_truth_max_range_m;
  const Eigen::Vector3f s = sensor.cast<float>();
  // 0 = matched, 1 = unmatched, 2 = out of range; near[i]: HD point near static truth.
  std::vector<std::uint8_t> state(truth.size(), 1), near(truth.size(), 0);
  const geometry::KdTree* ref = impl_->static_ref.get();
  const float near2 = float(impl_->cfg.hd_near_static_m * impl_->cfg.hd_near_static_m);
  ParallelForChunks(truth.size(), impl_->threads, 1024, [&](std::size_t begin, std::size_t end) {
    std::uint32_t idx = 0;
    float sq = 0.f;
    for (std::size_t i = begin; i != end; ++i) {
      const Eigen::Vector3f p = truth.points[i].xyz();
      if (max_range > 0.0 && (p - s).norm() > max_range) {
        state[i] = 2;
        continue;
      }
      if (impl_->tree.Nearest(p, &idx, &sq) && sq <= d2) state[i] = 0;
      if (ref && truth.cls[i] == PointClass::kHD && ref->Nearest(p, &idx, &sq) && sq <= near2) near[i] = 1;
    }
  });
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (state[i] == 2) {
      ++impl_->out_of_range;
      continue;
    }
    const int cls = int(truth.cls[i]);
    // Object ids only separate LD objects among static points (HD actors are pooled as "hd").
    const std::int32_t obj =
        truth.cls[i] == PointClass::kStatic && !truth.object.empty() ? std::max(truth.object[i], -1)
        : near[i]                                                    ? kNearStatic
                                                                     : -1;
    auto& t = impl_->tally[{cls, obj}];
    ++t.first;
    if (state[i] == 0) ++t.second;
  }
}

HdResult HdEvaluator::Result() const {
  HdResult r;
  r.match_dist_m = impl_->cfg.hd_match_dist_m;
  r.output_points = impl_->tree.size();
  r.ignored = impl_->out_of_range;
  std::map<std::string, ClassCount> rows;
  for (const auto& [key, tp] : impl_->tally) {
    const auto cls = PointClass(key.first);
    std::string name;
    if (cls == PointClass::kStatic) {
      r.static_total += tp.first;
      r.static_preserved += tp.second;
      if (key.second < 0) {
        name = "static";
      } else {
        const auto it = impl_->object_classes.find(key.second);
        name = "ld:" + (it != impl_->object_classes.end() ? it->second : std::string("object"));
      }
    } else if (cls == PointClass::kHD) {
      r.dynamic_total += tp.first;
      r.dynamic_removed += tp.first - tp.second;
      name = key.second == kNearStatic ? "hd near static" : "hd";
      if (key.second != kNearStatic) {
        r.separable_total += tp.first;
        r.separable_removed += tp.first - tp.second;
      }
    } else {
      r.ignored += tp.first;
      name = "unknown";
    }
    auto& row = rows[name];
    row.name = name;
    row.total += tp.first;
    row.preserved += tp.second;
  }
  r.sa = Ratio(r.static_preserved, r.static_total);
  r.da = Ratio(r.dynamic_removed, r.dynamic_total);
  r.separable_given = impl_->static_ref != nullptr;
  if (r.separable_given) r.da_separable = Ratio(r.separable_removed, r.separable_total);
  if (!std::isnan(r.sa) && !std::isnan(r.da)) r.aa = std::sqrt(r.sa * r.da);
  auto rank = [](const std::string& n) {
    return n == "static" ? 0 : n.rfind("ld:", 0) == 0 ? 1 : n == "hd" ? 2 : n == "hd near static" ? 3 : 4;
  };
  for (auto& [name, row] : rows) r.classes.push_back(row);
  std::stable_sort(r.classes.begin(), r.classes.end(),
                   [&](const ClassCount& a, const ClassCount& b) { return rank(a.name) < rank(b.name); });
  return r;
}

HdResult EvaluateHd(const PointCloud& truth, const PointCloud& output, const EvalConfig& cfg,
                    const std::map<int, std::string>& object_classes, int threads) {
  HdEvaluator ev(output, cfg, object_classes, threads);
  ev.Add(truth);
  return ev.Result();
}

// ------------------------------------------------------------------------------------- LD
namespace {
// Distance of each point of `c` to its nearest point of `keyframes` (keyframe positions).
std::vector<float> DistanceTo(const PointCloud& c, const PointCloud& keyframes, int threads) {
  std::vector<float> out(c.size(), std::numeric_limits<float>::infinity());
  if (keyframes.empty()) return out;
  const geometry::KdTree tree(std::make_shared<const PointCloud>(keyframes));
  ParallelForChunks(c.size(), threads, 4096, [&](std::size_t begin, std::size_t end) {
    std::uint32_t idx = 0;
    float sq = 0.f;
    for (std::size_t i = begin; i != end; ++i)
      if (tree.Nearest(c.points[i].xyz(), &idx, &sq)) out[i] = std::sqrt(sq);
  });
  return out;
}
// The points of `c` whose distance lies in [lo, hi).
PointCloud InBand(const PointCloud& c, const std::vector<float>& dist, double lo, double hi) {
  std::vector<bool> keep(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) keep[i] = dist[i] >= lo && dist[i] < hi;
  return c.select(keep);
}
}  // namespace

LdResult EvaluateLd(const ChangeClouds& truth, const ChangeClouds& pred, const PointCloud* kept_map,
                    const EvalConfig& cfg, int threads, const LdTrajectories* trajectories,
                    const ChangeClouds* truth_objects, const ChangeClouds* truth_separable) {
  cfg.Validate();
  auto arena = MakeArena(threads);
  const double d = cfg.ld_match_dist_m;
  LdResult r;
  r.match_dist_m = d;

  const PointCloud truth_pd = Concat(truth.pd_strong, truth.pd_weak);
  const PointCloud truth_nd = Concat(truth.nd_strong, truth.nd_weak);
  const PointCloud pred_pd = Concat(pred.pd_strong, pred.pd_weak);
  const PointCloud pred_nd = Concat(pred.nd_strong, pred.nd_weak);
  auto tree = [](const PointCloud& c) { return geometry::KdTree(std::make_shared<const PointCloud>(c)); };
  const auto t_pds = tree(truth.pd_strong), t_pdw = tree(truth.pd_weak), t_nds = tree(truth.nd_strong),
             t_ndw = tree(truth.nd_weak), t_pd = tree(truth_pd), t_nd = tree(truth_nd);
  const auto p_pds = tree(pred.pd_strong), p_pdw = tree(pred.pd_weak), p_nds = tree(pred.nd_strong),
             p_ndw = tree(pred.nd_weak), p_pd = tree(pred_pd), p_nd = tree(pred_nd);

  r.pd_strong = Prf(truth.pd_strong, pred.pd_strong, t_pds, p_pds, d, arena);
  r.pd_weak = Prf(truth.pd_weak, pred.pd_weak, t_pdw, p_pdw, d, arena);
  r.pd = Prf(truth_pd, pred_pd, t_pd, p_pd, d, arena);
  r.nd_strong = Prf(truth.nd_strong, pred.nd_strong, t_nds, p_nds, d, arena);
  r.nd_weak = Prf(truth.nd_weak, pred.nd_weak, t_ndw, p_ndw, d, arena);
  r.nd = Prf(truth_nd, pred_nd, t_nd, p_nd, d, arena);

  Strength(pred.pd_strong, pred.pd_weak, t_pd, truth.pd_strong.size(), d, arena, &r.pd_matched,
           &r.pd_strength_correct);
  r.pd_strength_accuracy = Ratio(r.pd_strength_correct, r.pd_matched);
  Strength(pred.nd_strong, pred.nd_weak, t_nd, truth.nd_strong.size(), d, arena, &r.nd_matched,
           &r.nd_strength_correct);
  r.nd_strength_accuracy = Ratio(r.nd_strength_correct, r.nd_matched);
  // Recall over a subset of the truth, PD and ND, against every predicted point of the kind.
  const auto recall_over = [&](const ChangeClouds& subset, PrfStats* pd, PrfStats* nd) {
    *pd = Recall(Concat(subset.pd_strong, subset.pd_weak), p_pd, d, arena);
    *nd = Recall(Concat(subset.nd_strong, subset.nd_weak), p_nd, d, arena);
  };
  r.objects_given = truth_objects != nullptr;
  if (truth_objects) recall_over(*truth_objects, &r.pd_objects, &r.nd_objects);
  r.separable_given = truth_separable != nullptr;
  if (truth_separable) recall_over(*truth_separable, &r.pd_separable, &r.nd_separable);

  if (trajectories && !cfg.ld_bands_m.empty()) {
    std::vector<double> edges = cfg.ld_bands_m;  // strictly increasing (cfg.Validate)
    edges.push_back(std::numeric_limits<double>::infinity());
    const auto d_tpd = DistanceTo(truth_pd, trajectories->central, threads);
    const auto d_ppd = DistanceTo(pred_pd, trajectories->central, threads);
    const auto d_tnd = DistanceTo(truth_nd, trajectories->query, threads);
    const auto d_pnd = DistanceTo(pred_nd, trajectories->query, threads);
    double lo = 0.0;
    for (const double hi : edges) {
      LdBand b;
      b.min_m = lo;
      b.max_m = hi;
      b.pd = Prf(InBand(truth_pd, d_tpd, lo, hi), InBand(pred_pd, d_ppd, lo, hi), t_pd, p_pd, d, arena);
      b.nd = Prf(InBand(truth_nd, d_tnd, lo, hi), InBand(pred_nd, d_pnd, lo, hi), t_nd, p_nd, d, arena);
      r.bands.push_back(b);
      lo = hi;
    }
  }

  r.weak_nd_truth = truth.nd_weak.size();
  if (kept_map) {
    r.kept_map_given = true;
    const geometry::KdTree kept(std::make_shared<const PointCloud>(*kept_map));
    r.weak_nd_kept = CountMatched(truth.nd_weak, kept, d, arena);
    r.weak_nd_preserved = Ratio(r.weak_nd_kept, r.weak_nd_truth);
  }
  return r;
}

namespace {
// Points of `c` (labelled `cls`) with (want_matched) / without a point of `tree` within `dist`.
void AppendUnmatched(const PointCloud& c, PointClass cls, const geometry::KdTree& tree, double dist,
                     int threads, PointCloud* out) {
  std::vector<std::uint8_t> miss(c.size(), 1);
  const float d2 = float(dist * dist);
  if (tree.size() > 0) {
    ParallelForChunks(c.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
      std::uint32_t idx = 0;
      float sq = 0.f;
      for (std::size_t i = begin; i != end; ++i)
        miss[i] = tree.Nearest(c.points[i].xyz(), &idx, &sq) && sq <= d2 ? 0 : 1;
    });
  }
  for (std::size_t i = 0; i < c.size(); ++i)
    if (miss[i]) {
      out->points.push_back(c.points[i]);
      out->cls.push_back(cls);
    }
}
}  // namespace

LdErrors LdErrorClouds(const ChangeClouds& truth, const ChangeClouds& pred, const EvalConfig& cfg, int threads) {
  cfg.Validate();
  const double d = cfg.ld_match_dist_m;
  auto tree = [](const PointCloud& c) { return geometry::KdTree(std::make_shared<const PointCloud>(c)); };
  const auto t_pd = tree(Concat(truth.pd_strong, truth.pd_weak)), t_nd = tree(Concat(truth.nd_strong, truth.nd_weak));
  const auto p_pd = tree(Concat(pred.pd_strong, pred.pd_weak)), p_nd = tree(Concat(pred.nd_strong, pred.nd_weak));
  LdErrors e;
  AppendUnmatched(pred.pd_strong, PointClass::kPDStrong, t_pd, d, threads, &e.false_positives);
  AppendUnmatched(pred.pd_weak, PointClass::kPDWeak, t_pd, d, threads, &e.false_positives);
  AppendUnmatched(pred.nd_strong, PointClass::kNDStrong, t_nd, d, threads, &e.false_positives);
  AppendUnmatched(pred.nd_weak, PointClass::kNDWeak, t_nd, d, threads, &e.false_positives);
  AppendUnmatched(truth.pd_strong, PointClass::kPDStrong, p_pd, d, threads, &e.false_negatives);
  AppendUnmatched(truth.pd_weak, PointClass::kPDWeak, p_pd, d, threads, &e.false_negatives);
  AppendUnmatched(truth.nd_strong, PointClass::kNDStrong, p_nd, d, threads, &e.false_negatives);
  AppendUnmatched(truth.nd_weak, PointClass::kNDWeak, p_nd, d, threads, &e.false_negatives);
  return e;
}

PointCloud WithoutPoints(const PointCloud& cloud, const PointCloud& taken, const EvalConfig& cfg, int threads) {
  cfg.Validate();
  if (taken.empty()) return cloud;
  const geometry::KdTree tree(std::make_shared<const PointCloud>(taken));
  const float eps2 = float(cfg.ld_same_point_m * cfg.ld_same_point_m);
  std::vector<std::uint8_t> keep(cloud.size(), 1);
  ParallelForChunks(cloud.size(), threads, 1024, [&](std::size_t begin, std::size_t end) {
    std::uint32_t idx = 0;
    float sq = 0.f;
    for (std::size_t i = begin; i != end; ++i)
      if (tree.Nearest(cloud.points[i].xyz(), &idx, &sq) && sq <= eps2)
        keep[i] = 0;
  });
  return cloud.select(std::vector<bool>(keep.begin(), keep.end()));
}

PointCloud KeptMapFromChanges(const PointCloud& central_static, const PointCloud& nd_strong,
                              const EvalConfig& cfg, int threads) {
  return WithoutPoints(central_static, nd_strong, cfg, threads);
}

// -------------------------------------------------------------------------------- restore
double SameClassFraction(const PointCloud& want, const PointCloud& got, double radius_m, int threads) {
  if (want.cls.size() != want.size() || got.cls.size() != got.size())
    throw Error("same-class share: both maps need a class per point");
  if (want.empty()) return 0.0;
  const geometry::KdTree tree(got);
  std::vector<char> same(want.size(), 0);
  ParallelForChunks(want.size(), threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i != end; ++i)
      for (const auto& [j, d2] : tree.Radius(want.points[i].xyz(), float(radius_m)))
        if (got.cls[j] == want.cls[i]) {
          same[i] = 1;
          break;
        }
  });
  return double(std::count(same.begin(), same.end(), char(1))) / double(want.size());
}

RestoreResult EvaluateRestore(const PointCloud& a, const PointCloud& b, const EvalConfig& cfg,
                              int threads) {
  cfg.Validate();
  RestoreResult r;
  r.patch_m = cfg.patch_m;
  r.min_points = cfg.patch_min_points;
  r.chamfer = cfg.chamfer;
  r.thresholds = cfg.chamfer_thresholds;
  r.np_above.assign(r.thresholds.size(), 0);
  r.points_a = a.size();
  r.points_b = b.size();
  r.same_class_m = cfg.same_class_m;
  const auto labelled = [](const PointCloud& c) { return !c.empty() && c.cls.size() == c.size(); };
  if (cfg.same_class_m > 0.0 && labelled(a) && labelled(b)) {
    r.same_class_a = SameClassFraction(a, b, cfg.same_class_m, threads);
    r.same_class_b = SameClassFraction(b, a, cfg.same_class_m, threads);
  }

  const CellMap ca = Bucket(a, cfg.patch_m), cb = Bucket(b, cfg.patch_m);
  r.patches_a = ca.size();
  r.patches_b = cb.size();
  const std::size_t min_pts = std::size_t(cfg.patch_min_points);
  std::vector<Cell> valid;
  for (const auto& [cell, idx_a] : ca) {
    const auto it = cb.find(cell);
    if (it == cb.end()) continue;
    ++r.patches_both;
    if (idx_a.size() >= min_pts && it->second.size() >= min_pts) valid.push_back(cell);
  }
  std::sort(valid.begin(), valid.end());  // deterministic order
  r.np_valid = valid.size();
  if (valid.empty()) return r;

  const bool squared = cfg.chamfer == "fan_squared";
  std::vector<double> cd(valid.size(), 0.0);
  ParallelFor(valid.size(), threads, [&](std::size_t k) {
    PointCloud pa = a.select(ca.at(valid[k]));
    PointCloud pb = b.select(cb.at(valid[k]));
    pa.cls.clear(), pa.session.clear(), pa.object.clear();
    pb.cls.clear(), pb.session.clear(), pb.object.clear();
    const auto sa = std::make_shared<const PointCloud>(std::move(pa));
    const auto sb = std::make_shared<const PointCloud>(std::move(pb));
    const geometry::KdTree ta(sa), tb(sb);
    const double ab = DirectedMean(*sa, tb, squared);
    const double ba = DirectedMean(*sb, ta, squared);
    cd[k] = squared ? ab + ba : 0.5 * (ab + ba);
  });
  double sum = 0.0, mx = 0.0;
  for (double v : cd) {
    sum += v;
    mx = std::max(mx, v);
    for (std::size_t t = 0; t < r.thresholds.size(); ++t)
      if (v > r.thresholds[t]) ++r.np_above[t];
  }
  r.mean = sum / double(cd.size());
  double var = 0.0;
  for (double v : cd) var += (v - r.mean) * (v - r.mean);
  r.variance = var / double(cd.size());
  r.max = mx;
  return r;
}

}  // namespace ltm::eval
