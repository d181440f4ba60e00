// Visibility votes: the hot loop shared by HD removal (map vs own scans), weak/strong ND (central
// ND points vs query scans) and weak/strong PD (query PD points vs central scans).
//
// Per keyframe: its scan's range images (one set per worker, rebuilt in place), then for every
// tile of points within the submap radius: projection of the tile's points (four at a time),
// their votes per level into the worker's scratch, and those added to the tile's counters under
// the tile's lock. The SSE2 code repeats the scalar code's float operations in the same order,
// so the votes are the same with or without it.
#include "ltmapper/removert/detail.hpp"

#include "ltmapper/io/io.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>
#include <utility>

namespace ltm::removert {
namespace detail {

MultiResImage::Grid MultiResImage::Grid::Make(const RemovertConfig& cfg, double row_deg, double col_deg) {
  constexpr double kPi = 3.14159265358979323846;
  Grid g;
  g.rows = std::max(1, int(std::ceil((cfg.fov_up_deg - cfg.fov_down_deg) / row_deg - 1e-9)));
  g.cols = std::max(1, int(std::lround(360.0 / col_deg)));
  g.row_scale = float(g.rows / ((cfg.fov_up_deg - cfg.fov_down_deg) * kRadPerDeg));
  g.col_scale = float(g.cols / (2.0 * kPi));
  g.up = float(cfg.fov_up_deg * kRadPerDeg);  // = MultiResImage::up_, which Angles() checks
  return g;
}

geometry::RangeImageConfig LevelConfig(const RemovertConfig& cfg, double pixel_deg) {
  const MultiResImage::Grid g = MultiResImage::Grid::Make(cfg, pixel_deg, pixel_deg);
  geometry::RangeImageConfig c;
  c.fov_up_deg = cfg.fov_up_deg;
  c.fov_down_deg = cfg.fov_down_deg;
  c.rows = g.rows;
  c.cols = g.cols;
  return c;
}

namespace {

#if defined(__SSE2__)
// Four-lane twins of FastAtan2 and MultiResImage::Angles. Each lane performs the scalar code's
// IEEE float operations in the same order (no FMA contraction in SSE; sqrt and division are
// correctly rounded in both) and branches become selects, so every lane is bit-identical to the
// scalar result: pixels, and so votes, do not depend on the code path.
inline __m128 Select(__m128 mask, __m128 a, __m128 b) {
  return _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b));
}

inline __m128 FastAtan2x4(__m128 y, __m128 x) {
  const __m128 sign = _mm_set1_ps(-0.f);
  const __m128 zero = _mm_setzero_ps();
  const __m128 ax = _mm_andnot_ps(sign, x), ay = _mm_andnot_ps(sign, y);
  const __m128 x_major = _mm_cmpgt_ps(ax, ay);
  const __m128 mx = Select(x_major, ax, ay);
  const __m128 mn = Select(x_major, ay, ax);
  const __m128 a = _mm_div_ps(mn, mx);  // 0 / 0 where mx == 0: replaced by 0 below
  const __m128 s = _mm_mul_ps(a, a);
  __m128 r = _mm_sub_ps(_mm_mul_ps(_mm_set1_ps(0.0208351f), s), _mm_set1_ps(0.085133f));
  r = _mm_add_ps(_mm_mul_ps(r, s), _mm_set1_ps(0.180141f));
  r = _mm_sub_ps(_mm_mul_ps(r, s), _mm_set1_ps(0.3302995f));
  r = _mm_add_ps(_mm_mul_ps(r, s), _mm_set1_ps(0.999866f));
  r = _mm_mul_ps(r, a);
  r = Select(_mm_cmpgt_ps(ay, ax), _mm_sub_ps(_mm_set1_ps(0.5f * kPiF), r), r);
  r = Select(_mm_cmplt_ps(x, zero), _mm_sub_ps(_mm_set1_ps(kPiF), r), r);
  r = Select(_mm_cmplt_ps(y, zero), _mm_xor_ps(r, sign), r);
  return _mm_andnot_ps(_mm_cmpeq_ps(mx, zero), r);
}

// MultiResImage::Angles of four points: the mask of the valid lanes.
inline __m128 Angles4(__m128 x, __m128 y, __m128 z, __m128 up, __m128 down, __m128* range,
                      __m128* pitch, __m128* yaw) {
  const __m128 rxy2 = _mm_add_ps(_mm_mul_ps(x, x), _mm_mul_ps(y, y));
  const __m128 r = _mm_sqrt_ps(_mm_add_ps(rxy2, _mm_mul_ps(z, z)));
  const __m128 pt = FastAtan2x4(z, _mm_sqrt_ps(rxy2));
  const __m128 ok = _mm_cmpgt_ps(r, _mm_set1_ps(1e-6f));
  const __m128 out_of_fov = _mm_or_ps(_mm_cmpgt_ps(pt, up), _mm_cmplt_ps(pt, down));
  *range = r;
  *pitch = pt;
  *yaw = FastAtan2x4(y, x);
  return _mm_andnot_ps(out_of_fov, ok);
}

// Angles of the four scan points from index i (PointXYZI: four packed floats, transposed to x /
// y / z lanes): the mask of those inside the FOV and [min_range, max_range].
struct ScanBounds4 {
  __m128 up, down, min_range, max_range;
};
inline int ScanAngles4(const PointCloud& scan, std::size_t i, const ScanBounds4& bd, __m128* r, __m128* pt,
                       __m128* yw) {
  static_assert(sizeof(PointXYZI) == 4 * sizeof(float) && offsetof(PointXYZI, x) == 0,
                "PointXYZI must be x y z intensity floats");
  const float* raw = reinterpret_cast<const float*>(scan.points.data()) + 4 * i;
  __m128 px = _mm_loadu_ps(raw), py = _mm_loadu_ps(raw + 4);
  __m128 pz = _mm_loadu_ps(raw + 8), pi = _mm_loadu_ps(raw + 12);
  _MM_TRANSPOSE4_PS(px, py, pz, pi);
  const __m128 ok = Angles4(px, py, pz, bd.up, bd.down, r, pt, yw);
  const __m128 out_of_range = _mm_or_ps(_mm_cmplt_ps(*r, bd.min_range), _mm_cmpgt_ps(*r, bd.max_range));
  return _mm_movemask_ps(_mm_andnot_ps(out_of_range, ok));
}
#endif

// Votes of one tile's valid points at one level (see CountVisibility): kSee, kHit, kOcc or 0 at
// vote[idx[j]]. Both lookups of a point come from one (pooled, range) pixel pair. The SSE2 path
// takes four points at a time without branches (the tests mispredict often, and a mispredict
// also cancels the next points' lookups in flight) with the scalar code's float operations.
// Surface hits (normals given) need the points' planes in the sensor frame and the image's
// nearest return per pixel (MultiResImage keep_returns).
constexpr std::uint8_t kSee = 1, kHit = 2, kOcc = 4, kSeeOwn = 8;
struct VoteTest {
  float tol_abs = 0.f, tol_rel = 0.f;
  float surface_max = 0.f;    // [m] cap of the surface-hit range difference
  std::uint8_t occluded = 0;  // kOcc when occluded points are counted, else 0
  std::uint8_t see_own = 0;   // kSeeOwn when the own pixel's see-through is counted, else 0
  // The own pixel's beam passed the point when the pixel's half size at the point's range is
  // within this tolerance (the beam test's BeamTest tol_m, plus RemovertConfig::LdOwnTolRel times
  // the range): a pixel wider than that holds rays that went past beside or above the point, no
  // sign its place was free.
  float own_tol_abs = std::numeric_limits<float>::infinity(), own_tol_rel = 0.f;
  float own_max_range = std::numeric_limits<float>::infinity();  // [m] per level (OwnReach)
  float yaw_sigma = 0.f;      // [rad] the poses' angular uncertainty: the window is also read at yaw -+ it
  bool yaw_needs_own = false; // no rings: read at yaw -+ yaw_sigma only where the point's own window has evidence
};
// How far the own pixel's see-through counts at this level: where half the pixel's larger side,
// seen from the sensor, spans at most the own-pixel tolerance: r h <= own_tol_abs + own_tol_rel r.
inline float OwnReach(const MultiResImage::Grid& grid, const VoteTest& t) {
  const float h = 0.5f / std::min(grid.row_scale, grid.col_scale);  // [rad]
  if (!std::isfinite(t.own_tol_abs) || h <= t.own_tol_rel) return std::numeric_limits<float>::infinity();
  return t.own_tol_abs / (h - t.own_tol_rel);
}
// Surface hit: the pixel's nearest return q lies on the point's plane (n . q = off, sensor
// frame) within the tolerance, at most surface_max from the point in range. Far ground at a
// grazing angle is sampled by rings metres apart in range, so the plain range test misses it;
// an occluder in front of the point (a wall, a car) is off its plane.
// Distance of q from the plane n . x = off (plane[0..3]).
inline float PlaneDistance(const float* plane, const Eigen::Vector3f& q) {
  return std::fabs(plane[0] * q.x() + plane[1] * q.y() + plane[2] * q.z() - plane[3]);
}
inline bool OnPlane(const float* plane, const Eigen::Vector3f& q, float at_off, float tol, float surface_max) {
  return at_off <= surface_max && PlaneDistance(plane, q) <= tol;
}

#if defined(__SSE2__)
// MultiResImage::Grid::Pixel of four points, in 32-bit lanes (pixel counts stay far below 2^31:
// resolutions >= 0.01 deg).
inline __m128i Pixel4(const MultiResImage::Grid& g, __m128 pitch, __m128 yaw) {
  const __m128i zero = _mm_setzero_si128();
  __m128i row = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(_mm_set1_ps(g.up), pitch), _mm_set1_ps(g.row_scale)));
  const __m128i last_row = _mm_set1_epi32(g.rows - 1);
  const __m128i past_last = _mm_cmpgt_epi32(row, last_row);
  row = _mm_or_si128(_mm_and_si128(past_last, last_row), _mm_andnot_si128(past_last, row));
  row = _mm_andnot_si128(_mm_cmplt_epi32(row, zero), row);
  __m128i col = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(_mm_set1_ps(kPiF), yaw), _mm_set1_ps(g.col_scale)));
  const __m128i cols = _mm_set1_epi32(g.cols);
  col = _mm_sub_epi32(col, _mm_and_si128(_mm_cmpgt_epi32(col, _mm_set1_epi32(g.cols - 1)), cols));
  col = _mm_andnot_si128(_mm_cmplt_epi32(col, zero), col);
  // row * cols in 32-bit lanes (SSE2 multiplies lanes 0, 2 and 1, 3 separately).
  const __m128i even = _mm_mul_epu32(row, cols);
  const __m128i odd = _mm_mul_epu32(_mm_srli_si128(row, 4), _mm_srli_si128(cols, 4));
  const __m128i prod = _mm_unpacklo_epi32(_mm_shuffle_epi32(even, _MM_SHUFFLE(0, 0, 2, 0)),
                                          _mm_shuffle_epi32(odd, _MM_SHUFFLE(0, 0, 2, 0)));
  return _mm_add_epi32(prod, col);
}
#endif

