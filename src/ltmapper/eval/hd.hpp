// ltmapper eval: HD removal scores (SA / DA / AA, KTH DynamicMap benchmark rule).
#pragma once

#include "ltmapper/eval/config.hpp"

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace ltm::eval {

struct ClassCount {
  std::string name;         // "static", "hd", "ld:<object class>", "unknown"
  std::size_t total = 0;
  std::size_t preserved = 0;
};
struct HdResult {
  double match_dist_m = 0.0;
  std::size_t output_points = 0;
  std::size_t static_total = 0, static_preserved = 0;
  std::size_t dynamic_total = 0, dynamic_removed = 0;
  // HD points farther than hd_near_static_m from every static truth point (when a static
  // reference was given): DA over those alone.
  bool separable_given = false;
  std::size_t separable_total = 0, separable_removed = 0;
  double da_separable = kNaN;
  std::size_t ignored = 0;  // truth points of class unknown or beyond hd_truth_max_range_m
  double sa = kNaN, da = kNaN, aa = kNaN;  // SA = preserved static / static, DA = removed HD / HD
  std::vector<ClassCount> classes;         // sorted: static, ld:*, hd, unknown
};

// KTH DynamicMap benchmark rule: every truth point (PointCloud::cls: kStatic or kHD, world frame
// of the output) is matched to the nearest output point; within hd_match_dist_m it is preserved,
// else removed. The output map is usually voxel-downsampled: with voxel v a truth point of an
// occupied voxel lies within v*sqrt(3) of the voxel's centroid and typically within ~v/2, so
// choose hd_match_dist_m around v (a larger distance lets HD points next to kept static points
// count as preserved, lowering DA). Feeding truth in pieces (Add) gives the same counts as one
// big cloud, so the raw map of a long session never has to be held in memory.
class HdEvaluator {
 public:
  // object_classes: LD object id -> class name, for the per-class rows (optional).
  HdEvaluator(PointCloud output, const EvalConfig& cfg,
              std::map<int, std::string> object_classes = {}, int threads = 0);
  ~HdEvaluator();
  HdEvaluator(const HdEvaluator&) = delete;
  HdEvaluator& operator=(const HdEvaluator&) = delete;
  // Truth points with labels (cls required; object optional: -1 / absent = permanent static).
  // `sensor` is where the points were observed from (for hd_truth_max_range_m).
  void Add(const PointCloud& truth, const Eigen::Vector3d& sensor = Eigen::Vector3d::Zero());
  // Static truth points (world frame of the output) for the "hd near static" split; call before Add.
  void SetStaticReference(PointCloud static_truth);
  HdResult Result() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
HdResult EvaluateHd(const PointCloud& truth, const PointCloud& output, const EvalConfig& cfg,
                    const std::map<int, std::string>& object_classes = {}, int threads = 0);

}  // namespace ltm::eval
