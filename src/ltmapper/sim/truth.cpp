// Simulate(): casts every keyframe of every session, writes the sessions (SC-LIO-SAM layout) and
// the truth folder: true poses and origins, labelled scans, static worlds, LD objects and the
// point-wise change truth per (central, query) pair with occlusion-aware strong / weak split.
#include "ltmapper/geometry/geometry.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/sim/simulator.hpp"


#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <ostream>

namespace ltm::sim {

namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string Num(int i, int width) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%0*d", width, i);
  return buf;
}
std::string SessionName(int s) { return "session_" + Num(s, 2); }

void WriteObjectsCsv(const std::string& path, const std::vector<LdObjectInfo>& objects) {
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    os << "id,class,present_in,placement,centroid_x,centroid_y,centroid_z,min_x,min_y,min_z,max_x,max_y,max_z,"
          "partner\n";
    os << std::fixed << std::setprecision(3);
    for (const auto& o : objects) {
      os << o.id << ',' << o.cls << ',';
      for (std::size_t i = 0; i < o.present_in.size(); ++i) os << (i ? ";" : "") << o.present_in[i];
      os << ',' << o.placement;
      for (const auto* v : {&o.centroid, &o.box_min, &o.box_max}) os << ',' << v->x() << ',' << v->y() << ',' << v->z();
      os << ',' << o.partner << '\n';
    }
  });
}

// The pose graph as the SC-LIO-SAM saver writes it: 6 decimals, no information matrix (so the
// quaternions are only normalised to ~1e-6 and readers must renormalise).
void WriteScLioSamG2o(const std::string& path, const Session& session) {
  auto put = [](std::ostream& os, const Pose& T) {
    const Eigen::Quaterniond q(T.linear());
    const Eigen::Vector3d t = T.translation();
    os << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w();
  };
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    os << std::fixed << std::setprecision(6);
    for (const auto& kf : session.keyframes) {
      os << "VERTEX_SE3:QUAT " << kf.index;
      put(os, kf.T_session_sensor);
      os << '\n';
    }
    for (const auto& e : session.odometry) {
      os << "EDGE_SE3:QUAT " << e.from << ' ' << e.to;
      put(os, e.T_from_to);
      os << '\n';
    }
  });
}

void WriteActorsCsv(const std::string& path, const std::vector<HdActorInfo>& actors) {
  io::WriteFileAtomic(path, [&](std::ostream& os) {
    os << "id,class,session,speed_mps\n" << std::fixed << std::setprecision(3);
    for (const auto& a : actors) os << a.id << ',' << a.cls << ',' << a.session << ',' << a.speed_mps << '\n';
  });
}

// For each world point: does some keyframe ray of `session` pass through it? The ray from the
// keyframe's sensor towards the point is cast in that session's world (with its HD actors at
// that time); it passes through when its first hit lies beyond the point's range plus the
// tolerance, or nothing is hit within max range. Only keyframes that could have measured the
// point are tried: range within [min_range, max_range - tol] and elevation inside the vertical
// FOV. With visibility_max_rays > 0, at most that many rays per point (the first keyframes).
std::vector<char> SeenThrough(Simulator& sim, int session, const PointCloud& pts, const SimConfig& cfg) {
  const std::size_t n = pts.size();
  std::vector<char> seen(n, 0);
  std::vector<int> tested(n, 0);
  const double tol = cfg.visibility_tolerance_m;
  const auto& poses = sim.T_world_sensor(session);
  std::vector<std::size_t> idx;
  std::vector<Eigen::Vector3f> dirs;
  std::vector<float> ranges;
  for (std::size_t j = 0; j < poses.size(); ++j) {
    const Eigen::Vector3d o = poses[j].translation();
    const Eigen::Matrix3d Rt = poses[j].linear().transpose();
    idx.clear();
    dirs.clear();
    ranges.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (seen[i] || (cfg.visibility_max_rays > 0 && tested[i] >= cfg.visibility_max_rays)) continue;
      const Eigen::Vector3d d = pts.points[i].xyz().cast<double>() - o;
      const double r = d.norm();
      if (r < cfg.min_range_m || r + tol > cfg.max_range_m) continue;
      if (!InFieldOfView(cfg, Rt * d)) continue;
      idx.push_back(i);
      dirs.push_back((d / r).cast<float>());
      ranges.push_back(float(r));
    }
    if (idx.empty()) continue;
    const auto hits = sim.CastRays(session, int(j), o, dirs);
    for (std::size_t m = 0; m < idx.size(); ++m) {
      ++tested[idx[m]];
      if (!hits[m].hit || hits[m].range > ranges[m] + tol) seen[idx[m]] = 1;
    }
  }
  return seen;
}