#if defined(__SSE2__)
// The pooled returns (window nearest) of four points' pixels at yaw + dyaw: where a point would be
// seen from a keyframe whose pose is off by dyaw.
inline __m128 PooledAt(const MultiResImage::Grid& g, const float* pairs, const float* pitch, const float* yaw,
                       float dyaw) {
  alignas(16) std::int32_t pix[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(pix),
                  Pixel4(g, _mm_loadu_ps(pitch), _mm_add_ps(_mm_loadu_ps(yaw), _mm_set1_ps(dyaw))));
  return _mm_setr_ps(pairs[2 * pix[0]], pairs[2 * pix[1]], pairs[2 * pix[2]], pairs[2 * pix[3]]);
}
#endif

#if defined(__SSE2__)
// The (pooled, range) pairs of four pixels: the nearest return in each pixel's window (s) and the
// pixel's own nearest return (at), lanes 0..3. Two pairs per register, then split.
inline void PairsAt4(const float* pairs, const std::int32_t* pix, __m128* s, __m128* at) {
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 p01 = _mm_loadh_pi(_mm_loadl_pi(inf, reinterpret_cast<const __m64*>(pairs + 2 * pix[0])),
                                  reinterpret_cast<const __m64*>(pairs + 2 * pix[1]));
  const __m128 p23 = _mm_loadh_pi(_mm_loadl_pi(inf, reinterpret_cast<const __m64*>(pairs + 2 * pix[2])),
                                  reinterpret_cast<const __m64*>(pairs + 2 * pix[3]));
  *s = _mm_shuffle_ps(p01, p23, _MM_SHUFFLE(2, 0, 2, 0));
  *at = _mm_shuffle_ps(p01, p23, _MM_SHUFFLE(3, 1, 3, 1));
}

// The window's nearest return s of four points, also read at yaw -+ t.yaw_sigma (pose error);
// with t.yaw_needs_own only in lanes whose own window has a return (VoteTest).
inline __m128 WidenedByYaw4(const MultiResImage::Grid& grid, const float* pairs, const float* pitch, const float* yaw,
                            const VoteTest& t, __m128 s) {
  if (t.yaw_sigma <= 0.f) return s;
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  __m128 w = _mm_min_ps(PooledAt(grid, pairs, pitch, yaw, -t.yaw_sigma), PooledAt(grid, pairs, pitch, yaw, t.yaw_sigma));
  if (t.yaw_needs_own) {
    const __m128 own = _mm_cmplt_ps(s, inf);
    w = _mm_or_ps(_mm_and_ps(own, w), _mm_andnot_ps(own, inf));
  }
  return _mm_min_ps(s, w);
}

// Four points' votes from their window's nearest return s, own pixel's return at and range r.
// See-through: even the nearest return in the window around the point's pixel lies beyond it (so
// grazing surfaces and silhouette edges, whose neighbouring pixels return nearer, give no vote).
// Hit: the pixel's own or the window's nearest return is at the point's range. No return anywhere
// in the window: no evidence. Own see-through: the point's own pixel has a return beyond it (the
// beam that passed the point went on), whatever the beams above and below it met. `occ`, `at_off`
// and `tol` are kept for the surface test of occluded lanes.
struct Votes4 {
  __m128i code;
  __m128 occ, at_off, tol;
};
inline Votes4 Classify4(__m128 s, __m128 at, __m128 r, const VoteTest& t) {
  const __m128 sign = _mm_set1_ps(-0.f), inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 tol = _mm_add_ps(_mm_set1_ps(t.tol_abs), _mm_mul_ps(_mm_set1_ps(t.tol_rel), r));
  const __m128 evidence = _mm_cmplt_ps(_mm_andnot_ps(sign, s), inf);
  const __m128 see = _mm_and_ps(evidence, _mm_cmpgt_ps(s, _mm_add_ps(r, tol)));
  const __m128 at_off = _mm_andnot_ps(sign, _mm_sub_ps(at, r));
  const __m128 s_off = _mm_andnot_ps(sign, _mm_sub_ps(s, r));
  const __m128 near = _mm_or_ps(_mm_cmple_ps(s_off, tol), _mm_cmple_ps(at_off, tol));
  const __m128 hit = _mm_andnot_ps(see, _mm_and_ps(evidence, near));
  const __m128 occ = _mm_andnot_ps(_mm_or_ps(see, hit), evidence);
  const __m128 see_own = _mm_and_ps(_mm_and_ps(_mm_cmplt_ps(at, inf), _mm_cmpgt_ps(at, _mm_add_ps(r, tol))),
                                    _mm_cmple_ps(r, _mm_set1_ps(t.own_max_range)));
  const __m128i c = _mm_or_si128(
      _mm_or_si128(_mm_or_si128(_mm_and_si128(_mm_castps_si128(see), _mm_set1_epi32(kSee)),
                                _mm_and_si128(_mm_castps_si128(hit), _mm_set1_epi32(kHit))),
                   _mm_and_si128(_mm_castps_si128(occ), _mm_set1_epi32(t.occluded))),
      _mm_and_si128(_mm_castps_si128(see_own), _mm_set1_epi32(t.see_own)));
  return {c, occ, at_off, tol};
}
#endif

// Arrays range / pitch / yaw hold m valid points plus 3 entries of padding (0); with kSurface,
// plane holds 4 floats per point (sensor-frame normal, offset) and returns the image's. Surface
// hit: an occluded point whose own pixel's return lies on its plane (OnPlane).
template <bool kSurface>
void VoteLevel(const MultiResImage::Grid grid, const float* pairs, VoteTest t, std::size_t m,
               const std::uint32_t* idx, const float* range, const float* pitch, const float* yaw,
               const float* plane, const Eigen::Vector3f* returns, std::uint8_t* vote) {
  t.own_max_range = OwnReach(grid, t);
#if defined(__SSE2__)
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  alignas(16) std::int32_t pix[4], code[4];
  for (std::size_t j = 0; j < m; j += 4) {
    _mm_store_si128(reinterpret_cast<__m128i*>(pix), Pixel4(grid, _mm_loadu_ps(pitch + j), _mm_loadu_ps(yaw + j)));
    __m128 s, at;
    PairsAt4(pairs, pix, &s, &at);
    s = WidenedByYaw4(grid, pairs, pitch + j, yaw + j, t, s);
    const Votes4 v = Classify4(s, at, _mm_loadu_ps(range + j), t);
    _mm_store_si128(reinterpret_cast<__m128i*>(code), v.code);
    const std::size_t lanes = std::min<std::size_t>(4, m - j);
    if constexpr (kSurface) {
      // Occluded lanes whose own pixel has a return: the (rarer) plane test, one at a time.
      const int cand = _mm_movemask_ps(_mm_and_ps(v.occ, _mm_cmplt_ps(at, inf)));
      if (cand) {
        alignas(16) float offs[4], tols[4];
        _mm_store_ps(offs, v.at_off);
        _mm_store_ps(tols, v.tol);
        for (std::size_t k = 0; k < lanes; ++k)
          if ((cand >> k & 1) && OnPlane(plane + 4 * (j + k), returns[std::size_t(pix[k])], offs[k], tols[k], t.surface_max))
            code[k] = kHit;
      }
    }
    for (std::size_t k = 0; k < lanes; ++k) vote[idx[j + k]] = std::uint8_t(code[k]);
  }
#else
  for (std::size_t j = 0; j < m; ++j) {
    const std::size_t pix = grid.Pixel(pitch[j], yaw[j]);
    float s = pairs[2 * pix];
    const float at = pairs[2 * pix + 1];
    if (t.yaw_sigma > 0.f && (!t.yaw_needs_own || std::isfinite(s)))
      s = std::min({s, pairs[2 * grid.Pixel(pitch[j], yaw[j] - t.yaw_sigma)],
                    pairs[2 * grid.Pixel(pitch[j], yaw[j] + t.yaw_sigma)]});
    const float r = range[j];
    const float tol = t.tol_abs + t.tol_rel * r;
    if (!std::isfinite(s)) continue;  // no return anywhere in the window: no evidence
    bool hit = std::fabs(s - r) <= tol || std::fabs(at - r) <= tol;
    if constexpr (kSurface)
      hit = hit || (!(s > r + tol) && std::isfinite(at) &&
                    OnPlane(plane + 4 * j, returns[pix], std::fabs(at - r), tol, t.surface_max));
    vote[idx[j]] = std::uint8_t((s > r + tol ? kSee : (hit ? kHit : t.occluded)) |
                                (std::isfinite(at) && at > r + tol && r <= t.own_max_range ? t.see_own : 0));
  }
#endif
}

}  // namespace

// Per row: how many rows above and below the pool looks for the nearest beam: window_px, or two
// local beam spacings (at the row's elevation) where the beams are sparser than the rows (one
// beam may have dropped its return).
std::vector<int> MultiResImage::WindowRows(const RemovertConfig& cfg, int rows, double row_deg) {
  std::vector<int> w(std::size_t(rows), cfg.window_px);
  if (cfg.window_px == 0 || !cfg.SensorResolved()) return w;
  constexpr double kSpanSpacings = 2.0;
  for (int r = 0; r < rows; ++r) {
    const double elevation = cfg.fov_up_deg - (r + 0.5) * row_deg;
    const double spacing = cfg.sensor_model.SpacingAt(elevation);
    w[std::size_t(r)] = std::max(cfg.window_px, int(std::ceil(kSpanSpacings * spacing / row_deg - 1e-6)));
  }
  return w;
}

