// Private to the removert module (not installed): the range images of one scan (multi-resolution
// images, the beam columns of the BeamTest) (visibility.cpp, occlusion.cpp).
#pragma once

#include "ltmapper/removert/config.hpp"
#include "ltmapper/removert/visibility.hpp"

#include "ltmapper/geometry/geometry.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

namespace ltm::removert::detail {

constexpr float kPiF = 3.14159265358979323846f;

// atan2 with |error| < 2e-5 rad (minimax polynomial of atan on [0, 1] plus octant folding).
// Pixels are >= 0.1 deg = 1.7e-3 rad, so at most ~1 % of points on a pixel border can land in
// the neighbouring pixel compared with std::atan2: harmless for voting, 5x faster.
inline float FastAtan2(float y, float x) {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float mx = ax > ay ? ax : ay;
  const float mn = ax > ay ? ay : ax;
  if (mx == 0.f) return 0.f;
  const float a = mn / mx;
  const float s = a * a;
  float r = ((((0.0208351f * s - 0.085133f) * s + 0.180141f) * s - 0.3302995f) * s + 0.999866f) * a;
  if (ay > ax) r = 0.5f * kPiF - r;
  if (x < 0.f) r = kPiF - r;
  return y < 0.f ? -r : r;
}

// A raw sweep's columns fired from the poses the sensor passed through while it turned (each point
// of the file in the frame of its column's firing; io::Deskew moves it into the keyframe frame with
// the session's SweepMotion: q = R(t) p + t v). Range images built from the raw points keep the beams'
// own elevations (a deskewed sweep's are bent by up to the sweep's travel over the range); a point
// asked in the keyframe frame is asked in the frame of the column that fired towards it (ToFiring).
class SweepFrames {
 public:
  SweepFrames() = default;
  // From the raw points' times per azimuth (inactive without times or a known motion).
  SweepFrames(const PointCloud& raw, const SweepMotion& motion);
  bool active() const { return !turn_.empty(); }
  // q (keyframe frame) in the frame of the column fired towards it (two fixed-point steps over the
  // column's time); *R (may be null) is that frame's rotation from the keyframe frame.
  Eigen::Vector3f ToFiring(const Eigen::Vector3f& q, Eigen::Matrix3f* R) const;
  // ToFiring of four points, lane by lane with the same float operations (SSE2 where built with
  // it): q and p hold x[4], y[4], z[4]; turn[k] is point k's *R. range / pitch / yaw[4] are p's
  // angles as MultiResImage's images take them.
  void ToFiring4(const float* q, float* p, const Eigen::Matrix3f** turn, float* range, float* pitch,
                 float* yaw) const;

