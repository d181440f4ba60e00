// Loop verification by registration: Generalized-ICP (Segal et al. 2009; our Gauss-Newton
// solver, gicp.cpp) between two downsampled clouds, scored by the inlier ratio (source points with a target neighbour within
// an inlier radius) and the RMS distance of those inliers, both gates derived from the voxel
// size and the sensor's range noise (InlierRadius, InlierRmsBound).
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/internal.hpp"

#include <cmath>
#include <sstream>

namespace ltm::slam {

namespace {
// Half the diagonal of a voxel: a point of a surface lies at most this far (in units of the
// voxel) from the centroid of its voxel, so a correctly placed source centroid finds a target
// centroid of the same surface within it.
const double kHalfVoxelDiagonal = std::sqrt(3.0) / 2.0;
// Gaussian gate on the range noise: 3 sigma keeps 99.7 % of correctly placed points.
constexpr double kNoiseSigmas = 3.0;
// Uniform offset within a voxel along each axis: variance v^2 / 12 per axis, three axes.
constexpr double kUniformVariance = 1.0 / 12.0;
constexpr double kAxes = 3.0;
// The coarse stage's early rejection asks for this fraction of reg_min_overlap: at the coarse
// voxel, before the fine stage, a true match overlaps at least half as well as at the end.
constexpr double kCoarseOverlapFraction = 0.5;
// GICP stops when a Gauss-Newton step rotates less than this and moves less than this: far
// below the verification's voxel-sized gates.
constexpr double kConvergedRotationRad = 1e-5;
constexpr double kConvergedTranslationM = 1e-5;
}  // namespace

double InlierRadius(double voxel_m, double range_noise_m) {
  // Both clouds carry range noise: the difference of two samples has std-dev sqrt(2) sigma.
  return kHalfVoxelDiagonal * voxel_m + kNoiseSigmas * std::sqrt(2.0) * range_noise_m;
}

double InlierRmsBound(double voxel_m, double range_noise_m) {
  // A correctly placed source centroid lies, at worst, anywhere in the voxel of the target
  // centroid it matches: a uniform offset on each of the three axes (variance v^2 / 12 each, an
  // RMS of v / 2); the range noise of both clouds adds 2 sigma^2. (On a plane the offset has two
  // axes only, v / sqrt(6): true loops measure between the two.)
  return std::sqrt(kAxes * kUniformVariance * voxel_m * voxel_m +
                   2.0 * range_noise_m * range_noise_m);
}

namespace {
struct Inliers {
  double ratio = 0.0, rms = 1e9;
};

// Inlier ratio and RMS of `source` under T against a kd-tree of the target.
Inliers CountInliers(const geometry::KdTree& tree, const PointCloud& source, const Pose& T, double radius) {
  double sum = 0.0;
  std::size_t inside = 0;
  for (const auto& p : source.points) {
    const Eigen::Vector3d q = T * p.xyz().cast<double>();
    std::uint32_t j = 0;
    float d2 = 0.f;
    if (!tree.Nearest(q.cast<float>(), &j, &d2) || d2 > radius * radius) continue;
    sum += d2;
    ++inside;
  }
  Inliers in;
  if (source.empty()) return in;
  in.ratio = double(inside) / double(source.size());
  if (inside > 0) in.rms = std::sqrt(sum / double(inside));
  return in;
}

// One GICP run from `guess` (updated in place); returns whether it converged.
bool RunGicp(const GicpCloud& t, const GicpCloud& s, double max_corr, const SlamConfig& cfg, Pose& guess) {
  GicpOptions opt;
  opt.max_correspondence_m = max_corr;
  opt.max_iterations = cfg.reg_max_iterations;
  opt.converged_rotation_rad = kConvergedRotationRad;
  opt.converged_translation_m = kConvergedTranslationM;
  const GicpResult g = AlignGicp(t, s, guess, opt);
  guess = g.T;
  return g.converged;
}

// Coarse stage (the initial translation may be metres off); returns an empty string or why the
// candidate is rejected early (saves the fine stage for wrong places).
std::string CoarseStage(const PointCloud& target, const PointCloud& source, const SlamConfig& cfg,
                        Pose& guess, double* coarse_overlap) {
  const std::size_t min_points = static_cast<std::size_t>(cfg.reg_covariance_neighbours) + 1;
  const PointCloud tc = geometry::VoxelDownsample(target, cfg.reg_coarse_voxel_m, 1);
  const PointCloud sc = geometry::VoxelDownsample(source, cfg.reg_coarse_voxel_m, 1);
  if (tc.size() < min_points || sc.size() < min_points) return {};
  const GicpCloud tcp(tc, cfg.reg_covariance_neighbours);
  RunGicp(tcp, GicpCloud(sc, cfg.reg_covariance_neighbours), cfg.reg_coarse_correspondence_m, cfg, guess);
  const double radius = InlierRadius(cfg.reg_coarse_voxel_m, cfg.reg_range_noise_m);
  *coarse_overlap = CountInliers(*tcp.tree, sc, guess, radius).ratio;
  const double need = kCoarseOverlapFraction * cfg.reg_min_overlap;
  if (*coarse_overlap >= need) return {};
  std::ostringstream why;
  why.precision(3);
  why << "coarse stage overlap " << *coarse_overlap << " < " << need;
  return why.str();
}

// Why a registered candidate is not accepted (empty when it is).
std::string Verdict(const RegistrationResult& r, const Pose& T_init, const SlamConfig& cfg) {
  const Pose delta = T_init.inverse() * r.T_target_source;
  const double corr_deg = Eigen::AngleAxisd(delta.linear()).angle() * 180.0 / M_PI;
  const double corr_m = delta.translation().norm();
  std::ostringstream why;
  why.precision(3);
  if (!r.converged) {
    why << "GICP did not converge";
  } else if (r.overlap < cfg.reg_min_overlap) {
    why << "inlier ratio " << r.overlap << " < " << cfg.reg_min_overlap << " (radius "
        << r.inlier_radius_m << " m)";
  } else if (r.inlier_rms_m > r.rms_bound_m) {
    why << "inlier RMS " << r.inlier_rms_m << " m > " << r.rms_bound_m << " m";
  } else if (corr_deg > cfg.reg_max_correction_deg) {
    why << "rotation correction " << corr_deg << " deg > " << cfg.reg_max_correction_deg;
  } else if (corr_m > cfg.reg_max_translation_m) {
    why << "translation correction " << corr_m << " m > " << cfg.reg_max_translation_m;
  }
  return why.str();
}
}  // namespace

RegistrationResult RegisterGicp(const PointCloud& target, const PointCloud& source,
                                const Pose& T_target_source_init, const SlamConfig& cfg) {
  RegistrationResult r;
  const std::size_t min_points = static_cast<std::size_t>(cfg.reg_covariance_neighbours) + 1;
  if (target.size() < min_points || source.size() < min_points) {
    r.reason = "too few points for registration (" + std::to_string(target.size()) + " / " +
               std::to_string(source.size()) + ")";
    return r;
  }
  Pose guess = T_target_source_init;
  if (cfg.reg_coarse_correspondence_m > 0.0) {
    r.reason = CoarseStage(target, source, cfg, guess, &r.overlap);
    if (!r.reason.empty()) return r;
  }
  const GicpCloud tgt(target, cfg.reg_covariance_neighbours);
  r.converged = RunGicp(tgt, GicpCloud(source, cfg.reg_covariance_neighbours), cfg.reg_max_correspondence_m, cfg, guess);
  r.T_target_source = Pose::Identity();
  r.T_target_source.linear() = Eigen::Quaterniond(guess.linear()).normalized().toRotationMatrix();
  r.T_target_source.translation() = guess.translation();

  // Inlier ratio and RMS with the final pose.
  r.inlier_radius_m = InlierRadius(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  r.rms_bound_m = InlierRmsBound(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  const Inliers in = CountInliers(*tgt.tree, source, r.T_target_source, r.inlier_radius_m);
  r.overlap = in.ratio;
  r.inlier_rms_m = in.rms;
  r.fitness = in.ratio > 0.0 ? in.rms * in.rms : 1e9;
  r.reason = Verdict(r, T_target_source_init, cfg);
  r.accepted = r.reason.empty();
  return r;
}

}  // namespace ltm::slam