// Along-ray tolerance for a first hit whose surface makes |cos| `cosine` with the ray: a point
// within truth.visibility_tolerance_m of that surface (normal distance) is on it, so the range
// window grows as 1/cos at grazing incidence (far ground), capped by visibility_grazing_max_m.
double RayTolerance(const SimConfig& cfg, float cosine) {
  const double tol = cfg.visibility_tolerance_m;
  const double c = std::max(double(cosine), 1e-6);
  return std::max(tol, std::min(tol / c, cfg.visibility_grazing_max_m));
}

// Keyframes coarse to fine (every 16th first, then the ones in between): a surface seen by a
// stretch of keyframes is found by the first pass, the order never changes the outcome.
std::vector<std::size_t> CoarseToFine(std::size_t n) {
  auto rev4 = [](std::size_t x) {
    return ((x & 1) << 3) | ((x & 2) << 1) | ((x & 4) >> 1) | ((x & 8) >> 3);
  };
  std::vector<std::size_t> order(n);
  for (std::size_t j = 0; j < n; ++j) order[j] = j;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return rev4(a % 16) < rev4(b % 16); });
  return order;
}

// The rays of one scan binned by direction in the keyframe's sensor frame (cells of kCellDeg
// in elevation and azimuth), to find the rays that pass near a point.
class RayDirectionGrid {
 public:
  static constexpr double kCellDeg = 0.5;
  RayDirectionGrid(const std::vector<Eigen::Vector3f>& dirs_world, const Eigen::Matrix3d& Rt)
      : rows_(int(std::ceil(180.0 / kCellDeg))), cols_(int(std::ceil(360.0 / kCellDeg))) {
    std::vector<std::uint32_t> cell(dirs_world.size());
    start_.assign(std::size_t(rows_) * cols_ + 1, 0);
    for (std::size_t i = 0; i < dirs_world.size(); ++i) {
      const Eigen::Vector3d u = Rt * dirs_world[i].cast<double>();
      cell[i] = std::uint32_t(Cell(Row(Elevation(u)), Col(Azimuth(u))));
      ++start_[cell[i] + 1];
    }
    for (std::size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    rays_.resize(dirs_world.size());
    std::vector<std::uint32_t> fill(start_.begin(), start_.end() - 1);
    for (std::size_t i = 0; i < dirs_world.size(); ++i) rays_[fill[cell[i]]++] = std::uint32_t(i);
  }
  // Calls f(ray) for every ray binned within `radius_deg` (plus one cell) of direction u.
  template <class F>
  void Near(const Eigen::Vector3d& u, double radius_deg, F&& f) const {
    const double el = Elevation(u), az = Azimuth(u);
    const int r0 = Row(std::max(-90.0, el - radius_deg)), r1 = Row(std::min(90.0, el + radius_deg));
    const double cos_el = std::cos((std::abs(el) + radius_deg) * M_PI / 180.0);
    const double span = cos_el > 1e-3 ? std::min(180.0, radius_deg / cos_el) : 180.0;
    const int dc = int(std::ceil(span / kCellDeg)) + 1, c = Col(az);
    for (int r = r0; r <= r1; ++r)
      for (int k = -std::min(dc, cols_ / 2); k <= std::min(dc, (cols_ - 1) / 2); ++k) {
        const int cell = Cell(r, (c + k + cols_) % cols_);
        for (std::uint32_t j = start_[std::size_t(cell)]; j < start_[std::size_t(cell) + 1]; ++j) f(rays_[j]);
      }
  }

 private:
  static double Elevation(const Eigen::Vector3d& u) { return std::asin(std::clamp(u.z(), -1.0, 1.0)) * 180.0 / M_PI; }
  static double Azimuth(const Eigen::Vector3d& u) { return std::atan2(u.y(), u.x()) * 180.0 / M_PI; }
  int Row(double el) const { return std::clamp(int((el + 90.0) / kCellDeg), 0, rows_ - 1); }
  int Col(double az) const { return std::clamp(int((az + 180.0) / kCellDeg), 0, cols_ - 1); }
  int Cell(int r, int c) const { return r * cols_ + c; }
  int rows_, cols_;
  std::vector<std::uint32_t> start_, rays_;
};

// The largest angle [deg] a column's sweep pose turns from the keyframe pose, and the farthest
// it moves [m]: a ray's direction in the keyframe frame is off by at most the one plus the other
// over the point's range.
std::pair<double, double> SweepSpread(const std::vector<Pose>& sweep, const Pose& T) {
  double deg = 0.0, m = 0.0;
  for (const Pose& P : sweep) {
    deg = std::max(deg, Eigen::AngleAxisd(T.linear().transpose() * P.linear()).angle() * 180.0 / M_PI);
    m = std::max(m, (P.translation() - T.translation()).norm());
  }
  return {deg, m};
}

// The very rays of `session`'s scans (the beam x column table or the scan's rosette, from each
// column's sweep pose; noise-free, cast in that session's world with its HD actors at that
// keyframe) that pass within truth.visibility_tolerance_m of each world point (perpendicular
// distance, at a distance `along` the ray within [min_range, max_range - tol]): decide(point,
// first hit, along, where the ray hit) marks the point done. Keyframes coarse to fine
// (CoarseToFine); a point done (on entry or by a ray) is not tested again. Returns the number of
// rays cast.
std::size_t BeamRays(Simulator& sim, int session, const PointCloud& pts, const SimConfig& cfg, int threads,
                     std::vector<char>* done,
                     const std::function<bool(std::size_t, const RayHit&, float, const Eigen::Vector3f&)>& decide) {
  const std::size_t n = pts.size();
  std::size_t cast = 0;
  const double tol = cfg.visibility_tolerance_m;
  const auto& poses = sim.T_world_sensor(session);
  std::vector<Eigen::Vector3f> origins, dirs;
  for (const std::size_t j : CoarseToFine(poses.size())) {
    const Pose& T = poses[j];
    const Eigen::Matrix3d Rt = T.linear().transpose();
    sim.FiredRays(session, int(j), &origins, &dirs);
    const RayDirectionGrid grid(dirs, Rt);
    const auto [turn_deg, move_m] = SweepSpread(sim.SweepPoses(session, int(j)), T);
    // Candidate (point, ray, distance along the ray) per chunk of points.
    struct Pass {
      std::uint32_t point, ray;
      float along;
    };
    constexpr std::size_t kBlock = 1024;
    std::vector<std::vector<Pass>> chunks((n + kBlock - 1) / kBlock);
    ParallelFor(chunks.size(), threads, [&](std::size_t block) {
      const std::size_t b = block * kBlock, e = std::min(n, b + kBlock);
      auto& out = chunks[block];
      for (std::size_t i = b; i < e; ++i) {
        if ((*done)[i]) continue;
        const Eigen::Vector3d p = pts.points[i].xyz().cast<double>(), d = p - T.translation();
        const double r = d.norm();
        if (r < cfg.min_range_m || r + tol > cfg.max_range_m + move_m) continue;
        const double radius_deg = std::asin(std::min(1.0, (tol + move_m) / r)) * 180.0 / M_PI + turn_deg;
        grid.Near(Rt * d / r, radius_deg, [&](std::uint32_t k) {
          const Eigen::Vector3d o = origins[k].cast<double>(), v = dirs[k].cast<double>();
          const double s = (p - o).dot(v);
          if (s < cfg.min_range_m || s + tol > cfg.max_range_m) return;
          if ((p - o - s * v).squaredNorm() <= tol * tol) out.push_back({std::uint32_t(i), k, float(s)});
        });
      }
    });
    std::vector<Pass> passes;
    for (auto& c : chunks) passes.insert(passes.end(), c.begin(), c.end());
    if (passes.empty()) continue;
    std::vector<std::uint32_t> rays;
    for (const Pass& q : passes) rays.push_back(q.ray);
    std::sort(rays.begin(), rays.end());
    rays.erase(std::unique(rays.begin(), rays.end()), rays.end());
    std::vector<Eigen::Vector3f> o(rays.size()), v(rays.size());
    for (std::size_t m = 0; m < rays.size(); ++m) o[m] = origins[rays[m]], v[m] = dirs[rays[m]];
    const auto hits = sim.CastRays(session, int(j), o, v);
    cast += rays.size();
    for (const Pass& q : passes) {
      const std::size_t m = std::size_t(std::lower_bound(rays.begin(), rays.end(), q.ray) - rays.begin());
      const RayHit& h = hits[m];
      if (decide(q.point, h, q.along, o[m] + h.range * v[m])) (*done)[q.point] = 1;
    }
  }
  return cast;
}

// Beam truth of LD objects: did one of the very rays of `session`'s scans (BeamRays) pass
// through each world point: end beyond it (first hit farther than along + tol), or hit nothing?
std::vector<char> BeamSeenThrough(Simulator& sim, int session, const PointCloud& pts, const SimConfig& cfg,
                                  int threads) {
  std::vector<char> seen(pts.size(), 0);
  const double tol = cfg.visibility_tolerance_m;
  BeamRays(sim, session, pts, cfg, threads, &seen,
           [&](std::size_t, const RayHit& h, float along, const Eigen::Vector3f&) {
             return !h.hit || double(h.range) > double(along) + tol;
           });
  return seen;
}

// Per point of session `owner`'s HD-free world not yet `done`: the owner's keyframes that hold it
// in range and FOV, nearest first.
std::vector<std::vector<std::uint32_t>> KeyframesInView(Simulator& sim, int owner, const PointCloud& pts,
                                                        const std::vector<char>& done, const SimConfig& cfg) {
  const auto& poses = sim.T_world_sensor(owner);
  std::vector<std::vector<std::uint32_t>> in_view(pts.size());
  if (poses.empty()) return in_view;
  PointCloud at;
  for (const Pose& T : poses) at.push_back(float(T.translation().x()), float(T.translation().y()), float(T.translation().z()));
  const geometry::KdTree tree(at);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (done[i]) continue;
    for (const auto& [j, d2] : tree.Radius(pts.points[i].xyz(), float(cfg.max_range_m))) {
      const Eigen::Vector3d d = pts.points[i].xyz().cast<double>() - poses[j].translation();
      const double r = d.norm();
      if (r >= cfg.min_range_m && r <= cfg.max_range_m && InFieldOfView(cfg, poses[j].linear().transpose() * d))
        in_view[i].push_back(j);
    }
  }
  return in_view;
}