 private:
  std::size_t FiringBin(const Eigen::Vector3f& q) const;  // the bin of the column fired towards q
  Eigen::Vector3f Origin(std::size_t bin) const;         // the bin's firing frame's origin
  // Per azimuth bin (kSweepBinDeg, visibility.cpp): the rotation from the keyframe frame to the
  // frame its column fired from, and (rows_) the same row by row, each row followed by one
  // coordinate of that frame's origin in the keyframe frame (16-byte aligned, for ToFiring4).
  std::vector<Eigen::Matrix3f> turn_;
  struct alignas(16) Rows {
    float row[3][4];
  };
  std::vector<Rows> rows_;
};

// The range image of one resolution: square pixels of `pixel_deg`, same pixel rule as
// geometry::RangeImage (row 0 = top of the FOV, column 0 at azimuth +180 deg, decreasing azimuth).
geometry::RangeImageConfig LevelConfig(const RemovertConfig& cfg, double pixel_deg);

// Range images of one scan at several resolutions, built from one (pitch, yaw) evaluation per
// point. Min range per pixel, +inf = no return. Build() reuses the buffers, so one image per
// worker serves all its keyframes.
class MultiResImage {
 public:
  // keep_returns: Build() also keeps each pixel's nearest return (sensor frame, Returns()).
  // within_beams: points are judged only within the beams' span (PointBounds; HD removal), else
  // anywhere in the images' FOV (LD: a change above the top beam is still judged by it).
  MultiResImage(const RemovertConfig& cfg, const std::vector<double>& resolutions_deg, bool keep_returns = false,
                bool within_beams = false);
  // Projects a scan (sensor frame); returns within [min_range, max_range] only. Then each
  // level's min-pooled twin: the min over the (2w+1) x (2w+1) window centred on each pixel
  // (columns wrap around), w = window_px.
  void Build(const PointCloud& scan);
  int levels() const { return int(levels_.size()); }
  // Angles of a scan return (sensor frame). False when outside the images' vertical FOV or at
  // ~0 range. Project() and Build() evaluate the same float operations four points at a time
  // (SSE2): keep them in step.
  bool Angles(const Eigen::Vector3f& p, float* range, float* pitch, float* yaw) const {
    return AnglesWithin(p, up_, down_, range, pitch, yaw);
  }
  // The same for a point to judge: within the beams' span (PointBounds), else false.
  bool PointAngles(const Eigen::Vector3f& p, float* range, float* pitch, float* yaw) const {
    return AnglesWithin(p, point_up_, point_down_, range, pitch, yaw);
  }
  // The points (x[i], y[i], z[i]) (world frame; readable up to n + 3: batches of four) within
  // 3D distance sqrt(radius2) of the sensor position c, moved into the sensor frame
  // (Rt (p - c)), whose PointAngles() are valid: returns how many; their input positions go to
  // idx[0, count) and their Angles() to range / pitch / yaw[0, count) (n long each). Batches of
  // four (SSE2) use the same float operations in the same order as the scalar code (Eigen's
  // products included), so the results are identical.
  std::size_t Project(const float* x, const float* y, const float* z, std::size_t n,
                      const Eigen::Vector3f& c, const Eigen::Matrix3f& Rt, float radius2,
                      std::uint32_t* idx, float* range, float* pitch, float* yaw) const;
  // One level's pixel rule, small enough for hot loops to keep in registers.
  struct Grid {
    int rows = 0, cols = 0;
    float row_scale = 0.f, col_scale = 0.f;  // pixels per rad
    float up = 0.f;                          // [rad] top of the FOV
    // rows x cols pixels of row_deg x col_deg over the config's vertical FOV and 360 deg.
    static Grid Make(const RemovertConfig& cfg, double row_deg, double col_deg);
    int Row(float pitch) const {
      int row = int((up - pitch) * row_scale);
      if (row >= rows) row = rows - 1;
      if (row < 0) row = 0;
      return row;
    }
    int Col(float yaw) const {
      int col = int((kPiF - yaw) * col_scale);
      if (col >= cols) col -= cols;
      if (col < 0) col = 0;
      return col;
    }
    std::size_t Pixel(float pitch, float yaw) const {
      return std::size_t(Row(pitch)) * std::size_t(cols) + std::size_t(Col(yaw));
    }
  };
  const Grid& GridOf(int level) const { return levels_[std::size_t(level)].grid; }
  std::size_t Pixel(int level, float pitch, float yaw) const { return GridOf(level).Pixel(pitch, yaw); }
  // (pooled, range) of each pixel side by side: the vote test reads both, from one cache line.
  const float* Pairs(int level) const { return levels_[std::size_t(level)].pairs.data(); }
  // Per pixel, the sensor-frame position of its nearest return (only with keep_returns; valid
  // where the pixel has a return).
  const Eigen::Vector3f* Returns(int level) const { return levels_[std::size_t(level)].ret.data(); }
  int Cols(int level) const { return GridOf(level).cols; }