MultiResImage::MultiResImage(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg,
                             bool keep_returns, bool within_beams)
    : keep_returns_(keep_returns) {
  up_ = float(cfg.fov_up_deg * kRadPerDeg);
  down_ = float(cfg.fov_down_deg * kRadPerDeg);
  min_range_ = float(cfg.min_range_m);
  max_range_ = float(cfg.max_range_m);
  window_ = cfg.window_px;
  point_up_ = up_;
  point_down_ = down_;
  if (within_beams) PointBounds(cfg);
  for (double res : resolutions_deg) {
    Level L;
    L.grid = Grid::Make(cfg, res, res);
    L.window_rows = WindowRows(cfg, L.grid.rows, res);
    L.scatter_rows = cfg.SensorResolved() ? int(std::lround(cfg.sensor_model.spread_deg / res)) : 0;
    L.both_sides = cfg.SensorResolved() && !cfg.sensor_model.ring_based;
    L.range.assign(std::size_t(L.grid.rows) * L.grid.cols, std::numeric_limits<float>::infinity());
    L.pooled = L.range;
    L.tmp = L.range;
    L.pairs.assign(2 * L.range.size(), std::numeric_limits<float>::infinity());
    if (keep_returns_) L.ret.assign(L.range.size(), Eigen::Vector3f::Zero());
    levels_.push_back(std::move(L));
  }
}

void MultiResImage::PointBounds(const RemovertConfig& cfg) {
  const geometry::SensorModel& m = cfg.sensor_model;
  if (!cfg.SensorResolved() || !m.ring_based || m.beams() < 2) return;
  point_up_ = std::min(up_, float((m.fov_up_deg + m.spread_deg) * kRadPerDeg));
  point_down_ = std::max(down_, float((m.fov_down_deg - m.spread_deg) * kRadPerDeg));
}

std::size_t MultiResImage::Project(const float* x, const float* y, const float* z, std::size_t n,
                                   const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, float radius2,
                                   std::uint32_t* idx, float* range, float* pitch, float* yaw) const {
  std::size_t m = 0;
#if defined(__SSE2__)
  const __m128 cx = _mm_set1_ps(c.x()), cy = _mm_set1_ps(c.y()), cz = _mm_set1_ps(c.z());
  __m128 R[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R[i][j] = _mm_set1_ps(Rt(i, j));
  const __m128 rad2 = _mm_set1_ps(radius2), up = _mm_set1_ps(point_up_), down = _mm_set1_ps(point_down_);
  alignas(16) float rs[4], ps[4], ys[4];
  for (std::size_t i = 0; i < n; i += 4) {
    const __m128 dx = _mm_sub_ps(_mm_loadu_ps(x + i), cx);
    const __m128 dy = _mm_sub_ps(_mm_loadu_ps(y + i), cy);
    const __m128 dz = _mm_sub_ps(_mm_loadu_ps(z + i), cz);
    // Eigen's association for 3-vectors: d.squaredNorm() = dx^2 + (dy^2 + dz^2) and
    // (Rt d)_k = Rt(k,0) dx + (Rt(k,1) dy + Rt(k,2) dz).
    const __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_add_ps(_mm_mul_ps(dy, dy), _mm_mul_ps(dz, dz)));
    __m128 p[3];
    for (int k = 0; k < 3; ++k)
      p[k] = _mm_add_ps(_mm_mul_ps(R[k][0], dx),
                        _mm_add_ps(_mm_mul_ps(R[k][1], dy), _mm_mul_ps(R[k][2], dz)));
    __m128 r, pt, yw;
    const __m128 valid = Angles4(p[0], p[1], p[2], up, down, &r, &pt, &yw);
    const __m128 ok = _mm_andnot_ps(_mm_cmpgt_ps(d2, rad2), valid);
    int mask = _mm_movemask_ps(ok);
    if (n - i < 4) mask &= (1 << (n - i)) - 1;
    if (mask == 0) continue;
    _mm_store_ps(rs, r);
    _mm_store_ps(ps, pt);
    _mm_store_ps(ys, yw);
    for (int k = 0; k < 4; ++k) {
      if (!(mask >> k & 1)) continue;
      idx[m] = std::uint32_t(i + std::size_t(k));
      range[m] = rs[k];
      pitch[m] = ps[k];
      yaw[m] = ys[k];
      ++m;
    }
  }
#else
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f d = Eigen::Vector3f(x[i], y[i], z[i]) - c;
    if (d.squaredNorm() > radius2) continue;
    if (!PointAngles(Rt * d, &range[m], &pitch[m], &yaw[m])) continue;
    idx[m++] = std::uint32_t(i);
  }
#endif
  return m;
}

void MultiResImage::Build(const PointCloud& scan) {
  for (Level& L : levels_) std::fill(L.range.begin(), L.range.end(), std::numeric_limits<float>::infinity());
  const int nl = levels();
  // The pixel's min range, and with keep_returns the return that has it (the last of equals).
  auto keep = [](Level& L, std::size_t pix, float r, const PointXYZI& q) {
    float& m = L.range[pix];
    if (r <= m) {
      m = r;
      L.ret[pix] = Eigen::Vector3f(q.x, q.y, q.z);
    }
  };
  auto add = [&](float r, float pitch, float yaw, const PointXYZI& q) {
    if (r < min_range_ || r > max_range_) return;
    for (int l = 0; l < nl; ++l) {
      Level& L = levels_[std::size_t(l)];
      const std::size_t pix = L.grid.Pixel(pitch, yaw);
      if (keep_returns_) {
        keep(L, pix, r, q);
      } else {
        float& px = L.range[pix];
        if (r < px) px = r;
      }
    }
  };
  std::size_t i = 0;
  const std::size_t n = scan.size();
#if defined(__SSE2__)
  const ScanBounds4 bd{_mm_set1_ps(up_), _mm_set1_ps(down_), _mm_set1_ps(min_range_), _mm_set1_ps(max_range_)};
  alignas(16) float rs[4];
  alignas(16) std::int32_t pix[4];
  for (; i + 4 <= n; i += 4) {
    __m128 r, pt, yw;
    const int mask = ScanAngles4(scan, i, bd, &r, &pt, &yw);
    if (mask == 0) continue;
    _mm_store_ps(rs, r);
    for (Level& L : levels_) {
      _mm_store_si128(reinterpret_cast<__m128i*>(pix), Pixel4(L.grid, pt, yw));
      for (int k = 0; k < 4; ++k)
        if (mask >> k & 1) {
          if (keep_returns_) {
            keep(L, std::size_t(pix[k]), rs[k], scan.points[i + std::size_t(k)]);
          } else {
            float& m = L.range[std::size_t(pix[k])];
            m = std::min(m, rs[k]);  // if (r < m) m = r
          }
        }
    }
  }
#endif
  for (; i < n; ++i) {
    const PointXYZI& q = scan.points[i];
    float r, pitch, yaw;
    if (Angles(Eigen::Vector3f(q.x, q.y, q.z), &r, &pitch, &yaw)) add(r, pitch, yaw, q);
  }
  for (Level& L : levels_) {
    Pool(L);
    for (std::size_t q = 0; q < L.range.size(); ++q) {
      L.pairs[2 * q] = L.pooled[q];
      L.pairs[2 * q + 1] = L.range[q];
    }
  }
}

// Separable min filter: along columns (wrapping) into tmp, then along rows into pooled. Min is
// exact and there are no NaNs, so the evaluation order does not change the result.
void MultiResImage::Pool(Level& L) const {
  if (window_ == 0) {
    std::copy(L.range.begin(), L.range.end(), L.pooled.begin());
    return;
  }
  PoolColumns(L);
  PoolRows(L);
}

// Horizontal: the min over the window_px columns on each side (wrapping) into L.tmp.
void MultiResImage::PoolColumns(Level& L) const {
  const int w = window_;
  const int rows = L.grid.rows, cols = L.grid.cols;
  for (int r = 0; r < rows; ++r) {
    const float* src = &L.range[std::size_t(r) * cols];
    float* dst = &L.tmp[std::size_t(r) * cols];
    // Columns whose window wraps around.
    auto wrapped = [&](int c) {
      float m = src[c];
      for (int d = 1; d <= w; ++d) {
        int a = c - d, b = c + d;
        if (a < 0) a += cols;
        if (b >= cols) b -= cols;
        m = std::min(m, std::min(src[a], src[b]));
      }
      dst[c] = m;
    };
    const int lo = std::min(w, cols), hi = std::max(lo, cols - w);
    for (int c = 0; c < lo; ++c) wrapped(c);
    for (int c = hi; c < cols; ++c) wrapped(c);
    // Interior: no wrap, vectorisable.
    std::copy(src + lo, src + hi, dst + lo);
    for (int d = 1; d <= w; ++d)
      for (int c = lo; c < hi; ++c) dst[c] = std::min(dst[c], std::min(src[c - d], src[c + d]));
  }
}

// Vertical, from L.tmp into L.pooled.
void MultiResImage::PoolRows(Level& L) const {
  const int rows = L.grid.rows, cols = L.grid.cols;
  // Vertical: every row within the beams' own scatter (L.scatter_rows: the estimated spread of a
  // beam's returns about its elevation, 0 for an ideal sensor), then the nearest row with a
  // return beyond that above and below, within L.window_rows: the beams on both sides of any
  // direction inside the row, and no farther beams, whose returns (the ground in front of a low
  // mover) would hide it.
  const int ws = L.scatter_rows;
  const float inf = std::numeric_limits<float>::infinity();
  for (int r = 0; r < rows; ++r) {
    float* dst = &L.pooled[std::size_t(r) * cols];
    std::copy(&L.tmp[std::size_t(r) * cols], &L.tmp[std::size_t(r) * cols] + cols, dst);
    for (int rr = std::max(0, r - ws); rr <= std::min(rows - 1, r + ws); ++rr) {
      const float* src = &L.tmp[std::size_t(rr) * cols];
      for (int c = 0; c < cols; ++c) dst[c] = std::min(dst[c], src[c]);
    }
  }
  // Nearest return at or beyond each row, per column, swept from the top (above) and the bottom
  // (below); row r takes the one found at r - ws - 1 (above) and r + ws + 1 (below).
  std::vector<float> last(static_cast<std::size_t>(cols));
  std::vector<int> last_row(static_cast<std::size_t>(cols));
  // Without rings (a non-repetitive pattern) no row structure guarantees a return on each side of
  // a direction: a pixel is evidence only where both sides had one (sides == 3).
  std::vector<std::uint8_t>& sides = L.sides;
  if (L.both_sides) sides.assign(L.pooled.size(), 0);
  auto sweep = [&](int step) {
    const std::uint8_t side = step > 0 ? 1 : 2;
    std::fill(last.begin(), last.end(), inf);
    std::fill(last_row.begin(), last_row.end(), -1);
    const int first = step > 0 ? 0 : rows - 1;
    for (int k = 0; k < rows; ++k) {
      const int r = first + step * k;     // the row to pool
      const int q = r - step * (ws + 1);  // the row whose nearest return it takes
      if (q >= 0 && q < rows) {
        const float* src = &L.tmp[std::size_t(q) * cols];
        for (int c = 0; c < cols; ++c)
          if (src[c] < inf) last[std::size_t(c)] = src[c], last_row[std::size_t(c)] = q;
      }
      const int wr = L.window_rows[std::size_t(r)];
      float* dst = &L.pooled[std::size_t(r) * cols];
      for (int c = 0; c < cols; ++c)
        if (last_row[std::size_t(c)] >= 0 && std::abs(r - last_row[std::size_t(c)]) <= wr) {
          dst[c] = std::min(dst[c], last[std::size_t(c)]);
          if (L.both_sides) sides[std::size_t(r) * cols + c] |= side;
        }
    }
  };
  sweep(1);   // nearest return above (smaller rows)
  sweep(-1);  // nearest return below
  if (L.both_sides)
    for (std::size_t q = 0; q < sides.size(); ++q)
      if (sides[q] != 3) L.pooled[q] = inf;
}