// The surface normal at each point of session `owner`'s HD-free world that is not yet `done`
// (unit, world frame; zero where not found): where a ray cast straight at it from the owner's
// keyframes that hold it in view (KeyframesInView, nearest first, each in its keyframe's world)
// first hits within truth.visibility_tolerance_m of it. Adds the rays cast to *rays.
std::vector<Eigen::Vector3f> SurfaceNormals(Simulator& sim, int owner, const PointCloud& pts,
                                            const std::vector<char>& done, const SimConfig& cfg, std::size_t* rays) {
  const auto& poses = sim.T_world_sensor(owner);
  const std::vector<std::vector<std::uint32_t>> tries = KeyframesInView(sim, owner, pts, done, cfg);
  std::vector<Eigen::Vector3f> normals(pts.size(), Eigen::Vector3f::Zero());
  std::size_t most = 0;
  for (const auto& t : tries) most = std::max(most, t.size());
  for (std::size_t k = 0; k < most; ++k) {
    std::vector<std::vector<std::uint32_t>> from(poses.size());  // points whose k-th keyframe is j
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (normals[i].isZero() && tries[i].size() > k) from[tries[i][k]].push_back(std::uint32_t(i));
    for (std::size_t j = 0; j < poses.size(); ++j) {
      if (from[j].empty()) continue;
      const Eigen::Vector3d o = poses[j].translation();
      std::vector<Eigen::Vector3f> dirs;
      std::vector<float> ranges;
      for (const std::uint32_t i : from[j]) {
        const Eigen::Vector3d d = pts.points[i].xyz().cast<double>() - o;
        ranges.push_back(float(d.norm()));
        dirs.push_back((d / d.norm()).cast<float>());
      }
      const auto hits = sim.CastRays(owner, int(j), o, dirs);
      *rays += dirs.size();
      for (std::size_t m = 0; m < hits.size(); ++m)
        if (hits[m].hit && std::abs(double(hits[m].range) - ranges[m]) <= cfg.visibility_tolerance_m)
          normals[from[j][m]] = hits[m].normal;
    }
  }
  return normals;
}