 private:
  static bool AnglesWithin(const Eigen::Vector3f& p, float up, float down, float* range, float* pitch, float* yaw) {
    const float rxy2 = p.x() * p.x() + p.y() * p.y();
    const float r = std::sqrt(rxy2 + p.z() * p.z());
    if (!(r > 1e-6f)) return false;
    const float pt = FastAtan2(p.z(), std::sqrt(rxy2));
    if (pt > up || pt < down) return false;
    *range = r;
    *pitch = pt;
    *yaw = FastAtan2(p.y(), p.x());
    return true;
  }
  // [rad] The elevations a point may have to be judged (point_up_, point_down_): a ring sensor's
  // outermost beams widened by their scatter (SensorModel::spread_deg). Beyond them no ray passes
  // on the far side of a point: the one beam on its near side returning farther (grazing ground
  // below the lowest beam of a tilted sensor) is no evidence that its place is free. Without
  // rings (or a resolved sensor) the images' FOV.
  void PointBounds(const RemovertConfig& cfg);
  static std::vector<int> WindowRows(const RemovertConfig& cfg, int rows, double row_deg);
  struct Level {
    Grid grid;
    std::vector<int> window_rows;  // per row: how far the pool looks for the nearest beam (WindowRows)
    int scatter_rows = 0;          // rows within the beams' estimated scatter: pooled whole
    bool both_sides = false;       // no rings: evidence only with a return above and below
    std::vector<std::uint8_t> sides;
    std::vector<float> range, pooled, tmp, pairs;
    std::vector<Eigen::Vector3f> ret;  // keep_returns
  };
  void Pool(Level& L) const;         // PoolColumns then PoolRows (or a copy when window_px is 0)
  void PoolColumns(Level& L) const;  // horizontal min over +-window_px columns into tmp
  void PoolRows(Level& L) const;     // vertical: scatter rows whole, then the nearest beam above / below
  bool keep_returns_ = false;
  int window_ = 0;
  float up_ = 0.f, down_ = 0.f;              // [rad] the images' vertical FOV (scan returns)
  float point_up_ = 0.f, point_down_ = 0.f;  // [rad] points judged (PointBounds)
  float min_range_ = 0.f, max_range_ = 0.f;
  std::vector<Level> levels_;
};

// A scan's nearest return per (column, row) cell of BeamTest::col_deg x row_deg, stored column
// by column: rows far finer than the beam spacing, so the rows between two beams stay empty and
// the first returns above and below a direction are the two beams around it.
constexpr std::uint8_t kBeamEnded = 1, kBeamAround = 2, kBeamPassed = 4, kBeamThrough = 8,
                       kBeamNear = 16;  // ColumnImage::Observed
// Where the beams of a session ended, in world coordinates: its map's points within reach of the
// points asked (ReachM), each with the normal of its map within BeamTest::tol_m of it (planar
// neighbourhoods only). The beam truth takes a return's along-ray tolerance from the incidence on
// the surface the ray met (tol / cos, at most grazing_max_m): a grazing ray that ended on a curb's
// face 1.5 m short of a point on the pavement behind it did not end on that point's surface, though
// the face's foot lies on the point's plane.
class HitSurfaces {
 public:
  HitSurfaces(const PointCloud& map, const PointCloud& points, const BeamTest& test, int threads);
  ~HitSurfaces();
  // [m] How far from a point the map points the test reads may lie: the ray within tol of the
  // point and its return within grazing_max_m along it, the return's nearest map point within tol
  // of it, and that point's normal from its neighbours within tol.
  static double ReachM(const BeamTest& test) { return test.grazing_max_m + 3.0 * test.tol_m; }
  // |cos| of the angle between unit `dir` and the surface at `at` (world); false where no map point
  // with a planar neighbourhood lies within tol of `at`.
  bool Cosine(const Eigen::Vector3f& at, const Eigen::Vector3f& dir, float* cosine) const;

