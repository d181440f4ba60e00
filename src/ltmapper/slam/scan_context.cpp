// Scan Context (Kim & Kim, IROS 2018): a rings x sectors egocentric height descriptor, a
// rotation-invariant ring key for retrieval, and a column-shift search for the yaw.
#include "ltmapper/slam/registration.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ltm::slam {

namespace {
constexpr double kTwoPi = 2.0 * M_PI;

ScanContext WithKeys(Eigen::MatrixXf desc) {
  ScanContext sc;
  sc.ring_key = desc.rowwise().mean();
  sc.sector_key = desc.colwise().mean().transpose();
  sc.desc = std::move(desc);
  return sc;
}

// Distance of a to b with b's columns shifted by `shift` (b column c compared with a column
// c + shift): 1 - mean cosine similarity over columns non-empty in both (original "distDirectSC").
double ShiftedDistance(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b, int shift) {
  const int cols = static_cast<int>(a.cols());
  double sum = 0.0;
  int used = 0;
  for (int c = 0; c < cols; ++c) {
    const int ca = ((c + shift) % cols + cols) % cols;
    const double na = a.col(ca).norm(), nb = b.col(c).norm();
    if (na == 0.0 || nb == 0.0) continue;
    sum += a.col(ca).dot(b.col(c)) / (na * nb);
    ++used;
  }
  return used == 0 ? 1.0 : 1.0 - sum / used;
}
}  // namespace

ScanContext MakeScanContext(const PointCloud& scan, const SlamConfig& cfg) {
  const int rings = cfg.sc_rings, sectors = cfg.sc_sectors;
  constexpr float kNoPoint = -std::numeric_limits<float>::infinity();
  Eigen::MatrixXf desc = Eigen::MatrixXf::Constant(rings, sectors, kNoPoint);
  const double ring_step = cfg.sc_max_range_m / rings;
  const double sector_step = kTwoPi / sectors;
  for (const auto& p : scan.points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    const double r = std::hypot(double(p.x), double(p.y));
    if (r >= cfg.sc_max_range_m) continue;
    double az = std::atan2(double(p.y), double(p.x));
    if (az < 0) az += kTwoPi;
    const int ring = std::min(rings - 1, static_cast<int>(r / ring_step));
    const int sector = std::min(sectors - 1, static_cast<int>(az / sector_step));
    // Height above the ground: the sensor sits sc_lidar_height_m above it.
    const float h = static_cast<float>(p.z + cfg.sc_lidar_height_m);
    float& bin = desc(ring, sector);
    bin = std::max(bin, h);
  }
  // Empty bins are 0 (as in the original code).
  desc = desc.unaryExpr([](float v) { return std::isinf(v) ? 0.f : v; });
  return WithKeys(std::move(desc));
}

ScanContext ScanContextFromMatrix(const Eigen::MatrixXd& desc) {
  return WithKeys(desc.cast<float>());
}

ScMatch CompareScanContexts(const ScanContext& a, const ScanContext& b, const SlamConfig& cfg) {
  ScMatch m;
  const int cols = static_cast<int>(a.desc.cols());
  if (a.desc.rows() != b.desc.rows() || a.desc.cols() != b.desc.cols() || cols == 0) {
    throw Error("Scan Context size mismatch: " + std::to_string(a.desc.rows()) + "x" +
                std::to_string(a.desc.cols()) + " vs " + std::to_string(b.desc.rows()) + "x" +
                std::to_string(b.desc.cols()));
  }
  // Coarse: the shift that best aligns the sector keys (column means).
  int coarse = 0;
  double best_key = std::numeric_limits<double>::infinity();
  for (int s = 0; s < cols; ++s) {
    double d = 0.0;
    for (int c = 0; c < cols; ++c) {
      const double diff = a.sector_key[(c + s) % cols] - b.sector_key[c];
      d += diff * diff;
    }
    if (d < best_key) {
      best_key = d;
      coarse = s;
    }
  }
  // Fine: full column-wise distance in a window around the coarse shift.
  const int radius = static_cast<int>(std::lround(0.5 * cfg.sc_search_ratio * cols));
  m.distance = std::numeric_limits<double>::infinity();
  for (int ds = -radius; ds <= radius; ++ds) {
    const int s = ((coarse + ds) % cols + cols) % cols;
    const double d = ShiftedDistance(a.desc, b.desc, s);
    if (d < m.distance) {
      m.distance = d;
      m.shift = s;
    }
  }
  // b column c = a column c + shift: azimuth_a = azimuth_b + shift * step, so p_a = Rz(yaw) p_b.
  double yaw = m.shift * kTwoPi / cols;
  if (yaw > M_PI) yaw -= kTwoPi;
  m.yaw_rad = yaw;
  return m;
}

}  // namespace ltm::slam