// A ray's first hit `at` lies on the surface of point p (normal n; zero: unknown, any surface
// counts): within truth.visibility_tolerance_m of p's plane. A ray that ended on another surface
// within the along-ray band of p (a car's side passed at a grazing angle, in front of the point
// on its back) did not observe p's surface.
bool OnItsSurface(const Eigen::Vector3f& n, const Eigen::Vector3f& p, const Eigen::Vector3f& at, const SimConfig& cfg) {
  return n.isZero() || double(std::abs(n.dot(at - p))) <= cfg.visibility_tolerance_m;
}

// Did session `session` observe the surface of each point (a point of session `owner`'s
// HD-free world, world frame)? A point is observed when some keyframe ray of `session` towards
// it (range within [lidar.min_range_m, lidar.max_range_m], elevation inside the vertical FOV,
// cast in the world of `session` with its HD actors at that keyframe) first hits permanent
// structure or an LD object present in both sessions within the along-ray tolerance of the
// point (RayTolerance), on the point's own surface (OnItsSurface with `normals`). Points already
// marked observed are skipped; a point stops being tested once observed. Returns the number of
// rays cast.
std::size_t Observe(Simulator& sim, int session, int owner, const PointCloud& pts,
                    const std::vector<Eigen::Vector3f>& normals, const SimConfig& cfg, std::vector<char>* observed) {
  const std::size_t n = pts.size();
  std::vector<int> tested(n, 0);
  std::size_t rays = 0;
  const auto& poses = sim.T_world_sensor(session);
  std::vector<std::size_t> todo, idx;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(*observed)[i]) todo.push_back(i);
  }
  std::vector<Eigen::Vector3f> dirs;
  std::vector<float> ranges;
  for (const std::size_t j : CoarseToFine(poses.size())) {
    const Eigen::Vector3d o = poses[j].translation();
    const Eigen::Matrix3d Rt = poses[j].linear().transpose();
    idx.clear();
    dirs.clear();
    ranges.clear();
    std::size_t kept = 0;
    for (const std::size_t i : todo) {
      if ((*observed)[i]) continue;
      todo[kept++] = i;
      if (cfg.visibility_max_rays > 0 && tested[i] >= cfg.visibility_max_rays) continue;
      const Eigen::Vector3d d = pts.points[i].xyz().cast<double>() - o;
      if (std::abs(d.x()) > cfg.max_range_m || std::abs(d.y()) > cfg.max_range_m) continue;
      const double r = d.norm();
      if (r < cfg.min_range_m || r > cfg.max_range_m) continue;
      if (!InFieldOfView(cfg, Rt * d)) continue;
      idx.push_back(i);
      dirs.push_back((d / r).cast<float>());
      ranges.push_back(float(r));
    }
    todo.resize(kept);
    if (idx.empty()) continue;
    const auto hits = sim.CastRays(session, int(j), o, dirs);
    rays += idx.size();
    for (std::size_t m = 0; m < idx.size(); ++m) {
      const std::size_t i = idx[m];
      ++tested[i];
      const RayHit& h = hits[m];
      const bool same = h.hit && h.cls != PointClass::kHD && (h.object < 0 || sim.IsPresent(h.object, owner));
      const Eigen::Vector3f at = o.cast<float>() + h.range * dirs[m];
      if (same && std::abs(double(h.range) - ranges[m]) <= RayTolerance(cfg, h.cos_incidence) &&
          OnItsSurface(normals[i], pts.points[i].xyz(), at, cfg))
        (*observed)[i] = 1;
    }
  }
  return rays;
}

