// Terrain, street grid, routes over it, keyframe poses, HD actor motion and odometry drift.
#include "ltmapper/sim/internal.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace ltm::sim::detail {

namespace {
constexpr double kDenseStep = 0.25;  // [m] vertex spacing of dense paths
}

Pose YawPose(double x, double y, double z, double yaw) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// ------------------------------------------------------------------------------------ terrain
Terrain MakeTerrain(const SimConfig& cfg, Rng& rng) {
  Terrain t;
  t.amp = cfg.relief_m;
  const double k = 2.0 * M_PI / cfg.relief_wavelength_m;
  t.k1 = k * rng.Uniform(0.8, 1.2);
  t.k2 = k * rng.Uniform(0.6, 1.0);
  t.k3 = k * rng.Uniform(1.2, 1.8);
  t.p1 = rng.Uniform(0, 2 * M_PI);
  t.p2 = rng.Uniform(0, 2 * M_PI);
  t.p3 = rng.Uniform(0, 2 * M_PI);
  return t;
}

// h = amp * (0.6 sin(k1 x + p1) cos(k2 y + p2) + 0.4 sin(k3 (x + y) / sqrt2 + p3)): smooth, with
// slopes of at most a few percent for the default amplitude and wavelength.
double Terrain::Height(double x, double y) const {
  return amp * (0.6 * std::sin(k1 * x + p1) * std::cos(k2 * y + p2) +
                0.4 * std::sin(k3 * (x + y) * M_SQRT1_2 + p3));
}

Eigen::Vector2d Terrain::Gradient(double x, double y) const {
  const double c3 = 0.4 * k3 * M_SQRT1_2 * std::cos(k3 * (x + y) * M_SQRT1_2 + p3);
  return amp * Eigen::Vector2d(0.6 * k1 * std::cos(k1 * x + p1) * std::cos(k2 * y + p2) + c3,
                               -0.6 * k2 * std::sin(k1 * x + p1) * std::sin(k2 * y + p2) + c3);
}

// --------------------------------------------------------------------------------------- grid
Grid MakeGrid(const SimConfig& cfg) {
  Grid g;
  g.half_extent = cfg.extent_m / 2;
  g.road_half = cfg.road_half_width_m;
  g.sidewalk = cfg.sidewalk_m;
  g.curb = cfg.curb_m;
  const int n = std::max(1, int(std::floor(cfg.extent_m / cfg.block_m + 1e-9)));
  const double first = -0.5 * (n - 1) * cfg.block_m;
  for (int i = 0; i < n; ++i) g.lines.push_back(first + i * cfg.block_m);
  return g;
}

bool Grid::OnRoad(double x, double y) const {
  for (double l : lines) {
    if (std::abs(x - l) < road_half || std::abs(y - l) < road_half) return true;
  }
  return false;
}

// --------------------------------------------------------------------------------------- path
void Path::Finish() {
  s.assign(p.size(), 0.0);
  for (std::size_t i = 1; i < p.size(); ++i) s[i] = s[i - 1] + (p[i] - p[i - 1]).norm();
}

Eigen::Vector2d Path::At(double at, Eigen::Vector2d* tangent) const {
  if (p.size() < 2) {
    if (tangent) *tangent = Eigen::Vector2d::UnitX();
    return p.empty() ? Eigen::Vector2d::Zero() : p[0];
  }
  at = std::clamp(at, 0.0, length());
  std::size_t i = std::size_t(std::upper_bound(s.begin(), s.end(), at) - s.begin());
  i = std::clamp<std::size_t>(i, 1, p.size() - 1);
  const double seg = s[i] - s[i - 1];
  const double a = seg > 0 ? (at - s[i - 1]) / seg : 0.0;
  if (tangent) {
    const Eigen::Vector2d d = (p[i] - p[i - 1]).normalized();
    *tangent = d;
  }
  return (1 - a) * p[i - 1] + a * p[i];
}

Path Path::Reversed() const {
  Path r;
  r.p.assign(p.rbegin(), p.rend());
  r.Finish();
  return r;
}