 private:
  float tol_;
  std::unique_ptr<geometry::KdTree> tree_;
  std::vector<Eigen::Vector3f> normals_;  // zero: no plane
};
// A point's sensor frame in the world, for HitSurfaces: the point (world) and the rotation from the
// (firing) sensor frame to the world.
struct PointInWorld {
  const HitSurfaces* surfaces = nullptr;
  Eigen::Vector3f at = Eigen::Vector3f::Zero();
  Eigen::Matrix3f to_world = Eigen::Matrix3f::Identity();
};

// A point as ColumnImage::Observed tests it: ps in the (firing) sensor frame, its range, pitch and
// yaw as MultiResImage::Angles gives them, on the plane n . x = off (plane[0..3], sensor frame).
struct BeamPoint {
  float range = 0.f, pitch = 0.f, yaw = 0.f;
  Eigen::Vector3f ps = Eigen::Vector3f::Zero();
  const float* plane = nullptr;
};
// What ColumnImage::Observed is asked beyond kBeamEnded (see there).
struct BeamAsk {
  bool want_around = false;               // PD: kBeamAround, kBeamPassed; ND (false): kBeamNear
  bool ask_through = false;               // kBeamThrough by a beam that crossed the plane
  const SurfaceExtent* inside = nullptr;  // kBeamThrough by the own column's beam (PassedInside)
  const Eigen::Vector3f* line_up = nullptr;  // a scan line's point: the world's up in the sensor frame;
                                             // kBeamThrough by a beam that passed it without a return
  const PointInWorld* world = nullptr;    // the surface a far return met (HitSurfaces)
};

// `test` as a ColumnImage for `cfg`'s sensor applies it: cells one azimuth step wide, rows at most
// half the finest beam spacing.
BeamTest ForSensor(const RemovertConfig& cfg, BeamTest test);
class ColumnImage {
 public:
  ColumnImage(const RemovertConfig& cfg, const BeamTest& test);
  void Build(const PointCloud& scan);
  // BeamTest for a point (BeamPoint) asked as `ask` says: kBeamEnded when a beam of
  // its column or of the columns within asin(tol / range) of it ended on its surface near it;
  // with want_around, kBeamAround when its cell is empty and the
  // beams around it met its surface farther away (Around), and kBeamPassed when a beam passed it
  // without a return (PassedWithoutReturn); with ask_through, kBeamThrough when none ended near
  // it, a beam of those columns crossed its plane within a map voxel of it and ended beyond the
  // crossing by more than tol / cos(incidence), uncapped (the beam truth's "observed absent"), and
  // no return of the scan lies on its plane within ld.normal_radius_m of it (MetSurfaceNear); with
  // `inside` (the point's surface extent, PassedInside; null = not asked), kBeamThrough also when none
  // ended near it and the beam of its own column passed it without a return crossing its surface
  // inside that extent (PassedInside), on the same MetSurfaceNear condition; with line_up (a scan
  // line's point over its own map's surface), kBeamThrough also when none ended near it, a beam passed
  // it without a return (PassedWithoutReturn), no return of the scan lies within ld.normal_radius_m of
  // it and the beams above and below it did not meet a surface at its distance (MetUnderOrOver).
  // Without want_around (ND), kBeamNear when a beam of the table passed within the tolerance of it
  // (BeamNear). With
  // `world` (null: not asked), a return farther than tol from the point along its ray ended near it
  // only within the along-ray tolerance of the surface it met too (HitSurfaces).
  std::uint8_t Observed(const BeamPoint& p, const BeamAsk& ask) const;
  // A ring sensor fires every beam at every azimuth step: a beam of the table whose ray passes
  // within the tolerance of the point (at its range, inside the sensor's max range) and whose
  // cells there and one step to each side hold no return went on past the point and met nothing
  // (the sky, or beyond the range): its place was free. A lone empty cell is a dropped return,
  // and a column without any return is the seam of a deskewed sweep (where it starts and ends),
  // no evidence. False for sensors without rings or a known azimuth step.
  bool PassedWithoutReturn(float range, float pitch, float yaw) const;
  // A beam of the point's own column (its neighbours on both sides empty too) that passed it without
  // a return (as above), along its true direction (the column's firing azimuth, read off a return
  // of that column, fired_; the table's elevation) within tol of the point, and that crossed the point's
  // plane inside its surface: within `inside`'s extent (along `inside.up` and the level direction
  // in the plane). A beam that passed within tol of a point but crossed the plane beyond the
  // surface's edge passed beside it (over a canopy's top, past a fence seen edge-on).
  bool PassedInside(float range, float pitch, float yaw, const Eigen::Vector3f& ps, const float* plane,
                    const SurfaceExtent& inside) const;
  // Whether the beam at elevation_deg of `m` can tell its returns from its neighbours': they
  // scatter (3 x the scans' spread, SensorModel::spread_deg) short of halfway to the next beam.
  // Only those beams are asked by PassedWithoutReturn and PassedInside; a deskewed sweep's spread
  // (its near returns, bent by the sensor's motion) may leave none.
  static bool TellsItsReturns(const geometry::SensorModel& m, double elevation_deg);
  // How many of a ring sensor's beams tell their returns (0 without rings).
  static int BeamsThatTell(const geometry::SensorModel& m);
  // Whether a beam of the sensor's table passed within the tolerance of a point at (range, pitch):
  // its elevation within asin(tol / range) of the pitch, widened by 3 x the scans' scatter. Always
  // for sensors without a beam table (no rings) or an azimuth step. The beam truth counts a point
  // observed only where a ray passed within the tolerance of it.
  bool BeamNear(float range, float pitch) const;