// Beam truth of surfaces both sessions have: did one of the very rays of `session`'s scans
// (BeamRays) end on the surface of each point of session `owner`'s HD-free world: its first hit
// permanent structure or an LD object present in both sessions, within the along-ray tolerance
// of the point (RayTolerance), on its own surface (OnItsSurface with `normals`)? Points already
// marked observed are skipped.
std::size_t BeamObserve(Simulator& sim, int session, int owner, const PointCloud& pts,
                        const std::vector<Eigen::Vector3f>& normals, const SimConfig& cfg, int threads,
                        std::vector<char>* observed) {
  return BeamRays(sim, session, pts, cfg, threads, observed,
                  [&](std::size_t i, const RayHit& h, float along, const Eigen::Vector3f& at) {
                    const bool same =
                        h.hit && h.cls != PointClass::kHD && (h.object < 0 || sim.IsPresent(h.object, owner));
                    return same && std::abs(double(h.range) - double(along)) <= RayTolerance(cfg, h.cos_incidence) &&
                           OnItsSurface(normals[i], pts.points[i].xyz(), at, cfg);
                  });
}

// The surfaces of `own` (session `s`'s HD-free world: permanent structure and LD objects
// present in both sessions) that session `o` may not have observed, and which of them it surely
// did: `o`'s HD-free world has a point of the same kind within truth.visibility_tolerance_m
// (`o` scanned that surface; the first test of both truths, Unobserved); and the others' surface
// normals (SurfaceNormals, adding its rays to *rays).
struct Coverage {
  PointCloud pts;
  std::vector<char> scanned;
  std::vector<Eigen::Vector3f> normals;
};
Coverage ScannedByOther(Simulator& sim, int s, int o, const PointCloud& own, const PointCloud& other,
                        const SimConfig& cfg, int threads, std::size_t* rays) {
  auto shared = [&](int obj) { return obj < 0 || (sim.IsPresent(obj, s) && sim.IsPresent(obj, o)); };
  std::vector<bool> keep_own(own.size()), keep_other(other.size());
  for (std::size_t i = 0; i < own.size(); ++i) keep_own[i] = shared(own.object[i]);
  for (std::size_t i = 0; i < other.size(); ++i) keep_other[i] = shared(other.object[i]);
  Coverage c{own.select(keep_own), {}, {}};
  const std::vector<bool> scanned = geometry::WithinRadius(c.pts, other.select(keep_other), cfg.visibility_tolerance_m, threads);
  c.scanned.assign(scanned.begin(), scanned.end());
  c.normals = SurfaceNormals(sim, s, c.pts, c.scanned, cfg, rays);
  return c;
}

// The points of `c` (session `s`'s surfaces) that session `o` did not observe: not scanned, nor
// reached by `o`'s rays: the very rays of its scans (BeamObserve, the beam truth) or, with
// `exact`, a ray from each keyframe straight at the point (Observe, the exact-ray truth). These
// surfaces exist in both worlds, so no ray of `o` can pass through them (rays that seem to are
// tangent to an edge): not observed means occluded, out of range or out of the FOV, or (beam
// truth) between the beams. Adds the rays cast to *rays.
PointCloud Unobserved(Simulator& sim, int s, int o, const Coverage& c, const SimConfig& cfg, int threads, bool exact,
                      std::size_t* rays) {
  std::vector<char> observed = c.scanned;
  *rays += exact ? Observe(sim, o, s, c.pts, c.normals, cfg, &observed)
                 : BeamObserve(sim, o, s, c.pts, c.normals, cfg, threads, &observed);
  std::vector<bool> un(c.pts.size());
  for (std::size_t i = 0; i < c.pts.size(); ++i) un[i] = !observed[i];
  return c.pts.select(un);
}