// A beam's returns lie within this many sigmas of the scans' elevation scatter about it.
constexpr double kBeamScatterSigmas = 3.0;

// The beam test's cells for the sensor: columns one azimuth step wide, rows at most half the
// finest beam spacing. A cell keeps its nearest return, so one that held two returns of a beam
// (a column two steps wide) or two beams would lose the farther: on grazing ground the return
// that ended near the point, 3 m behind its neighbour at 70 m.
BeamTest ForSensor(const RemovertConfig& cfg, BeamTest test) {
  if (!cfg.SensorResolved()) return test;
  const geometry::SensorModel& m = cfg.sensor_model;
  if (m.azimuth_step_deg > 0.0) test.col_deg = m.azimuth_step_deg;
  double finest = m.MaxSpacing();
  for (std::size_t i = 1; i < m.elevations_deg.size(); ++i)
    finest = std::min(finest, m.elevations_deg[i - 1] - m.elevations_deg[i]);
  if (finest > 0.0) test.row_deg = std::min(test.row_deg, 0.5 * finest);
  return test;
}

ColumnImage::ColumnImage(const RemovertConfig& cfg, const BeamTest& test_in)
    : test_(ForSensor(cfg, test_in)), grid_(MultiResImage::Grid::Make(cfg, test_.row_deg, test_.col_deg)) {
  const BeamTest& test = test_;
  // Per row: how far to look for the beams above and below: span_deg, or two local beam
  // spacings where the beams are sparser (one of them may have dropped its return).
  constexpr double kSpanSpacings = 2.0;
  span_.resize(std::size_t(grid_.rows));
  for (int r = 0; r < grid_.rows; ++r) {
    const double elevation = cfg.fov_up_deg - (r + 0.5) * test.row_deg;
    const double spacing = cfg.SensorResolved() ? cfg.sensor_model.SpacingAt(elevation) : 0.0;
    span_[std::size_t(r)] = std::max(1, int(std::lround(std::max(test.span_deg, kSpanSpacings * spacing) / test.row_deg)));
  }
  if (cfg.SensorResolved() && cfg.sensor_model.ring_based && cfg.sensor_model.azimuth_step_deg > 0.0) {
    // A beam's returns lie within 0.4 of the local spacing of its tabled elevation (the table is
    // estimated; the other beams' lie beyond), and within 3 x the scans' scatter about it (deskewed
    // sweeps: the vehicle's motion during the sweep moves them). A beam whose scatter reaches
    // halfway to its neighbours cannot be told from them: it gives no evidence (TellsItsReturns).
    constexpr double kOwnBand = 0.4;
    const geometry::SensorModel& m = cfg.sensor_model;
    const double scatter = kBeamScatterSigmas * m.spread_deg;
    for (const double e : m.elevations_deg) table_el_.push_back(float(e * kRadPerDeg));
    std::sort(table_el_.begin(), table_el_.end());
    table_reach_ = float(scatter * kRadPerDeg);
    for (const double e : m.elevations_deg) {
      if (!TellsItsReturns(m, e)) continue;
      const double spacing = m.SpacingAt(e);
      beam_el_.push_back(float(e * kRadPerDeg));
      beam_margin_.push_back(float(std::max({0.5 * test.row_deg, kOwnBand * spacing, scatter}) * kRadPerDeg));
    }
  }
  down_ = float(cfg.fov_down_deg * kRadPerDeg);
  through_m_ = float(cfg.map_voxel_m);
  surface_reach_m_ = float(cfg.ld_normal_radius_m);
  min_range_ = float(cfg.min_range_m);
  max_range_ = float(cfg.max_range_m);
  range_.assign(std::size_t(grid_.rows) * std::size_t(grid_.cols), std::numeric_limits<float>::infinity());
  ret_.assign(range_.size(), Eigen::Vector3f::Zero());
  any_.assign(range_.size(), 0);
  fired_.assign(std::size_t(grid_.cols), std::numeric_limits<float>::quiet_NaN());
}

void ColumnImage::Build(const PointCloud& scan) {
  std::fill(range_.begin(), range_.end(), std::numeric_limits<float>::infinity());
  std::fill(any_.begin(), any_.end(), 0);
  std::fill(fired_.begin(), fired_.end(), std::numeric_limits<float>::quiet_NaN());
  // Every return marks its cell in any_ (a beam that met something, at any range); the range test
  // reads those within [min_range, max_range].
  const float blind = min_range_ + float(test_.tol_m);  // nearer: the blind zone's edge (EmptyColumn)
  auto put = [&](float r, float pitch, float yaw, const PointXYZI& q) {
    const std::size_t col = std::size_t(grid_.Col(yaw)), cell = col * std::size_t(grid_.rows) + std::size_t(grid_.Row(pitch));
    any_[cell] = std::max<std::uint8_t>(any_[cell], r < blind ? kNearBlind : 1);
    fired_[col] = yaw;
    if (r < min_range_ || r > max_range_) return;
    if (r < range_[cell]) {
      range_[cell] = r;
      ret_[cell] = Eigen::Vector3f(q.x, q.y, q.z);
    }
  };
  std::size_t i = 0;
  const std::size_t n = scan.size();
#if defined(__SSE2__)
  // Four points at a time through the angle kernel MultiResImage::Build uses.
  const ScanBounds4 bd{_mm_set1_ps(grid_.up), _mm_set1_ps(down_), _mm_set1_ps(1e-6f),
                       _mm_set1_ps(std::numeric_limits<float>::infinity())};
  alignas(16) float rs[4], ps[4], ys[4];
  for (; i + 4 <= n; i += 4) {
    __m128 r, pt, yw;
    const int mask = ScanAngles4(scan, i, bd, &r, &pt, &yw);
    if (mask == 0) continue;
    _mm_store_ps(rs, r);
    _mm_store_ps(ps, pt);
    _mm_store_ps(ys, yw);
    for (int k = 0; k < 4; ++k)
      if (mask >> k & 1) put(rs[k], ps[k], ys[k], scan.points[i + std::size_t(k)]);
  }
#endif
  for (; i < n; ++i) {
    const PointXYZI& q = scan.points[i];
    const float rxy2 = q.x * q.x + q.y * q.y;
    const float r = std::sqrt(rxy2 + q.z * q.z);
    if (!(r > 1e-6f)) continue;
    const float pitch = FastAtan2(q.z, std::sqrt(rxy2));
    if (pitch > grid_.up || pitch < down_) continue;
    put(r, pitch, FastAtan2(q.y, q.x), q);
  }
}

// Along-ray tolerance for a surface whose normal makes |cos| `cosine` with the ray: `tol` from
// the surface, so up to tol / cos along a grazing ray, at most `cap` (BeamTest::grazing_max_m).
static float AlongRay(float tol, float cosine, float cap) { return std::max(tol, std::min(tol / std::max(cosine, 1e-6f), cap)); }

// The nearest rows above and below `row` within its span holding a return in the column at rc
// (-1: none).
std::pair<int, int> ColumnImage::BeamsAround(const float* rc, int row) const {
  const int rows = grid_.rows, span = span_[std::size_t(row)];
  int ra = -1, rb = -1;
  for (int r = row - 1; r >= std::max(0, row - span) && ra < 0; --r)
    if (std::isfinite(rc[r])) ra = r;
  for (int r = row + 1; r <= std::min(rows - 1, row + span) && rb < 0; ++r)
    if (std::isfinite(rc[r])) rb = r;
  return {ra, rb};
}

// Beam r of column c ended on the point's surface near it: its return on the point's plane, its
// ray passing within tol of the point, and its return within the along-ray tolerance of the point's
// place along it, at the incidence on the point's plane and (with `world`) on the surface the
// return met (the sim's beam truth: a ray of the scan that ended on the surface near the point).
bool ColumnImage::EndedNear(const BeamPoint& p, std::size_t c, int r, const PointInWorld* world) const {
  const float tol = float(test_.tol_m), grazing_max = float(test_.grazing_max_m);
  const float rr = range_[c + std::size_t(r)];
  const Eigen::Vector3f& q = ret_[c + std::size_t(r)];
  if (PlaneDistance(p.plane, q) > tol) return false;
  const Eigen::Vector3f u = q / rr;
  const float s = p.ps.dot(u);
  if ((p.ps - s * u).squaredNorm() > tol * tol) return false;
  const float along = std::fabs(rr - s);
  const Eigen::Vector3f nrm(p.plane[0], p.plane[1], p.plane[2]);
  if (along > AlongRay(tol, std::fabs(nrm.dot(u)), grazing_max)) return false;
  float met = 0.f;
  return along <= tol || world == nullptr ||
         !world->surfaces->Cosine(world->at + world->to_world * (q - p.ps), world->to_world * u, &met) ||
         along <= AlongRay(tol, met, grazing_max);
}

// at(c, r) for the cell of the column at offset c in `row` when it holds a return, else for the
// nearest beams above and below it (BeamsAround; their rows in *ra / *rb, -1: none).
template <class At>
bool ColumnImage::OwnOrAround(std::size_t c, int row, At&& at, int* ra, int* rb) const {
  const float* rc = range_.data() + c;
  if (std::isfinite(rc[row]) && at(c, row)) return true;
  std::tie(*ra, *rb) = BeamsAround(rc, row);
  return (*ra >= 0 && at(c, *ra)) || (*rb >= 0 && at(c, *rb));
}

// Beam r of column c crossed the point's plane within a map voxel of it (the surface element the
// map point stands for) and its return lies beyond the crossing by more than tol / cos(incidence):
// it went through the point's place, past the band along the ray where it is within tol of the
// plane (not capped at grazing_max as for a beam that ended near: a ray grazing a facade ends on
// it a few metres on).
bool ColumnImage::WentBeyond(const BeamPoint& p, std::size_t c, int r) const {
  constexpr float kUncapped = std::numeric_limits<float>::infinity();
  const float rr = range_[c + std::size_t(r)];
  const Eigen::Vector3f u = ret_[c + std::size_t(r)] / rr;
  const Eigen::Vector3f nrm(p.plane[0], p.plane[1], p.plane[2]);
  const float cs = nrm.dot(u);
  if (std::fabs(cs) < 1e-3f) return false;
  const float t = nrm.dot(p.ps) / cs;
  return t > 0.f && (t * u - p.ps).squaredNorm() <= through_m_ * through_m_ &&
         rr - t > AlongRay(float(test_.tol_m), std::fabs(cs), kUncapped);
}

