// Loop verification by registration: Generalized-ICP (Segal et al. 2009; our Gauss-Newton
// solver, gicp.cpp) between two downsampled clouds, then three gates:
//  1. overlap: the share of source points with a target neighbour within the inlier radius
//     (half a voxel diagonal plus 3 sigma of both clouds' range noise) >= registration.min_overlap;
//  2. surfaces agree: each inlier's residual along the target's local normal, over the variance
//     the surfaces themselves explain (both neighbourhoods' spread along their normals plus the
//     range noise of both clouds), z = e^2 / var, averages at most 1, its expectation;
//  3. nothing crosses: no more inliers beyond 3 sigma (z > 9) than a Gaussian leaves (0.27 %) plus
//     3 binomial standard deviations for the inlier count. A registration slid along a street
//     keeps facades and ground on their planes (gate 2 passes) but moves poles, trunks and
//     corners across their surfaces: a tail of 2-10 % of the inliers; true loops keep it at
//     0-0.3 % on every simulated sensor and on KITTI.
// Both plane gates follow the sensor's sampling: a point-to-point distance grows with the gaps
// between a sparse LiDAR's rings, a distance along the surface normal does not.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/slam/internal.hpp"
#include "ltmapper/slam/registration.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

namespace ltm::slam {

namespace {
// Half the diagonal of a voxel: a point of a surface lies at most this far (in units of the
// voxel) from the centroid of its voxel, so a correctly placed source centroid finds a target
// centroid of the same surface within it.
const double kHalfVoxelDiagonal = std::sqrt(3.0) / 2.0;
// Gaussian gate on the range noise: 3 sigma keeps 99.7 % of correctly placed points.
constexpr double kNoiseSigmas = 3.0;
// Plane gates: z = e^2 / var averages 1 for Gaussian residuals; beyond 3 sigma (z > 9) lie 0.27 %.
constexpr double kMaxMeanPlaneZ = 1.0;
constexpr double kTailSigmas = 3.0;
constexpr double kGaussianTail = 0.0027;  // P(|x| > 3 sigma), two-sided
// The coarse stage's early rejection asks for this fraction of reg_min_overlap: at the coarse
// voxel, before the fine stage, a true match overlaps at least half as well as at the end.
constexpr double kCoarseOverlapFraction = 0.5;
// ViewShare's direction bins: coarser than the widest gap between a sensor's directions (a VLP-16's
// 2 deg between beams, a rosette's petals), so a bin inside the field of view holds a return, and
// fine enough to draw a forward cone's edge.
constexpr double kViewBinDeg = 5.0;
}  // namespace

double InlierRadius(double voxel_m, double range_noise_m) {
  // Both clouds carry range noise: the difference of two samples has std-dev sqrt(2) sigma.
  return kHalfVoxelDiagonal * voxel_m + kNoiseSigmas * std::sqrt(2.0) * range_noise_m;
}

namespace {
struct Inliers {
  double ratio = 0.0, rms = 1e9;
  double plane_z = 1e9;  // mean of z = (residual along the target normal)^2 / explained variance
  double tail = 1.0;     // share of the planar inliers with z > kTailSigmas^2
  std::size_t planar = 0;
  Matrix6d fisher = Matrix6d::Zero();  // sum J^T J / var of the planar inliers (PoseFisher)
};

// One planar inlier's row of d(residual along the target normal) / d(pose), for a perturbation
// T exp(delta) on the source side, delta = (translation, rotation) as the pose graph's residuals:
// T exp(delta) s = T s + R (rho - [s]x omega), so the row is -[m^T, (s x m)^T] with m = R^T n
// (the normal in the source frame); the sign cancels in J^T J.
Vector6d PlaneRow(const Eigen::Matrix3d& R, const Eigen::Vector3d& n, const Eigen::Vector3d& s) {
  const Eigen::Vector3d m = R.transpose() * n;
  Vector6d row;
  row << m, s.cross(m);
  return row;
}

// The share of `source` under T with a target point within `radius` (the coarse stage's and
// OverlapRatio's measure: no plane is computed for it).
double OverlapWithin(const GicpCloud& target, const PointCloud& source, const Pose& T, double radius) {
  if (source.empty()) return 0.0;
  std::size_t inside = 0;
  for (const auto& p : source.points) {
    std::uint32_t j = 0;
    float d2 = 0.f;
    inside += target.tree->Nearest((T * p.xyz().cast<double>()).cast<float>(), &j, &d2) && d2 <= radius * radius;
  }
  return double(inside) / double(source.size());
}

// Overlap, RMS and the plane statistics of `source` under T against the target.
Inliers CountInliers(const GicpCloud& target, const GicpCloud& source, const Pose& T, double radius,
                     double range_noise_m) {
  const double noise_var = 2.0 * range_noise_m * range_noise_m;  // both clouds
  const double tail_z = kTailSigmas * kTailSigmas;
  double sum = 0.0, z_sum = 0.0;
  std::size_t inside = 0, tail = 0;
  Inliers in;
  const PointCloud& src = source.cloud();
  for (std::size_t i = 0; i < src.size(); ++i) {
    const Eigen::Vector3d q = T * src.points[i].xyz().cast<double>();
    std::uint32_t j = 0;
    float d2 = 0.f;
    if (!target.tree->Nearest(q.cast<float>(), &j, &d2) || d2 > radius * radius) continue;
    sum += d2;
    ++inside;
    const GicpCloud::Plane& pt = target.PlaneAt(j);
    if (pt.normal.isZero()) continue;  // too few neighbours for a surface
    const double e = pt.normal.dot(q - target.cloud().points[j].xyz().cast<double>());
    const double var = pt.spread + source.PlaneAt(i).spread + noise_var;
    const double z = e * e / var;
    const Vector6d row = PlaneRow(T.linear(), pt.normal, src.points[i].xyz().cast<double>());
    in.fisher += row * row.transpose() / var;
    z_sum += z;
    tail += z > tail_z;
    ++in.planar;
  }
  if (src.empty()) return in;
  in.ratio = double(inside) / double(src.size());
  if (inside > 0) in.rms = std::sqrt(sum / double(inside));
  // Neighbouring residuals are not independent: each normal comes from the point's k nearest
  // neighbours, so about one in k residuals carries new information.
  in.fisher /= double(source.neighbours());
  if (in.planar > 0) {
    in.plane_z = z_sum / double(in.planar);
    in.tail = double(tail) / double(in.planar);
  }
  return in;
}

// The tail the Gaussian model allows for n inliers: its share plus 3 binomial standard deviations.
double TailBound(std::size_t n) {
  return kGaussianTail + kTailSigmas * std::sqrt(kGaussianTail * (1.0 - kGaussianTail) / double(std::max<std::size_t>(n, 1)));
}

// One GICP run from `guess` (updated in place); returns whether it converged.
bool RunGicp(const GicpCloud& t, const GicpCloud& s, double max_corr, const SlamConfig& cfg, Pose& guess) {
  GicpOptions opt;
  opt.max_correspondence_m = max_corr;
  opt.max_iterations = cfg.reg_max_iterations;
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
  const GicpCloud tcp(tc, cfg.reg_covariance_neighbours), scp(sc, cfg.reg_covariance_neighbours);
  RunGicp(tcp, scp, cfg.reg_coarse_correspondence_m, cfg, guess);
  const double radius = InlierRadius(cfg.reg_coarse_voxel_m, cfg.reg_range_noise_m);
  *coarse_overlap = OverlapWithin(tcp, sc, guess, radius);
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
  } else if (r.plane_z > kMaxMeanPlaneZ) {
    why << "surfaces disagree: mean plane residual z " << r.plane_z << " > " << kMaxMeanPlaneZ;
  } else if (r.plane_tail > r.plane_tail_bound) {
    why << "surfaces cross: " << 100.0 * r.plane_tail << " % of the inliers beyond 3 sigma > "
        << 100.0 * r.plane_tail_bound << " %";
  } else if (corr_deg > cfg.reg_max_correction_deg) {
    why << "rotation correction " << corr_deg << " deg > " << cfg.reg_max_correction_deg;
  } else if (corr_m > cfg.reg_max_translation_m) {
    why << "translation correction " << corr_m << " m > " << cfg.reg_max_translation_m;
  }
  return why.str();
}
}  // namespace