// Runs jobs in submission order on one background thread (or inline when not threaded), with a
// bounded queue: keyframe k's files and truth are processed while keyframe k+1 is cast.
class OrderedWorker {
 public:
  explicit OrderedWorker(bool threaded, std::size_t max_queue = 4) : max_queue_(max_queue) {
    if (threaded) thread_ = std::thread([this] { Loop(); });
  }
  ~OrderedWorker() {
    try {
      Finish();
    } catch (...) {
    }
  }
  void Push(std::function<void()> job) {
    if (!thread_.joinable()) {
      job();
      return;
    }
    std::unique_lock<std::mutex> lock(m_);
    cv_.wait(lock, [&] { return queue_.size() < max_queue_ || error_; });
    if (error_) return;
    queue_.push_back(std::move(job));
    cv_.notify_all();
  }
  // Waits for every job; rethrows the first error.
  void Finish() {
    if (thread_.joinable()) {
      {
        std::lock_guard<std::mutex> lock(m_);
        done_ = true;
        cv_.notify_all();
      }
      thread_.join();
    }
    if (error_) {
      auto e = error_;
      error_ = nullptr;
      std::rethrow_exception(e);
    }
  }

 private:
  void Loop() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait(lock, [&] { return !queue_.empty() || done_; });
        if (queue_.empty()) return;
        job = std::move(queue_.front());
        queue_.pop_front();
        cv_.notify_all();
      }
      try {
        job();
      } catch (...) {
        std::lock_guard<std::mutex> lock(m_);
        if (!error_) error_ = std::current_exception();
        queue_.clear();
        cv_.notify_all();
        return;
      }
    }
  }
  std::size_t max_queue_;
  std::thread thread_;
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> queue_;
  bool done_ = false;
  std::exception_ptr error_;
};

// PointCloud::append drops the optional arrays when `src` has none, which an empty cloud never
// has: skip empty ones so the labels survive.
void Append(PointCloud& dst, const PointCloud& src) {
  if (!src.empty()) dst.append(src);
}

std::size_t DirBytes(const std::string& dir) {
  std::size_t total = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) total += std::size_t(e.file_size());
  }
  return total;
}

}  // namespace