Path Path::Offset(double right) const {
  Path o;
  o.p.resize(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    const std::size_t a = i == 0 ? 0 : i - 1, b = std::min(i + 1, p.size() - 1);
    Eigen::Vector2d t = p[b] - p[a];
    t = t.norm() > 0 ? t.normalized() : Eigen::Vector2d::UnitX();
    o.p[i] = p[i] + right * Eigen::Vector2d(t.y(), -t.x());
  }
  o.Finish();
  return o;
}

double Path::Distance(const Eigen::Vector2d& q) const {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& v : p) best = std::min(best, (v - q).squaredNorm());
  return std::sqrt(best);
}

// ------------------------------------------------------------------------------------- routes
namespace {

struct NodeRoute {
  std::vector<std::pair<int, int>> nodes;  // grid intersections (i, j)
};

// Random walk over intersections without U-turns (unless at a dead end): straight ahead is
// twice as likely as each turn.
NodeRoute RandomWalk(int n, int edges, Rng& rng) {
  NodeRoute r;
  int i = rng.Int(n), j = rng.Int(n);
  static const int kDir[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
  int dir = rng.Int(4);
  r.nodes.push_back({i, j});
  for (int e = 0; e < edges; ++e) {
    std::vector<std::pair<int, double>> options;
    for (int d = 0; d < 4; ++d) {
      if (d == (dir + 2) % 4) continue;  // no U-turn
      const int ni = i + kDir[d][0], nj = j + kDir[d][1];
      if (ni < 0 || nj < 0 || ni >= n || nj >= n) continue;
      options.push_back({d, d == dir ? 2.0 : 1.0});
    }
    if (options.empty()) options.push_back({(dir + 2) % 4, 1.0});
    double total = 0;
    for (auto& o : options) total += o.second;
    double u = rng.Uniform() * total;
    int pick = options.back().first;
    for (auto& o : options) {
      if (u < o.second) {
        pick = o.first;
        break;
      }
      u -= o.second;
    }
    dir = pick;
    i += kDir[dir][0];
    j += kDir[dir][1];
    r.nodes.push_back({i, j});
  }
  return r;
}

void AddSegment(Path& path, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const double len = (b - a).norm();
  const int steps = std::max(1, int(std::ceil(len / kDenseStep)));
  for (int k = path.p.empty() ? 0 : 1; k <= steps; ++k) path.p.push_back(a + (b - a) * (double(k) / steps));
}

// Centre line through the intersections with circular arcs of radius R at turns.
Path CentreLine(const NodeRoute& r, const Grid& grid, double R) {
  std::vector<Eigen::Vector2d> v;
  for (auto& [i, j] : r.nodes) v.push_back({grid.lines[i], grid.lines[j]});
  Path path;
  Eigen::Vector2d cur = v[0];
  path.p.push_back(cur);
  for (std::size_t k = 1; k + 1 < v.size(); ++k) {
    const Eigen::Vector2d a = (v[k] - v[k - 1]).normalized(), b = (v[k + 1] - v[k]).normalized();
    const double cross = a.x() * b.y() - a.y() * b.x();
    if (std::abs(cross) < 1e-9) {
      if (a.dot(b) > 0) continue;  // straight on
      // U-turn at a dead end: go to the node and back.
      AddSegment(path, cur, v[k]);
      cur = v[k];
      continue;
    }
    const double r = std::min(R, 0.45 * std::min((v[k] - v[k - 1]).norm(), (v[k + 1] - v[k]).norm()));
    const Eigen::Vector2d t1 = v[k] - a * r, t2 = v[k] + b * r, c = t1 + b * r;
    AddSegment(path, cur, t1);
    const double th1 = std::atan2(t1.y() - c.y(), t1.x() - c.x());
    const double sweep = cross > 0 ? M_PI / 2 : -M_PI / 2;
    const int steps = std::max(2, int(std::ceil(std::abs(sweep) * r / kDenseStep)));
    for (int s = 1; s <= steps; ++s) {
      const double th = th1 + sweep * s / steps;
      path.p.push_back(c + r * Eigen::Vector2d(std::cos(th), std::sin(th)));
    }
    cur = t2;
  }
  AddSegment(path, cur, v.back());
  path.Finish();
  return path;
}

}  // namespace

double RouteOverlap(const Path& a, const Path& b, double tol) {
  if (a.p.empty()) return 0.0;
  std::size_t near = 0, total = 0;
  for (std::size_t i = 0; i < a.p.size(); i += 8) {
    ++total;
    if (b.Distance(a.p[i]) <= tol) ++near;
  }
  return double(near) / double(total);
}

namespace {
// Arc length of the first keyframe along a driving lane.
double DriveStart(const Path& lane) { return std::min(30.0, 0.1 * lane.length()); }
}  // namespace

Path DrivenPart(const SimConfig& cfg, const Path& centre) {
  const double s0 = DriveStart(centre.Offset(cfg.lane_offset_m));
  const double s1 = s0 + (cfg.keyframes - 1) * cfg.keyframe_spacing_m;
  Path d;
  for (std::size_t i = 0; i < centre.p.size(); ++i)
    if (centre.s[i] >= s0 && centre.s[i] <= s1) d.p.push_back(centre.p[i]);
  d.Finish();
  return d;
}

Path MakeRoute(const SimConfig& cfg, const Grid& grid, Rng& rng, double min_length,
               const Path* reference, double min_overlap) {
  const int n = int(grid.lines.size());
  const int edges = int(std::ceil(min_length / cfg.block_m)) + 1;
  Path best;
  double best_score = -1;
  const Path driven_reference = reference ? DrivenPart(cfg, *reference) : Path();
  for (int attempt = 0; attempt < 60; ++attempt) {
    Path p;
    for (int e = edges; p.length() < min_length; ++e) {  // corners shorten the path
      p = CentreLine(RandomWalk(n, e, rng), grid, cfg.corner_radius_m);
    }
    if (!reference) return p;
    // Share of the keyframes' part of the route on the streets session 0 drove.
    const double ov = RouteOverlap(DrivenPart(cfg, p), driven_reference, 1.0);
    // Overlapping but not the same drive: prefer overlap in [min_overlap, 0.85].
    const double score = ov >= min_overlap && ov <= 0.85 ? 2.0 - std::abs(ov - 0.5) : ov;
    if (score > best_score) {
      best_score = score;
      best = p;
    }
    if (ov >= min_overlap && ov <= 0.85) break;
  }
  return best;
}

// Equidistant keyframes along the driving lane; height from the road surface, roll and pitch
// from the terrain slope (z up, x forward).
std::vector<Pose> KeyframePoses(const SimConfig& cfg, const Grid& grid, const Terrain& terrain,
                                const Path& centre) {
  (void)grid;
  const Path lane = centre.Offset(cfg.lane_offset_m);
  std::vector<Pose> poses;
  const double start = DriveStart(lane);
  for (int k = 0; k < cfg.keyframes; ++k) {
    Eigen::Vector2d t;
    const Eigen::Vector2d p = lane.At(start + k * cfg.keyframe_spacing_m, &t);
    const double yaw = std::atan2(t.y(), t.x());
    const Eigen::Vector2d g = terrain.Gradient(p.x(), p.y());
    const Eigen::Vector2d left(-t.y(), t.x());
    const double pitch = -std::atan(g.dot(t)), roll = std::atan(g.dot(left));
    Pose T = Pose::Identity();
    T.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    T.translation() = Eigen::Vector3d(p.x(), p.y(), terrain.Height(p.x(), p.y()) + cfg.sensor_height_m);
    poses.push_back(T);
  }
  return poses;
}

// ---------------------------------------------------------------------------------- HD actors
bool HdActor::PoseAt(double t, const Grid& grid, const Terrain& terrain, Pose* T) const {
  const double s = s0 + speed * t;
  if (s < 0 || s > path.length()) return false;
  Eigen::Vector2d tan;
  const Eigen::Vector2d c = path.At(s, &tan);
  const Eigen::Vector2d p = c + offset * Eigen::Vector2d(tan.y(), -tan.x());
  *T = YawPose(p.x(), p.y(), grid.GroundZ(terrain, p.x(), p.y()), std::atan2(tan.y(), tan.x()));
  return true;
}

// Actors that meet the ego vehicle: cars leading it, following it and coming the other way on
// its own streets, pedestrians on the sidewalks of its route. Each sweeps through many scans.
std::vector<HdActor> MakeActors(const SimConfig& cfg, const Path& centre, int session, int first_id,
                                Rng& rng) {
  (void)session;
  std::vector<HdActor> actors;
  const double L = centre.length();
  const double start = std::min(30.0, 0.1 * L);
  const double v_ego = cfg.ego_speed_mps;
  const double T = (cfg.keyframes - 1) * cfg.keyframe_spacing_m / v_ego;
  const Path reversed = centre.Reversed();
  int id = first_id;
  for (int i = 0; i < cfg.hd_cars; ++i) {
    HdActor a;
    a.id = id++;
    a.offset = cfg.lane_offset_m;
    switch (i % 3) {
      case 0:  // leading, slowly pulling away
        a.path = centre;
        a.s0 = start + rng.Uniform(12.0, 30.0);
        a.speed = v_ego * rng.Uniform(1.0, 1.15);
        break;
      case 1: {  // oncoming, meets the ego at t_meet
        a.path = reversed;
        a.speed = cfg.hd_car_speed_mps * rng.Uniform(0.7, 1.3);
        const double t_meet = rng.Uniform(0.05, 0.95) * T;
        a.s0 = (L - (start + v_ego * t_meet)) - a.speed * t_meet;
        break;
      }
      default:  // following, slowly falling back
        a.path = centre;
        a.s0 = start - rng.Uniform(10.0, 25.0);
        a.speed = v_ego * rng.Uniform(0.9, 1.0);
        break;
    }
    actors.push_back(std::move(a));
  }
  for (int i = 0; i < cfg.hd_pedestrians; ++i) {
    HdActor a;
    a.id = id++;
    a.pedestrian = true;
    const bool forward = rng.Bernoulli(0.5);
    a.path = forward ? centre : reversed;
    a.offset = cfg.road_half_width_m + 0.5 * cfg.sidewalk_m;
    a.speed = cfg.hd_pedestrian_speed_mps * rng.Uniform(0.7, 1.3);
    const double t_meet = rng.Uniform(0.05, 0.95) * T;
    const double ego_s = start + v_ego * t_meet;
    const double meet_s = forward ? ego_s : L - ego_s;
    a.s0 = meet_s - a.speed * t_meet;
    actors.push_back(std::move(a));
  }
  return actors;
}

}  // namespace ltm::sim::detail