double OverlapRatio(const GicpCloud& target, const PointCloud& source, const Pose& T_target_source,
                    const SlamConfig& cfg) {
  return OverlapWithin(target, source, T_target_source, InlierRadius(cfg.reg_voxel_m, cfg.reg_range_noise_m));
}

double ViewShare(const PointCloud& target, const PointCloud& source, const Pose& T_target_source, double slack_m) {
  // The whole sphere in kViewBinDeg bins; a bin's farthest target return, -1 without one.
  geometry::RangeImageConfig bins;
  bins.fov_up_deg = 90.0;
  bins.fov_down_deg = -90.0;
  bins.rows = int(180.0 / kViewBinDeg);
  bins.cols = int(360.0 / kViewBinDeg);
  const geometry::RangeImage sphere(bins);
  std::vector<float> farthest(std::size_t(bins.rows * bins.cols), -1.f);
  const auto at = [&](const Eigen::Vector3f& p, float* range) -> float* {
    int row = 0, col = 0;
    return sphere.Project(p, &row, &col, range) ? &farthest[std::size_t(row * bins.cols + col)] : nullptr;
  };
  float r = 0.f;
  for (const auto& p : target.points)
    if (float* f = at(p.xyz(), &r)) *f = std::max(*f, r);
  if (source.empty()) return 0.0;
  const Eigen::Isometry3f T = T_target_source.cast<float>();
  std::size_t seen = 0;
  for (const auto& p : source.points) {
    const float* f = at(T * p.xyz(), &r);
    seen += f && r <= *f + float(slack_m);
  }
  return double(seen) / double(source.size());
}