namespace {
// A session's truth clouds, voxelised: its static world (no HD) and its LD objects.
struct SessionTruth {
  PointCloud static_world, ld_world;
};

void WriteScenarioFiles(const Simulator& sim, const SimConfig& cfg, const std::string& truth) {
  SimConfig resolved = cfg;
  io::SaveConfigFields(truth + "/scenario.yaml", FieldsOf(resolved));
  WriteObjectsCsv(truth + "/objects.csv", sim.ld_objects());
  WriteActorsCsv(truth + "/hd_actors.csv", sim.hd_actor_info());
}

// The labelled scan of keyframe k: written as labels/NNNNNN.ply, its static and LD points added
// to the session's truth accumulators (world frame).
void AddScanTruth(const PointCloud& cloud, const Pose& T_world_sensor, const std::string& path, double voxel,
                  int threads, SessionTruth* acc, SimReport* rep) {
  auto t0 = Clock::now();
  io::WritePly(path, cloud);
  rep->seconds_write += Since(t0);
  t0 = Clock::now();
  const PointCloud world = geometry::Transform(cloud, T_world_sensor);
  std::vector<bool> is_static(world.size()), is_ld(world.size());
  for (std::size_t i = 0; i < world.size(); ++i) {
    is_static[i] = world.cls[i] != PointClass::kHD;
    is_ld[i] = is_static[i] && world.object[i] >= 0;
    rep->hd_points += !is_static[i];
    rep->ld_points += is_ld[i];
  }
  Append(acc->static_world, geometry::VoxelDownsample(world.select(is_static), voxel, threads));
  Append(acc->ld_world, geometry::VoxelDownsample(world.select(is_ld), voxel, threads));
  rep->seconds_truth += Since(t0);
}

// Casts every keyframe of session s (scans in keyframe order; truth written by a worker thread)
// into `session` with the drifted odometry.
SessionTruth CastSession(Simulator& sim, const SimConfig& cfg, int s, const std::string& tdir, int threads,
                         Session* session, SimReport* rep) {
  const auto& drifted = sim.T_session_sensor_drifted(s);
  const auto& world_poses = sim.T_world_sensor(s);
  SessionTruth acc;
  Progress progress("sim " + session->name, std::size_t(sim.keyframes(s)));
  OrderedWorker worker(threads != 1);
  for (int k = 0; k < sim.keyframes(s); ++k) {
    const auto t = Clock::now();
    auto cloud = std::make_shared<const PointCloud>(sim.CastScan(s, k));
    rep->seconds_cast += Since(t);
    rep->rays += std::size_t(cfg.beams) * std::size_t(cfg.columns);
    rep->points += cloud->size();
    worker.Push([&, cloud, k] {
      // The labelled truth is where the points are: a raw sweep's moved by its true sweep poses.
      AddScanTruth(sim.TrueDeskewed(s, k, *cloud), world_poses[std::size_t(k)], tdir + "/labels/" + Num(k, 6) + ".ply", cfg.truth_voxel_m,
                   threads, &acc, rep);
      progress.Tick();
    });
    Keyframe kf;
    kf.index = k;
    kf.T_session_sensor = drifted[std::size_t(k)];
    kf.time_s = sim.KeyframeTime(s, k);
    kf.cloud = std::move(cloud);
    session->keyframes.push_back(std::move(kf));
    if (k > 0) {
      Edge e;
      e.from = k - 1;
      e.to = k;
      e.T_from_to = drifted[std::size_t(k - 1)].inverse() * drifted[std::size_t(k)];
      session->odometry.push_back(e);
    }
  }
  worker.Finish();
  progress.Done();
  return acc;
}

// Session s: its SC-LIO-SAM folder under sessions/ and its truth folder (labelled scans, true
// poses and origin, static world); returns its voxelised truth clouds.
SessionTruth SimulateSession(Simulator& sim, const SimConfig& cfg, int s, const std::string& out_dir,
                             int threads, SimReport* rep) {
  const std::string name = SessionName(s);
  const std::string sdir = out_dir + "/sessions/" + name, tdir = out_dir + "/truth/" + name;
  io::MakeDirs(tdir + "/labels");
  Session session;
  session.name = name;
  session.dir = sdir;
  SessionTruth acc = CastSession(sim, cfg, s, tdir, threads, &session, rep);
  auto t = Clock::now();
  io::WriteSession(sdir, session);
  WriteScLioSamG2o(sdir + "/singlesession_posegraph.g2o", session);  // replaces io's full-precision file
  io::WriteKittiPoses(tdir + "/poses_world.txt", sim.T_world_sensor(s));
  io::WriteKittiPoses(tdir + "/origin.txt", {sim.T_world_session(s)});
  rep->seconds_write += Since(t);
  t = Clock::now();
  SessionTruth out;
  out.static_world = geometry::VoxelDownsample(acc.static_world, cfg.truth_voxel_m, threads);
  io::WritePcd(tdir + "/static_world.pcd", out.static_world);
  io::WritePly(tdir + "/static_world.ply", out.static_world);
  out.ld_world = geometry::VoxelDownsample(acc.ld_world, cfg.truth_voxel_m, threads);
  rep->seconds_truth += Since(t);
  rep->keyframes += std::size_t(sim.keyframes(s));
  return out;
}

PointCloud OfClass(const PointCloud& c, PointClass k) {
  std::vector<bool> keep(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) keep[i] = c.cls[i] == k;
  return c.select(keep);
}

// The pair's change clouds per class (objects only, and all) into pdir, with their counts.
void WritePairClouds(const std::string& pdir, const PointCloud& nd, const PointCloud& pd, const PointCloud& snd,
                     const PointCloud& spd, PairTruthCounts* counts) {
  io::MakeDirs(pdir);
  const PointClass kinds[4] = {PointClass::kPDStrong, PointClass::kPDWeak, PointClass::kNDStrong, PointClass::kNDWeak};
  const char* names[4] = {"pd_strong", "pd_weak", "nd_strong", "nd_weak"};
  std::size_t* obj_counts[4] = {&counts->objects_pd_strong, &counts->objects_pd_weak, &counts->objects_nd_strong,
                                &counts->objects_nd_weak};
  std::size_t* all_counts[4] = {&counts->pd_strong, &counts->pd_weak, &counts->nd_strong, &counts->nd_weak};
  PointCloud objects = nd, all;
  Append(objects, pd);
  for (int c = 0; c < 4; ++c) {
    const bool is_pd = c < 2;
    const PointCloud o = OfClass(is_pd ? pd : nd, kinds[c]);
    PointCloud a = o;
    Append(a, OfClass(is_pd ? spd : snd, kinds[c]));
    io::WritePcd(pdir + "/objects_" + names[c] + ".pcd", o);
    io::WritePcd(pdir + "/" + names[c] + ".pcd", a);
    *obj_counts[c] = o.size();
    *all_counts[c] = a.size();
    Append(all, a);
  }
  io::WritePly(pdir + "/objects_changes.ply", objects);
  io::WritePly(pdir + "/changes.ply", all);
}

// Strong / weak of LD object points by whether the other session saw through them: ND is
// strong when seen through, PD weak (its space was observed free).
void Split(PointCloud& c, const std::vector<char>& seen, bool nd) {
  for (std::size_t i = 0; i < c.size(); ++i)
    c.cls[i] = nd ? (seen[i] ? PointClass::kNDStrong : PointClass::kNDWeak)
                  : (seen[i] ? PointClass::kPDWeak : PointClass::kPDStrong);
}

// Change truth of the pair (central 0, query q): the LD objects that changed, plus every other
// surface one session has and the other never observed (FORMATS.md).
PairTruthCounts WritePairTruth(Simulator& sim, const SimConfig& cfg, int q, const std::vector<SessionTruth>& st,
                               const std::string& truth, int threads) {
  PairTruthCounts counts;
  counts.query = q;
  auto changed = [&](const PointCloud& c, int in, int out) {
    std::vector<bool> keep(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) keep[i] = sim.IsPresent(c.object[i], in) && !sim.IsPresent(c.object[i], out);
    return c.select(keep);
  };
  const SessionTruth& central = st[0];
  const SessionTruth& query = st[std::size_t(q)];
  // LD objects: present in one session only.
  PointCloud nd = changed(central.ld_world, 0, q), pd = changed(query.ld_world, q, 0);
  // The beam truth (the scans' own rays) decides strong / weak; the exact-ray truth (a ray cast
  // straight at each point) is written beside it (exact_ray/).
  PointCloud nd_exact = nd, pd_exact = pd;
  Split(nd, BeamSeenThrough(sim, q, nd, cfg, threads), true);  // query saw through: strong ND
  Split(pd, BeamSeenThrough(sim, 0, pd, cfg, threads), false);  // central saw the space free: weak PD
  Split(nd_exact, SeenThrough(sim, q, nd_exact, cfg), true);
  Split(pd_exact, SeenThrough(sim, 0, pd_exact, cfg), false);
  // Surfaces both sessions have (permanent, LD objects present in both) that the other
  // session never observed: weak ND (central side, kept in the map) and strong PD (query side).
  // Each truth with its own rays: the scans' (beam) or one straight at each point (exact).
  const std::string pdir = truth + "/pair_00_" + Num(q, 2);
  PairTruthCounts exact;
  const Coverage central_side =
      ScannedByOther(sim, 0, q, central.static_world, query.static_world, cfg, threads, &counts.rays);
  const Coverage query_side = ScannedByOther(sim, q, 0, query.static_world, central.static_world, cfg, threads, &counts.rays);
  for (const bool exact_rays : {false, true}) {
    PointCloud snd = Unobserved(sim, 0, q, central_side, cfg, threads, exact_rays, &counts.rays);
    PointCloud spd = Unobserved(sim, q, 0, query_side, cfg, threads, exact_rays, &counts.rays);
    snd.cls.assign(snd.size(), PointClass::kNDWeak);
    spd.cls.assign(spd.size(), PointClass::kPDStrong);
    if (exact_rays)
      WritePairClouds(io::layout::ExactRayTruthDir(pdir), nd_exact, pd_exact, snd, spd, &exact);
    else
      WritePairClouds(pdir, nd, pd, snd, spd, &counts);
  }
  return counts;
}
}  // namespace