std::uint8_t ColumnImage::Observed(const BeamPoint& p, const BeamAsk& ask) const {
  const int rows = grid_.rows, row = grid_.Row(p.pitch), col = grid_.Col(p.yaw);
  const auto cell = [&](int c) { return std::size_t((c + grid_.cols) % grid_.cols) * std::size_t(rows); };
  const auto ended_near = [&](std::size_t c, int r) { return EndedNear(p, c, r, ask.world); };
  const auto went_beyond = [&](std::size_t c, int r) { return WentBeyond(p, c, r); };
  int ra = -1, rb = -1;
  bool ended = OwnOrAround(cell(col), row, ended_near, &ra, &rb);
  const bool own_empty = !std::isfinite(range_[cell(col) + std::size_t(row)]);
  const bool around = ask.want_around && own_empty && Around(p.range, cell(col), ra, rb, p.ps, p.plane);
  // The truth counts every ray that passes within tol of the point, whatever its azimuth: the
  // columns within asin(tol / range) of the point's.
  const int reach =
      std::min(grid_.cols / 2, int(std::ceil(std::asin(std::min(1.f, float(test_.tol_m) / p.range)) * grid_.col_scale)));
  for (int d = 1; d <= reach && !ended; ++d)
    for (int c : {col - d, col + d}) {
      int a = -1, b = -1;
      if (!ended) ended = OwnOrAround(cell(c), row, ended_near, &a, &b);
    }
  const bool passed = ask.want_around && !ended && PassedWithoutReturn(p.range, p.pitch, p.yaw);
  // Without a beam ending near it, a beam of those columns went through its place (WentBeyond).
  bool went = false;
  for (int d = -reach; d <= reach && ask.ask_through && !ended && !went; ++d) {
    int a = -1, b = -1;
    went = OwnOrAround(cell(col + d), row, went_beyond, &a, &b);
  }
  // ND's, with `inside`: the beam of the point's own column passed it without a return and crossed
  // its surface inside (PassedInside), not beside its edge.
  const bool passed_own =
      ask.inside != nullptr && !ended && PassedInside(p.range, p.pitch, p.yaw, p.ps, p.plane, *ask.inside);
  // Not where the scan met the point's surface nearby (MetSurfaceNear): that ray passed an edge of
  // it (a wall's top, a gap between fence panels) without crossing it.
  const bool through = (went || passed_own) && !MetSurfaceNear(p.range, p.pitch, p.yaw, p.ps, p.plane);
  // A scan line's point (its surface's orientation unknown: a far fence's rows): a beam that passed
  // it without a return, where the scan met nothing within reach of it (a wall's top row: the beams
  // below met the wall).
  const bool through_line = ask.line_up != nullptr && !ended && PassedWithoutReturn(p.range, p.pitch, p.yaw) &&
                            !MetSurfaceNear(p.range, p.pitch, p.yaw, p.ps, nullptr) &&
                            !MetUnderOrOver(p, col, *ask.line_up);
  // kBeamNear gates ND's pixel see-through (VoteCounts); PD (want_around) does not read it.
  const bool near = !ask.want_around && BeamNear(p.range, p.pitch);
  return std::uint8_t((ended ? kBeamEnded : 0) | (around ? kBeamAround : 0) | (passed ? kBeamPassed : 0) |
                      (through || through_line ? kBeamThrough : 0) | (near ? kBeamNear : 0));
}

bool ColumnImage::MetSurfaceNear(float range, float pitch, float yaw, const Eigen::Vector3f& ps,
                                 const float* plane) const {
  const float tol = float(test_.tol_m), reach_m = surface_reach_m_;
  const float angle = std::asin(std::min(1.f, reach_m / range));
  const int dc = std::min(grid_.cols / 2, int(std::ceil(angle * grid_.col_scale)));
  const int r0 = std::max(0, grid_.Row(pitch + angle)), r1 = std::min(grid_.rows - 1, grid_.Row(pitch - angle));
  const int col = grid_.Col(yaw);
  for (int d = -dc; d <= dc; ++d) {
    const std::size_t c = std::size_t((col + d + grid_.cols) % grid_.cols) * std::size_t(grid_.rows);
    for (int r = r0; r <= r1; ++r) {
      if (!std::isfinite(range_[c + std::size_t(r)])) continue;
      const Eigen::Vector3f& q = ret_[c + std::size_t(r)];
      if ((plane == nullptr || PlaneDistance(plane, q) <= tol) && (q - ps).squaredNorm() <= reach_m * reach_m)
        return true;
    }
  }
  return false;
}

bool ColumnImage::MetUnderOrOver(const BeamPoint& p, int col, const Eigen::Vector3f& up) const {
  const auto level = [&](const Eigen::Vector3f& v) { return (v - v.dot(up) * up).norm(); };
  const float tol = float(test_.tol_m), across = level(p.ps);
  const int row = grid_.Row(p.pitch);
  const auto at_its_distance = [&](std::size_t c, int r) {
    return r >= 0 && std::fabs(level(ret_[c + std::size_t(r)]) - across) <= tol;
  };
  for (int d = -1; d <= 1; ++d) {
    const std::size_t c = std::size_t((col + d + grid_.cols) % grid_.cols) * std::size_t(grid_.rows);
    const auto [ra, rb] = BeamsAround(range_.data() + c, row);
    if (at_its_distance(c, ra) || at_its_distance(c, rb)) return true;
  }
  return false;
}

bool ColumnImage::EmptyColumn(int col, int row_top, int row_bottom) const {
  const std::size_t c = std::size_t((col + grid_.cols) % grid_.cols);
  if (!std::isfinite(fired_[c])) return false;  // no return in the whole column: the sweep's seam, not the sky
  const std::uint8_t* ac = any_.data() + c * std::size_t(grid_.rows);
  for (int r = row_top; r <= row_bottom; ++r)
    if (ac[r]) return false;
  // A beam that met a surface nearer than the sensor's minimum range returns nothing either: where
  // the beams around these rows met one within the tolerance of that range (a vehicle passing
  // beside the sensor), the empty rows may be the blind zone, not free space.
  const int span = span_[std::size_t(row_top)];
  for (int r = std::max(0, row_top - span); r <= std::min(grid_.rows - 1, row_bottom + span); ++r)
    if (ac[r] == kNearBlind) return false;
  return true;
}

bool ColumnImage::PassedWithoutReturn(float range, float pitch, float yaw) const {
  const int col = grid_.Col(yaw);
  return AnyBeamNear(range, pitch, [&](float e, float reach, int row_top, int row_bottom) {
    // A column within reach of the point's whose neighbours on both sides are empty too: three
    // empty columns in a row, centred within reach.
    const float d_el = e - pitch;
    const int cols = int(std::sqrt(std::max(0.f, reach * reach - d_el * d_el)) * grid_.col_scale);
    int run = 0;
    for (int c = col - cols - 1; c <= col + cols + 1; ++c) {
      run = EmptyColumn(c, row_top, row_bottom) ? run + 1 : 0;
      if (run >= 3) return true;
    }
    return false;
  });
}

bool ColumnImage::BeamNear(float range, float pitch) const {
  if (table_el_.empty()) return true;
  const float reach = std::asin(std::min(1.f, float(test_.tol_m) / range)) + table_reach_;
  const auto it = std::lower_bound(table_el_.begin(), table_el_.end(), pitch - reach);
  return it != table_el_.end() && *it <= pitch + reach;
}

bool ColumnImage::TellsItsReturns(const geometry::SensorModel& m, double elevation_deg) {
  return kBeamScatterSigmas * m.spread_deg < 0.5 * m.SpacingAt(elevation_deg);
}

int ColumnImage::BeamsThatTell(const geometry::SensorModel& m) {
  if (!m.ring_based) return 0;
  return int(std::count_if(m.elevations_deg.begin(), m.elevations_deg.end(),
                           [&](double e) { return TellsItsReturns(m, e); }));
}

bool ColumnImage::PassedInside(float range, float pitch, float yaw, const Eigen::Vector3f& ps, const float* plane,
                               const SurfaceExtent& inside) const {
  const float tol = float(test_.tol_m);
  const int col = grid_.Col(yaw);
  const float fired = fired_[std::size_t(col)];
  if (!std::isfinite(fired)) return false;
  const Eigen::Vector3f n(plane[0], plane[1], plane[2]);
  const Eigen::Vector3f side = inside.up.cross(n).normalized();
  return AnyBeamNear(range, pitch, [&](float e, float, int row_top, int row_bottom) {
    if (!EmptyColumn(col - 1, row_top, row_bottom) || !EmptyColumn(col, row_top, row_bottom) ||
        !EmptyColumn(col + 1, row_top, row_bottom))
      return false;
    const Eigen::Vector3f u(std::cos(e) * std::cos(fired), std::cos(e) * std::sin(fired), std::sin(e));
    if ((ps - ps.dot(u) * u).squaredNorm() > tol * tol) return false;  // the beam passed farther than tol
    const float cs = n.dot(u);
    if (std::fabs(cs) < 1e-3f) return false;  // along the plane: it crosses nowhere
    const Eigen::Vector3f off = (plane[3] / cs) * u - ps;  // from the point to where it crossed the plane
    const float up = off.dot(inside.up), across = off.dot(side);
    return up <= inside.above && -up <= inside.below && across <= inside.left && -across <= inside.right;
  });
}