 private:
  // Column col (any, wrapped) holds no return in rows row_top..row_bottom, is swept, and no beam
  // within a row's span of them met a surface within the tolerance of the minimum range.
  bool EmptyColumn(int col, int row_top, int row_bottom) const;
  bool Around(float range, std::size_t column, int ra, int rb, const Eigen::Vector3f& ps, const float* plane) const;
  std::pair<int, int> BeamsAround(const float* rc, int row) const;
  // Calls f(elevation, reach, row_top, row_bottom) for each beam of the table whose elevation lies
  // within reach = asin(tol / range) of `pitch` (its rows: its elevation +- its margin), until f
  // returns true; false for sensors without rings or a known azimuth step, and outside
  // [min_range, max_range - tol].
  template <class F>
  bool AnyBeamNear(float range, float pitch, F&& f) const {
    const float tol = float(test_.tol_m);
    if (beam_el_.empty() || range < min_range_ || range + tol > max_range_) return false;
    const float reach = std::asin(std::min(1.f, tol / range));
    // beam_el_ runs top first.
    const auto first = std::lower_bound(beam_el_.begin(), beam_el_.end(), pitch + reach, std::greater<float>());
    for (auto b = std::size_t(first - beam_el_.begin()); b < beam_el_.size() && beam_el_[b] >= pitch - reach; ++b) {
      const float e = beam_el_[b];
      if (f(e, reach, grid_.Row(e + beam_margin_[b]), grid_.Row(e - beam_margin_[b]))) return true;
    }
    return false;
  }
  // Observed's steps: beam r of column c (its cells' offset c) ended on p's surface near it, or
  // went through p's place; either asked of a column's cell in p's row, else the beams around it.
  bool EndedNear(const BeamPoint& p, std::size_t c, int r, const PointInWorld* world) const;
  bool WentBeyond(const BeamPoint& p, std::size_t c, int r) const;
  template <class At>
  bool OwnOrAround(std::size_t c, int row, At&& at, int* ra, int* rb) const;
  // A return of the scan on the point's plane (within tol; any return where `plane` is null) within
  // surface_reach_m_ of it.
  bool MetSurfaceNear(float range, float pitch, float yaw, const Eigen::Vector3f& ps, const float* plane) const;
  // The nearest beams above and below a scan line's point in its column (and the columns beside it)
  // returned at its horizontal distance (within tol; level across `up`, the world's up in the sensor
  // frame: a tilted sensor's own z is not): the surface under or over it that the scan met (a
  // standing wall whose top row the point is), which a beam that passed it went over or under.
  bool MetUnderOrOver(const BeamPoint& p, int col, const Eigen::Vector3f& up) const;
  BeamTest test_;
  MultiResImage::Grid grid_;  // cells stored column by column: [col * rows + row]
  std::vector<int> span_;     // [rows] per row: how far above / below to look for the beams
  float down_ = 0.f;          // [rad]
  static constexpr std::uint8_t kNearBlind = 2;  // any_: a return within the tolerance of min range
  float min_range_ = 0.f, max_range_ = 0.f;
  float through_m_ = 0.f;        // [m] kBeamThrough: the beam crossed the point's plane this close to it
  float surface_reach_m_ = 0.f;  // [m] MetSurfaceNear's reach
  std::vector<float> range_;          // +inf = no return
  std::vector<Eigen::Vector3f> ret_;  // the cell's nearest return
  std::vector<std::uint8_t> any_;     // 1 = a return at any range, kNearBlind = one nearer than min
                                      // range + tol (EmptyColumn)
  std::vector<float> fired_;          // [cols] the azimuth [rad] of the column's returns, the one its
                                      // beams fired at (PassedInside); NaN = no return at all (deskewed
                                      // sweeps leave a seam of empty columns where they start and end)
  std::vector<float> table_el_;       // [rad] every beam's elevation, ascending (BeamNear; ring sensors
                                      // with an azimuth step)
  float table_reach_ = 0.f;           // [rad] BeamNear's widening: 3 x the scans' scatter
  std::vector<float> beam_el_;        // [rad] the beams' elevations (ring sensors with an azimuth step)
  std::vector<float> beam_margin_;    // [rad] per beam: its returns lie within this of its elevation
};

}  // namespace ltm::removert::detail
