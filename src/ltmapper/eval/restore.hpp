// ltmapper eval: the LT-mapper paper's restoration table (Chamfer distance over cubic patches)
// and class agreement.
#pragma once

#include "ltmapper/eval/config.hpp"

#include <string>
#include <vector>

namespace ltm::eval {

struct RestoreResult {
  double patch_m = 0.0;
  int min_points = 0;
  std::string chamfer;
  std::size_t points_a = 0, points_b = 0;
  std::size_t patches_a = 0, patches_b = 0, patches_both = 0;  // occupied patches
  std::size_t np_valid = 0;                // patches where both maps have >= min_points
  double max = kNaN, mean = kNaN, variance = kNaN;  // over valid patches (population variance)
  std::vector<double> thresholds;
  std::vector<std::size_t> np_above;       // valid patches with CD > thresholds[k]
  // Class agreement (both maps labelled, same_class_m > 0; else NaN): the share of A's points with
  // a B point of the same class within same_class_m, and the reverse.
  double same_class_m = 0.0;
  double same_class_a = kNaN, same_class_b = kNaN;
};
// Both maps in the same frame. Patches are the cells floor(p / patch_m) of one grid anchored at
// the origin. In a valid patch, d(A->B) is the mean over A's points of the distance to the
// nearest B point OF THE SAME PATCH, and CD = (d(A->B) + d(B->A)) / 2 [m] ("mean"), or the sum
// of the two directed means of squared distances [m^2] ("fan_squared", Fan et al. 2017).
RestoreResult EvaluateRestore(const PointCloud& a, const PointCloud& b, const EvalConfig& cfg,
                              int threads = 0);
// Share of `want`'s points with a point of `got` of the same class within radius_m (0 when want
// is empty). Both clouds must carry classes (cls), else ltm::Error.
double SameClassFraction(const PointCloud& want, const PointCloud& got, double radius_m, int threads = 0);

}  // namespace ltm::eval