bool ColumnImage::Around(float range, std::size_t column, int ra, int rb, const Eigen::Vector3f& ps,
                         const float* plane) const {
  const float tol = float(test_.tol_m);
  const float grazing_max = float(test_.grazing_max_m);
  const float* rc = range_.data() + column;
  const Eigen::Vector3f* qc = ret_.data() + column;
  // 0: no return, 1: on the point's plane, 2: nearer (occluder), 3: farther (past the surface's edge).
  auto kind = [&](int r) {
    if (PlaneDistance(plane, qc[r]) <= tol) return 1;
    return rc[r] < range ? 2 : 3;
  };
  const Eigen::Vector3f u = ps / range;  // the ray's direction
  const Eigen::Vector3f nrm(plane[0], plane[1], plane[2]);
  const int above = ra >= 0 ? kind(ra) : 0, below = rb >= 0 ? kind(rb) : 0;
  if (above == 1 && below == 1) {
    // The surface between the two beams: the plane through their returns that holds the
    // horizontal direction along the point's surface (its contour line; across the ray for
    // level ground). The ray towards the point must meet it within the along-ray tolerance of
    // the point: not in a trough behind a crest the lower beam hit. A plane, not the returns'
    // ranges: on a surface seen obliquely the column's returns lie at other azimuths than the point.
    // A surface within ~6 deg of level (|n x z| = sin slope < kLevelSine) has no contour
    // direction to speak of: take the horizontal across the ray.
    constexpr float kLevelSine = 0.1f;
    Eigen::Vector3f t = nrm.cross(Eigen::Vector3f::UnitZ());
    if (t.norm() < kLevelSine) t = Eigen::Vector3f(-u.y(), u.x(), 0.f);
    Eigen::Vector3f m = (qc[ra] - qc[rb]).cross(t);
    if (m.norm() < 1e-6f) m = nrm;
    m.normalize();
    const float cosine = std::fabs(m.dot(u));
    if (cosine < 1e-6f) return false;
    const float s = m.dot(qc[ra]) / m.dot(u);
    return std::fabs(s - range) <= AlongRay(tol, cosine, grazing_max);
  }
  // One side on the surface, the other without a return or past it: the surface's edge.
  const int on = above == 1 ? ra : below == 1 ? rb : -1;
  const int other = above == 1 ? below : above;
  return on >= 0 && (other == 0 || other == 3);
}

TileIndex::TileIndex(const PointCloud& cloud, double tile_m) : tile_m_(tile_m) {
  const std::size_t n = cloud.size();
  // Tiles in key order, points in input order within a tile: a counting sort by tile (tile ids
  // first by appearance, then renumbered by key).
  std::vector<std::uint32_t> tile(n);
  std::vector<std::int64_t> keys;  // by first appearance
  std::int64_t last_key = 0;
  std::uint32_t last_id = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const PointXYZI& p = cloud.points[i];
    const std::int64_t key =
        Key(std::int32_t(std::floor(p.x / tile_m)), std::int32_t(std::floor(p.y / tile_m)));
    if (keys.empty() || key != last_key) {  // neighbouring points mostly share a tile
      const auto [it, added] = tiles_.try_emplace(key, std::uint32_t(keys.size()));
      if (added) keys.push_back(key);
      last_key = key;
      last_id = it->second;
    }
    tile[i] = last_id;
  }
  std::vector<std::uint32_t> by_key(keys.size()), rank(keys.size());
  for (std::size_t t = 0; t < keys.size(); ++t) by_key[t] = std::uint32_t(t);
  std::sort(by_key.begin(), by_key.end(),
            [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
  for (std::size_t r = 0; r < by_key.size(); ++r) rank[by_key[r]] = std::uint32_t(r);
  for (auto& kv : tiles_) kv.second = rank[kv.second];
  std::vector<std::uint32_t> next(keys.size() + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++next[rank[tile[i]] + 1];
  for (std::size_t r = 0; r < keys.size(); ++r) next[r + 1] += next[r];
  ranges_.resize(keys.size());
  for (std::size_t r = 0; r < keys.size(); ++r) ranges_[r] = {next[r], next[r + 1]};
  order_.resize(n);
  for (std::size_t i = 0; i < n; ++i) order_[next[rank[tile[i]]]++] = std::uint32_t(i);
  constexpr std::size_t kPad = 3;  // batches of four may read past the last point
  x_.assign(n + kPad, 0.f);
  y_.assign(n + kPad, 0.f);
  z_.assign(n + kPad, 0.f);
  for (std::size_t k = 0; k < n; ++k) {
    const PointXYZI& p = cloud.points[order_[k]];
    x_[k] = p.x;
    y_[k] = p.y;
    z_[k] = p.z;
  }
}

namespace {
// Azimuth bins of SweepFrames: the columns of one bin fire within 0.1 / 360 of a sweep of each
// other (0.03 ms at 10 Hz), so the sensor's travel between them is far below a millimetre.
constexpr float kSweepBinDeg = 0.1f;
constexpr int kSweepBins = int(360.f / kSweepBinDeg + 0.5f);

// The bin of azimuth `yaw` [rad].
std::size_t SweepBin(float yaw) {
  return std::size_t(std::clamp(int(std::floor((yaw * 180.f / kPiF + 180.f) / kSweepBinDeg)), 0, kSweepBins - 1));
}
}  // namespace

SweepFrames::SweepFrames(const PointCloud& raw, const SweepMotion& motion) {
  raw.CheckConsistent("removert: raw sweep");  // a time per point
  if (raw.time.empty() || raw.empty() || !motion.known) return;
  const int bins = kSweepBins;
  std::vector<double> sum(std::size_t(bins), 0.0);
  std::vector<int> n(std::size_t(bins), 0);
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const PointXYZI& p = raw.points[i];
    const std::size_t b = SweepBin(FastAtan2(p.y, p.x));
    sum[b] += raw.time[i];
    ++n[b];
  }
  // A bin without a return takes the time of the nearest bin with one (around the circle).
  std::vector<double> time(std::size_t(bins), 0.0);
  for (int b = 0; b < bins; ++b)
    for (int d = 0; d <= bins / 2; ++d) {
      const std::size_t lo = std::size_t((b - d + bins) % bins), hi = std::size_t((b + d) % bins);
      if (n[lo] || n[hi]) {
        time[std::size_t(b)] = n[lo] ? sum[lo] / n[lo] : sum[hi] / n[hi];
        break;
      }
    }
  for (const double t : time) {  // io::Deskew: q = R(t) p + t v, so p = R(t)^T (q - t v)
    turn_.push_back(motion.RotationAt(t).transpose().cast<float>());
    const Eigen::Vector3f origin = (t * motion.v_mps).cast<float>();
    Rows& r = rows_.emplace_back();
    for (int a = 0; a < 3; ++a) {
      for (int c = 0; c < 3; ++c) r.row[a][c] = turn_.back()(a, c);
      r.row[a][3] = origin(a);
    }
  }
}

Eigen::Vector3f SweepFrames::Origin(std::size_t bin) const {
  const Rows& r = rows_[bin];
  return Eigen::Vector3f(r.row[0][3], r.row[1][3], r.row[2][3]);
}

std::size_t SweepFrames::FiringBin(const Eigen::Vector3f& q) const {
  const std::size_t b = SweepBin(FastAtan2(q.y(), q.x()));
  const Eigen::Vector3f p = turn_[b] * (q - Origin(b));
  return SweepBin(FastAtan2(p.y(), p.x()));  // the column that fired towards q as its own frame sees q
}

Eigen::Vector3f SweepFrames::ToFiring(const Eigen::Vector3f& q, Eigen::Matrix3f* R) const {
  const std::size_t b = FiringBin(q);
  if (R) *R = turn_[b];
  return turn_[b] * (q - Origin(b));
}

#if defined(__SSE2__)
namespace {
// SweepBin of four azimuths [rad], lane by lane. The quotient is negative only by rounding, where
// truncation and floor both clamp to bin 0.
inline __m128i SweepBin4(__m128 yaw) {
  const __m128 deg = _mm_div_ps(_mm_mul_ps(yaw, _mm_set1_ps(180.f)), _mm_set1_ps(kPiF));
  __m128i b = _mm_cvttps_epi32(_mm_div_ps(_mm_add_ps(deg, _mm_set1_ps(180.f)), _mm_set1_ps(kSweepBinDeg)));
  b = _mm_andnot_si128(_mm_cmplt_epi32(b, _mm_setzero_si128()), b);
  const __m128i last = _mm_set1_epi32(kSweepBins - 1);
  const __m128i past = _mm_cmpgt_epi32(b, last);
  return _mm_or_si128(_mm_and_si128(past, last), _mm_andnot_si128(past, b));
}

// One step of SweepFrames::ToFiring for four points q (x, y, z lanes): each lane's bin from the
// azimuth of `at`, then p = turn[bin] (q - origin[bin]) in Eigen's association (as Project). Each
// bin's 12 floats in `rows` (turn's rows, each followed by origin's coordinate: 16-byte aligned) are
// transposed into lanes.
void FiringStep4(const float* rows, const __m128* q, __m128 at_x, __m128 at_y, __m128* p,
                 std::int32_t* bin) {
  _mm_storeu_si128(reinterpret_cast<__m128i*>(bin), SweepBin4(FastAtan2x4(at_y, at_x)));
  __m128 m[3][4];  // [row][column 0..2 of turn, origin]
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 4; ++k) m[r][k] = _mm_load_ps(rows + 12 * bin[k] + 4 * r);
    _MM_TRANSPOSE4_PS(m[r][0], m[r][1], m[r][2], m[r][3]);
  }
  const __m128 d[3] = {_mm_sub_ps(q[0], m[0][3]), _mm_sub_ps(q[1], m[1][3]), _mm_sub_ps(q[2], m[2][3])};
  for (int r = 0; r < 3; ++r)
    p[r] = _mm_add_ps(_mm_mul_ps(m[r][0], d[0]), _mm_add_ps(_mm_mul_ps(m[r][1], d[1]), _mm_mul_ps(m[r][2], d[2])));
}
}  // namespace
#endif

void SweepFrames::ToFiring4(const float* q, float* p, const Eigen::Matrix3f** turn, float* range, float* pitch,
                            float* yaw) const {
#if defined(__SSE2__)
  const __m128 qv[3] = {_mm_loadu_ps(q), _mm_loadu_ps(q + 4), _mm_loadu_ps(q + 8)};
  __m128 pv[3];
  std::int32_t bin[4];
  const float* rows = rows_.front().row[0];
  FiringStep4(rows, qv, qv[0], qv[1], pv, bin);
  FiringStep4(rows, qv, pv[0], pv[1], pv, bin);
  for (int k = 0; k < 4; ++k) turn[k] = &turn_[std::size_t(bin[k])];
  const __m128 x2 = _mm_mul_ps(pv[0], pv[0]), y2 = _mm_mul_ps(pv[1], pv[1]), z2 = _mm_mul_ps(pv[2], pv[2]);
  _mm_storeu_ps(range, _mm_sqrt_ps(_mm_add_ps(x2, _mm_add_ps(y2, z2))));  // Eigen's norm()
  _mm_storeu_ps(pitch, FastAtan2x4(pv[2], _mm_sqrt_ps(_mm_add_ps(x2, y2))));
  _mm_storeu_ps(yaw, FastAtan2x4(pv[1], pv[0]));
  for (int a = 0; a < 3; ++a) _mm_storeu_ps(p + 4 * a, pv[a]);
#else
  for (int k = 0; k < 4; ++k) {
    const std::size_t b = FiringBin(Eigen::Vector3f(q[k], q[4 + k], q[8 + k]));
    const Eigen::Vector3f pk = ToFiring(Eigen::Vector3f(q[k], q[4 + k], q[8 + k]), nullptr);
    turn[k] = &turn_[b];
    range[k] = pk.norm();
    pitch[k] = FastAtan2(pk.z(), std::sqrt(pk.x() * pk.x() + pk.y() * pk.y()));
    yaw[k] = FastAtan2(pk.y(), pk.x());
    for (int a = 0; a < 3; ++a) p[4 * a + k] = pk(a);
  }
#endif
}