namespace ltm::sim {

// Odometry increments with a per-session scale error, x/y noise proportional to the step, and
// random walks in yaw and z growing with sqrt(step), composed from the first true pose.
std::vector<Pose> DriftPoses(const std::vector<Pose>& truth, const SimConfig& cfg, std::uint64_t seed) {
  detail::Rng rng(seed);
  std::vector<Pose> out;
  if (truth.empty()) return out;
  out.push_back(truth[0]);
  const double scale = 1.0 + cfg.drift_scale * rng.Normal();
  for (std::size_t i = 1; i < truth.size(); ++i) {
    Pose d = truth[i - 1].inverse() * truth[i];
    const double step = d.translation().norm();
    Eigen::Vector3d t = d.translation() * scale;
    t.x() += cfg.drift_translation * step * rng.Normal();
    t.y() += cfg.drift_translation * step * rng.Normal();
    t.z() += cfg.drift_z_m * std::sqrt(step) * rng.Normal();
    const double dyaw = cfg.drift_yaw_deg * M_PI / 180.0 * std::sqrt(step) * rng.Normal();
    Pose noisy = Pose::Identity();
    noisy.linear() = d.linear() * Eigen::AngleAxisd(dyaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    noisy.translation() = t;
    out.push_back(out.back() * noisy);
  }
  return out;
}

}  // namespace ltm::sim
