// Spherical range image (see geometry.hpp for the pixel rule). Build() is the hot loop of HD
// removal: constants are precomputed in the constructor, the loop is allocation-free and uses
// float trigonometry.
#include "ltmapper/geometry/geometry.hpp"

#include <cmath>
#include <limits>
#include <string>

namespace ltm::geometry {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr float kPiF = 3.14159265358979323846f;
constexpr float kMinRange = 1e-6f;  // [m] points closer than this have no direction
}  // namespace

RangeImage::RangeImage(const RangeImageConfig& cfg) : cfg_(cfg) {
  if (cfg.rows < 1 || cfg.cols < 1)
    throw Error("RangeImage: rows and cols must be >= 1, got " + std::to_string(cfg.rows) + " x " +
                std::to_string(cfg.cols));
  if (!(cfg.fov_up_deg > cfg.fov_down_deg) || cfg.fov_up_deg > 90.0 || cfg.fov_down_deg < -90.0)
    throw Error("RangeImage: need -90 <= fov_down_deg < fov_up_deg <= 90, got " +
                std::to_string(cfg.fov_down_deg) + " .. " + std::to_string(cfg.fov_up_deg));
  up_rad_ = cfg.fov_up_deg * kPi / 180.0;
  down_rad_ = cfg.fov_down_deg * kPi / 180.0;
  fov_rad_ = up_rad_ - down_rad_;
  up_f_ = static_cast<float>(up_rad_);
  down_f_ = static_cast<float>(down_rad_);
  row_scale_ = static_cast<float>(cfg.rows / fov_rad_);
  col_scale_ = static_cast<float>(cfg.cols / (2.0 * kPi));
  range_.assign(std::size_t(cfg.rows) * cfg.cols, std::numeric_limits<float>::infinity());
  index_.assign(range_.size(), -1);
}

bool RangeImage::Project(const Eigen::Vector3f& p, int* row, int* col, float* range) const {
  const float r = std::sqrt(p.x() * p.x() + p.y() * p.y() + p.z() * p.z());
  if (!(r > kMinRange)) return false;  // also rejects NaN
  const float pitch = std::asin(std::min(1.f, std::max(-1.f, p.z() / r)));
  if (pitch > up_f_ || pitch < down_f_) return false;
  int rw = static_cast<int>((up_f_ - pitch) * row_scale_);  // >= 0, so truncation = floor
  if (rw >= cfg_.rows) rw = cfg_.rows - 1;                  // exactly on the lower edge
  const float yaw = std::atan2(p.y(), p.x());               // [-pi, pi]
  int cl = static_cast<int>((kPiF - yaw) * col_scale_);     // [0, cols]
  if (cl >= cfg_.cols) cl -= cfg_.cols;                     // yaw = -pi is the same as +pi
  if (cl < 0) cl = 0;
  *row = rw;
  *col = cl;
  *range = r;
  return true;
}

void RangeImage::Build(const PointCloud& cloud) {
  const std::size_t n_pix = std::size_t(cfg_.rows) * cfg_.cols;
  range_.assign(n_pix, std::numeric_limits<float>::infinity());
  index_.assign(n_pix, -1);
  if (cloud.size() > std::size_t(std::numeric_limits<int>::max()))
    throw Error("RangeImage::Build: more than 2^31 - 1 points");
  float* rng = range_.data();
  int* idx = index_.data();
  const int n = static_cast<int>(cloud.size());
  for (int i = 0; i < n; ++i) {
    const PointXYZI& q = cloud.points[std::size_t(i)];
    int row, col;
    float r;
    if (!Project(Eigen::Vector3f(q.x, q.y, q.z), &row, &col, &r)) continue;
    const std::size_t k = std::size_t(row) * cfg_.cols + col;
    if (r < rng[k]) {
      rng[k] = r;
      idx[k] = i;
    }
  }
}

}  // namespace ltm::geometry