namespace {
// The keyframe's scan file, deskewed with its session's motion (io::ReadScan) or as read (raw).
std::shared_ptr<const PointCloud> ReadKeyframeFile(const WorldKeyframe& kf, bool deskew) {
  if (kf.cloud_path.empty())
    throw Error("removert: keyframe " + std::to_string(kf.index) + " has neither a cloud nor a path");
  auto cloud = std::make_shared<PointCloud>(deskew ? io::ReadScan(kf.cloud_path, kf.sweep) : io::ReadCloud(kf.cloud_path));
  geometry::RemoveNonFinite(*cloud);
  io::RequireScanPoints(*cloud, kf.cloud_path + " (keyframe " + std::to_string(kf.index) + ")");
  return cloud;
}
}  // namespace

// A scan read from its file must hold finite points (the stages' one check, as in LT-SLAM); a
// cloud given in memory is the caller's (an empty one is "no returns", used by the tests).
std::shared_ptr<const PointCloud> LoadScan(const WorldKeyframe& kf) {
  return kf.cloud ? kf.cloud : ReadKeyframeFile(kf, true);
}

std::shared_ptr<const PointCloud> LoadVoterScan(const WorldKeyframe& kf, const SweepTiming& timing,
                                                SweepFrames* frames) {
  if (frames) *frames = SweepFrames();
  if (!kf.sweep.known) return LoadScan(kf);  // a raw sweep then is an error (io::ReadScan says so)
  std::shared_ptr<const PointCloud> raw = kf.cloud ? kf.cloud : ReadKeyframeFile(kf, false);
  if (raw->time.empty() && timing.known) raw = std::make_shared<const PointCloud>(io::Reskew(*raw, kf.sweep, timing));
  if (frames && !raw->time.empty()) *frames = SweepFrames(*raw, kf.sweep);
  return raw;
}

PointCloud ToLocal(const PointCloud& cloud, const Pose& T_world_sensor) {
  return geometry::Transform(cloud, T_world_sensor.inverse());
}

}  // namespace detail

namespace {
using detail::kHit, detail::kOcc, detail::kSee, detail::kSeeOwn;

// What one CountVisibility call fixes: the points' tile index, the options and the vote test.
struct VoteSetup {
  const detail::TileIndex& index;
  const VisibilityOptions& options;
  detail::VoteTest test;
  std::size_t levels = 0;
  float radius = 0.f;
  bool surface = false;  // a sensor-frame plane per point (the surface hit and / or the beam test)
  bool beams = false;    // the beam test (options.beams)
  bool SurfaceVotes() const { return surface && test.surface_max > 0.f; }
};

VoteSetup MakeSetup(const RemovertConfig& cfg, const detail::TileIndex& index, const VisibilityOptions& options,
                    std::size_t levels) {
  VoteSetup s{index, options, {}, levels, float(cfg.submap_radius_m)};
  s.test.tol_abs = float(cfg.tol_abs_m);
  s.test.tol_rel = float(cfg.tol_rel);
  s.test.surface_max = float(options.surface_max_m);
  s.test.occluded = options.count_occluded ? kOcc : 0;
  s.test.see_own = options.count_own_see ? detail::kSeeOwn : 0;
  if (options.count_own_see && options.beams) {  // the beam test's tolerance, growing with the range
    s.test.own_tol_abs = float(options.beams->tol_m);
    s.test.own_tol_rel = float(cfg.LdOwnTolRel());
  }
  // A point's direction seen from another keyframe is off by the poses' relative rotation (yaw,
  // the odometry's largest error, moves it along the columns): the window is read there too.
  // Without rings only where the point's own window has evidence: there the windows at yaw -+ it
  // may hold returns of the pattern's other passes, no ray near the point (evidence from nothing),
  // so they may only withdraw a see-through, never make one.
  s.test.yaw_sigma = float(cfg.pose_sigma_deg * kRadPerDeg);
  s.test.yaw_needs_own = cfg.SensorResolved() && !cfg.sensor_model.ring_based;
  s.beams = options.normals != nullptr && options.beams != nullptr;
  s.surface = options.normals != nullptr && (s.test.surface_max > 0.f || s.beams);
  return s;
}

// One worker's state: a keyframe's range images (reused from keyframe to keyframe) and one
// tile's projections (valid points: position in the tile, range, pitch, yaw, sensor-frame plane)
// and votes.
struct Scratch {
  Scratch(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg, const VoteSetup& s)
      : img(cfg, resolutions_deg, s.SurfaceVotes(), s.options.within_beams) {
    if (s.beams) columns = std::make_unique<detail::ColumnImage>(cfg, *s.options.beams);
  }
  detail::MultiResImage img;
  std::unique_ptr<detail::ColumnImage> columns;  // beam test
  detail::SweepFrames frames;                    // the keyframe's raw sweep (images in its firing frames)
  std::vector<Eigen::Vector3f> fired_at;         // with frames: per projected point, itself in its
  std::vector<const Eigen::Matrix3f*> fired_turn;  // column's firing frame, and that frame's rotation (SweepFrames')
  std::vector<std::uint32_t> idx;
  std::vector<float> range, pitch, yaw, plane;
  std::size_t valid = 0;                 // projected points of the current tile
  std::vector<std::uint8_t> votes;       // [level * tile size + position in the tile]
  std::vector<std::uint8_t> seen_beams;  // [position in the tile]
};

// A raw sweep's images: each projected point of the tile from b seen from where its column fired
// (SweepFrames::ToFiring4, four at a time; the last group repeats its last point).
void FiringAngles(const VoteSetup& s, const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, std::uint32_t b,
                  Scratch* sc) {
  const auto& ix = s.index;
  sc->fired_at.resize(sc->valid);
  sc->fired_turn.resize(sc->valid);
  float q[12], p[12], range[4], pitch[4], yaw[4];
  const Eigen::Matrix3f* turn[4];
  for (std::size_t j0 = 0; j0 < sc->valid; j0 += 4) {
    const std::size_t m = std::min<std::size_t>(4, sc->valid - j0);
    for (std::size_t k = 0; k < 4; ++k) {
      const std::size_t i = b + sc->idx[j0 + std::min(k, m - 1)];
      const Eigen::Vector3f v = Rt * (Eigen::Vector3f(ix.x()[i], ix.y()[i], ix.z()[i]) - c);
      for (std::size_t a = 0; a < 3; ++a) q[4 * a + k] = v(Eigen::Index(a));
    }
    sc->frames.ToFiring4(q, p, turn, range, pitch, yaw);
    for (std::size_t k = 0; k < m; ++k) {
      sc->fired_at[j0 + k] = Eigen::Vector3f(p[k], p[4 + k], p[8 + k]);
      sc->fired_turn[j0 + k] = turn[k];
      sc->range[j0 + k] = range[k];
      sc->pitch[j0 + k] = pitch[k];
      sc->yaw[j0 + k] = yaw[k];
    }
  }
}

// The tile's points [b, b + tn) in the keyframe's images (sensor at c, R^T = Rt): sc->valid.
void ProjectTile(const VoteSetup& s, const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, std::uint32_t b,
                 std::size_t tn, Scratch* sc) {
  if (sc->idx.size() < tn) {
    sc->idx.resize(tn);
    sc->range.resize(tn + 3);
    sc->pitch.resize(tn + 3);
    sc->yaw.resize(tn + 3);
    if (s.surface) sc->plane.resize(4 * (tn + 3));
  }
  const auto& ix = s.index;
  sc->valid = sc->img.Project(ix.x() + b, ix.y() + b, ix.z() + b, tn, c, Rt, s.radius * s.radius, sc->idx.data(),
                              sc->range.data(), sc->pitch.data(), sc->yaw.data());
  if (sc->frames.active()) FiringAngles(s, c, Rt, b, sc);
  for (std::size_t j = sc->valid; j < sc->valid + 3; ++j) sc->range[j] = sc->pitch[j] = sc->yaw[j] = 0.f;  // padding
}

// Point k's surface extent (VisibilityOptions::passed_at) in the sensor frame, in *out; null where
// it is not asked.
const SurfaceExtent* InsideOf(const VoteSetup& s, const Eigen::Matrix3f& Rt, std::size_t k, SurfaceExtent* out) {
  if (s.options.passed_at == nullptr) return nullptr;
  const SurfaceExtent& e = (*s.options.passed_at)[k];
  if (e.above <= 0.f && e.below <= 0.f && e.left <= 0.f && e.right <= 0.f) return nullptr;
  *out = e;
  out->up = Rt * e.up;
  return out;
}

// Each projected point's plane in the sensor frame: normal n_s = Rt n, offset n_s . (Rt (p - c)),
// and with the beam test whether the beams saw it.
void SensorPlanes(const VoteSetup& s, const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, std::uint32_t b,
                  std::size_t tn, Scratch* sc) {
  if (s.beams) sc->seen_beams.assign(tn, 0);
  const auto& ix = s.index;
  SurfaceExtent inside;
  for (std::size_t j = 0; j < sc->valid; ++j) {
    const std::size_t i = b + sc->idx[j];
    const bool fired = sc->frames.active();  // world to the (firing) sensor frame: ProjectTile's
    const Eigen::Vector3f ps = fired ? sc->fired_at[j] : Eigen::Vector3f(Rt * (Eigen::Vector3f(ix.x()[i], ix.y()[i], ix.z()[i]) - c));
    const Eigen::Matrix3f R = fired ? Eigen::Matrix3f(*sc->fired_turn[j] * Rt) : Rt;
    const Eigen::Vector3f ns = R * (*s.options.normals)[ix.order()[i]];
    const Eigen::Vector3f up = R.col(2);  // the world's up in the sensor frame
    float* pl = &sc->plane[4 * j];
    pl[0] = ns.x();
    pl[1] = ns.y();
    pl[2] = ns.z();
    pl[3] = ns.dot(ps);
    // A point whose plane takes no surface hits: a plane of NaNs, on which no return lies.
    if (s.options.surface_at != nullptr && !(*s.options.surface_at)[ix.order()[i]])
      std::fill(pl, pl + 4, std::numeric_limits<float>::quiet_NaN());
    const auto asked = [&](const std::vector<bool>* at) { return at != nullptr && (*at)[ix.order()[i]]; };
    if (!s.beams) continue;
    detail::PointInWorld world;
    if (s.options.hit_surfaces != nullptr)
      world = {s.options.hit_surfaces, Eigen::Vector3f(ix.x()[i], ix.y()[i], ix.z()[i]), R.transpose()};
    sc->seen_beams[sc->idx[j]] =
        sc->columns->Observed({sc->range[j], sc->pitch[j], sc->yaw[j], ps, pl},
                              {s.options.count_own_see, asked(s.options.through_at), InsideOf(s, R, ix.order()[i], &inside),
                               asked(s.options.line_at) ? &up : nullptr,
                               s.options.hit_surfaces != nullptr ? &world : nullptr});
  }
}

// The tile's votes per level (see / hit / occluded bits) into sc->votes.
void VoteTile(const VoteSetup& s, std::size_t tn, Scratch* sc) {
  sc->votes.assign(s.levels * tn, 0);
  for (std::size_t l = 0; l < s.levels; ++l) {
    std::uint8_t* vote = sc->votes.data() + l * tn;
    const int level = int(l);
    if (s.SurfaceVotes())
      detail::VoteLevel<true>(sc->img.GridOf(level), sc->img.Pairs(level), s.test, sc->valid, sc->idx.data(),
                              sc->range.data(), sc->pitch.data(), sc->yaw.data(), sc->plane.data(),
                              sc->img.Returns(level), vote);
    else
      detail::VoteLevel<false>(sc->img.GridOf(level), sc->img.Pairs(level), s.test, sc->valid, sc->idx.data(),
                               sc->range.data(), sc->pitch.data(), sc->yaw.data(), nullptr, nullptr, vote);
  }
}

// Counters in tile order; each keyframe adds at most 1 per point and level, so uint16 with fewer
// than 65535 keyframes never overflows. A worker adds one tile's votes under the tile's lock:
// plain adds instead of one atomic per point and level, and workers on different keyframes
// rarely want the same tile at the same time.
struct VoteCounts {
  VoteCounts(const VoteSetup& s, std::size_t n)
      : n(n), levels(s.levels), see_needs_beam(s.beams && !s.options.count_own_see), see(n * s.levels, 0),
        hit(n * s.levels, 0), occ(s.test.occluded ? n * s.levels : 0, 0),
        see_own(s.test.see_own ? n * s.levels : 0, 0),
        beam_hits(s.beams ? n : 0, 0), beam_around(s.beams && s.options.count_own_see ? n : 0, 0),
        beam_passed(beam_around.size(), 0), beam_through(s.beams && s.options.AsksThrough() ? n : 0, 0),
        locks(new std::mutex[s.index.tiles()]) {}