SimReport Simulate(const SimConfig& user_cfg, const std::string& out_dir, int threads) {
  const SimConfig cfg = ResolveLidar(user_cfg);
  const auto t_total = Clock::now();
  SimReport rep;
  auto t = Clock::now();
  Simulator sim(cfg, threads);
  rep.seconds_build = Since(t);
  const int N = sim.sessions();
  rep.sessions = N;
  rep.triangles = sim.triangles();
  rep.ld_objects = sim.ld_objects().size();
  rep.hd_actors = sim.hd_actors();

  const std::string truth = out_dir + "/truth";
  io::MakeDirs(out_dir + "/sessions");
  io::MakeDirs(truth);
  WriteScenarioFiles(sim, cfg, truth);
  std::vector<SessionTruth> st;
  for (int s = 0; s < N; ++s) st.push_back(SimulateSession(sim, cfg, s, out_dir, threads, &rep));
  t = Clock::now();
  for (int q = 1; q < N; ++q) rep.pairs.push_back(WritePairTruth(sim, cfg, q, st, truth, threads));
  rep.seconds_truth += Since(t);
  rep.rays_per_s = rep.seconds_cast > 0 ? double(rep.rays) / rep.seconds_cast : 0.0;
  rep.bytes_written = DirBytes(out_dir);
  rep.seconds_total = Since(t_total);
  return rep;
}

}  // namespace ltm::sim