double WidestBlindArcDeg(const PointCloud& scan) {
  const int bins = int(360.0 / kViewBinDeg);
  std::vector<bool> hit(std::size_t(bins), false);
  for (const auto& p : scan.points) {
    if (p.x == 0.f && p.y == 0.f) continue;
    const double az = std::atan2(double(p.y), double(p.x)) * 180.0 / M_PI + 180.0;  // [0, 360]
    hit[std::size_t(std::min(bins - 1, int(az / kViewBinDeg)))] = true;
  }
  int widest = 0, run = 0;  // empty bins in a row, twice round the circle for a run through 0 deg
  for (int i = 0; i < 2 * bins; ++i) {
    run = hit[std::size_t(i % bins)] ? 0 : run + 1;
    widest = std::max(widest, run);
  }
  return std::min(widest, bins) * kViewBinDeg;
}

PointCloud OffTheGround(const PointCloud& cloud, const Eigen::Vector3d& up, const SlamConfig& cfg) {
  const PointCloud levelled =
      geometry::Transform(cloud, Pose(Eigen::Quaterniond::FromTwoVectors(up.normalized(), Eigen::Vector3d::UnitZ())));
  geometry::LowestGrid lowest(2.0 * cfg.reg_voxel_m);
  lowest.Add(levelled);
  std::vector<bool> keep(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    float z = 0.f;
    keep[i] = !lowest.At(levelled.points[i].xyz(), &z) || levelled.points[i].z > z + cfg.reg_voxel_m;
  }
  return cloud.select(keep);
}

bool Registrable(std::size_t points, const SlamConfig& cfg) {
  return points > static_cast<std::size_t>(cfg.reg_covariance_neighbours);
}

namespace {
// Why clouds of these sizes cannot be registered (empty when they can): Registrable.
std::string TooFewPoints(std::size_t target, std::size_t source, const SlamConfig& cfg) {
  if (Registrable(target, cfg) && Registrable(source, cfg)) return {};
  return "too few points for registration (" + std::to_string(target) + " / " + std::to_string(source) + ")";
}

// The fine stage from `guess`, and the gates' measures with its final pose.
RegistrationResult FineStage(const GicpCloud& tgt, const GicpCloud& src, Pose guess, const Pose& T_target_source_init,
                             const SlamConfig& cfg) {
  RegistrationResult r;
  r.converged = RunGicp(tgt, src, cfg.reg_max_correspondence_m, cfg, guess);
  r.T_target_source = Pose::Identity();
  r.T_target_source.linear() = Eigen::Quaterniond(guess.linear()).normalized().toRotationMatrix();
  r.T_target_source.translation() = guess.translation();
  r.inlier_radius_m = InlierRadius(cfg.reg_voxel_m, cfg.reg_range_noise_m);
  const Inliers in = CountInliers(tgt, src, r.T_target_source, r.inlier_radius_m, cfg.reg_range_noise_m);
  r.overlap = in.ratio;
  r.inlier_rms_m = in.rms;
  r.plane_z = in.plane_z;
  r.plane_tail = in.tail;
  r.plane_tail_bound = TailBound(in.planar);
  r.fisher = in.fisher;
  r.fitness = in.ratio > 0.0 ? in.rms * in.rms : 1e9;
  r.reason = Verdict(r, T_target_source_init, cfg);
  r.accepted = r.reason.empty();
  return r;
}
}  // namespace

RegistrationResult RegisterGicp(const PointCloud& target, const PointCloud& source,
                                const Pose& T_target_source_init, const SlamConfig& cfg) {
  RegistrationResult r;
  r.reason = TooFewPoints(target.size(), source.size(), cfg);
  if (!r.reason.empty()) return r;
  Pose guess = T_target_source_init;
  if (cfg.reg_coarse_correspondence_m > 0.0) {
    r.reason = CoarseStage(target, source, cfg, guess, &r.overlap);
    if (!r.reason.empty()) return r;
  }
  const GicpCloud tgt(target, cfg.reg_covariance_neighbours), src(source, cfg.reg_covariance_neighbours);
  return FineStage(tgt, src, guess, T_target_source_init, cfg);
}

RegistrationResult RegisterGicp(const GicpCloud& target, const GicpCloud& source, const Pose& T_target_source_init,
                                const SlamConfig& cfg) {
  if (cfg.reg_coarse_correspondence_m > 0.0)
    throw Error("RegisterGicp on prepared clouds is the fine stage alone: registration.coarse_correspondence_m must be 0");
  RegistrationResult r;
  r.reason = TooFewPoints(target.cloud().size(), source.cloud().size(), cfg);
  if (!r.reason.empty()) return r;
  return FineStage(target, source, T_target_source_init, T_target_source_init, cfg);
}

}  // namespace ltm::slam