  void Add(std::uint32_t tile, std::uint32_t b, std::size_t tn, const Scratch& sc) {
    const std::lock_guard<std::mutex> lock(locks[tile]);
    if (!beam_hits.empty()) {
      std::uint16_t* ov = beam_hits.data() + b;
      for (std::size_t i = 0; i < tn; ++i) ov[i] = std::uint16_t(ov[i] + (sc.seen_beams[i] & detail::kBeamEnded));
    }
    if (!beam_around.empty()) {
      std::uint16_t* av = beam_around.data() + b;
      for (std::size_t i = 0; i < tn; ++i) av[i] = std::uint16_t(av[i] + ((sc.seen_beams[i] & detail::kBeamAround) >> 1));
      std::uint16_t* pv = beam_passed.data() + b;
      for (std::size_t i = 0; i < tn; ++i) pv[i] = std::uint16_t(pv[i] + ((sc.seen_beams[i] & detail::kBeamPassed) >> 2));
    }
    if (!beam_through.empty()) {
      std::uint16_t* tv = beam_through.data() + b;
      for (std::size_t i = 0; i < tn; ++i) tv[i] = std::uint16_t(tv[i] + ((sc.seen_beams[i] & detail::kBeamThrough) >> 3));
    }
    for (std::size_t l = 0; l < levels; ++l) {
      const std::uint8_t* vote = sc.votes.data() + l * tn;
      std::uint16_t* sv = see.data() + l * n + b;
      std::uint16_t* hv = hit.data() + l * n + b;
      for (std::size_t i = 0; i < tn; ++i) {
        const bool see = (vote[i] & kSee) && (!see_needs_beam || (sc.seen_beams[i] & detail::kBeamNear));
        sv[i] = std::uint16_t(sv[i] + (see ? 1 : 0));
        hv[i] = std::uint16_t(hv[i] + ((vote[i] & kHit) >> 1));
      }
      if (!occ.empty()) {
        std::uint16_t* ov = occ.data() + l * n + b;
        for (std::size_t i = 0; i < tn; ++i) ov[i] = std::uint16_t(ov[i] + ((vote[i] & kOcc) >> 2));
      }
      if (!see_own.empty()) {
        std::uint16_t* ov = see_own.data() + l * n + b;
        for (std::size_t i = 0; i < tn; ++i) ov[i] = std::uint16_t(ov[i] + ((vote[i] & kSeeOwn) >> 3));
      }
    }
  }

  // The counters in the caller's point order.
  void ToInputOrder(const std::vector<std::uint32_t>& order, VisibilityVotes* out) const {
    for (std::size_t i = 0; i < beam_hits.size(); ++i) out->beam_hits[std::size_t(order[i])] = beam_hits[i];
    for (std::size_t i = 0; i < beam_around.size(); ++i) out->beam_around[std::size_t(order[i])] = beam_around[i];
    for (std::size_t i = 0; i < beam_passed.size(); ++i) out->beam_passed[std::size_t(order[i])] = beam_passed[i];
    for (std::size_t i = 0; i < beam_through.size(); ++i) out->beam_through[std::size_t(order[i])] = beam_through[i];
    for (std::size_t l = 0; l < levels; ++l)
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t orig = std::size_t(order[i]);
        out->see[l * n + orig] = see[l * n + i];
        out->hit[l * n + orig] = hit[l * n + i];
        if (!occ.empty()) out->occ[l * n + orig] = occ[l * n + i];
        if (!see_own.empty()) out->see_own[l * n + orig] = see_own[l * n + i];
      }
  }

  std::size_t n, levels;
  // ND (the beam test, not the own pixel): a pixel's see-through counts only from a keyframe a beam
  // of which passed within the tolerance of the point (kBeamNear). A sparse sensor's pixel between
  // two beams also holds what lies behind a surface's edge; the beam truth calls the point
  // observed only where a ray passed it.
  bool see_needs_beam;
  std::vector<std::uint16_t> see, hit, occ, see_own, beam_hits, beam_around, beam_passed, beam_through;
  std::unique_ptr<std::mutex[]> locks;
};

void CheckVisibilityInput(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                          const VisibilityOptions& options) {
  if (options.normals && options.normals->size() != points.size())
    throw Error("removert: " + std::to_string(options.normals->size()) + " normals for " +
                std::to_string(points.size()) + " points");
  if (options.surface_at && options.surface_at->size() != points.size())
    throw Error("removert: " + std::to_string(options.surface_at->size()) + " surface flags for " +
                std::to_string(points.size()) + " points");
  if (keyframes.size() >= 65535)
    throw Error("removert: " + std::to_string(keyframes.size()) +
                " keyframes in one session; vote counters hold at most 65534");
}

VisibilityVotes ZeroVotes(std::size_t n, std::size_t levels, const VisibilityOptions& options) {
  VisibilityVotes out;
  out.points = n;
  out.levels = int(levels);
  out.see.assign(n * levels, 0);
  out.hit.assign(n * levels, 0);
  if (options.count_occluded) out.occ.assign(n * levels, 0);
  if (options.count_own_see) out.see_own.assign(n * levels, 0);
  if (options.normals != nullptr && options.beams != nullptr) {
    out.beam_hits.assign(n, 0);
    if (options.count_own_see) out.beam_around.assign(n, 0), out.beam_passed.assign(n, 0);
    if (options.AsksThrough()) out.beam_through.assign(n, 0);
  }
  return out;
}
}  // namespace

VisibilityVotes CountVisibility(const PointCloud& points, const std::vector<WorldKeyframe>& keyframes,
                                const std::vector<double>& resolutions_deg,
                                const RemovertConfig& user_cfg, int threads,
                                const VisibilityOptions& options) {
  const RemovertConfig cfg = keyframes.empty() ? user_cfg : WithSensor(user_cfg, keyframes, threads);
  CheckVisibilityInput(points, keyframes, options);
  VisibilityVotes out = ZeroVotes(points.size(), resolutions_deg.size(), options);
  if (points.empty() || resolutions_deg.empty() || keyframes.empty()) return out;

  const detail::TileIndex index(points, cfg.tile_m);
  const VoteSetup setup = MakeSetup(cfg, index, options, resolutions_deg.size());
  VoteCounts counts(setup, points.size());
  tbb::enumerable_thread_specific<Scratch> scratch([&] { return Scratch(cfg, resolutions_deg, setup); });
  detail::ParallelFor(keyframes.size(), threads, [&](std::size_t k) {
    const WorldKeyframe& kf = keyframes[k];
    const Eigen::Vector3f c = kf.T_world_sensor.translation().cast<float>();
    bool near = false;  // no point within its radius: no vote, so its scan is not even read
    index.ForTilesNear(c, setup.radius, [&](std::uint32_t, std::uint32_t, std::uint32_t) { near = true; });
    if (!near) return;
    Scratch& sc = scratch.local();
    {
      const auto scan = detail::LoadVoterScan(kf, cfg.sweep_timing, &sc.frames);
      sc.img.Build(*scan);
      if (setup.beams) sc.columns->Build(*scan);
    }
    const Eigen::Matrix3f Rt = kf.T_world_sensor.linear().transpose().cast<float>();
    index.ForTilesNear(c, setup.radius, [&](std::uint32_t tile, std::uint32_t b, std::uint32_t e) {
      ProjectTile(setup, c, Rt, b, e - b, &sc);
      if (sc.valid == 0) return;
      if (setup.surface) SensorPlanes(setup, c, Rt, b, e - b, &sc);
      VoteTile(setup, e - b, &sc);
      counts.Add(tile, b, e - b, sc);
    });
  });
  counts.ToInputOrder(index.order(), &out);
  return out;
}

}  // namespace ltm::removert
