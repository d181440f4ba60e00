// Private pieces of the simulator shared by its .cpp files (not part of the public API).
#pragma once

#include "ltmapper/sim/sim.hpp"

#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace ltm::sim::detail {

// ------------------------------------------------------------------------------- randomness
// splitmix64 finaliser: a good 64-bit mix, used both to seed and to hash ray coordinates.
inline std::uint64_t Mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
inline std::uint64_t Hash(std::uint64_t a, std::uint64_t b, std::uint64_t c = 0, std::uint64_t d = 0) {
  return Mix(Mix(Mix(Mix(a) ^ b) ^ c) ^ d);
}
// Uniform in [0, 1) from 53 bits.
inline double ToUnit(std::uint64_t x) { return double(x >> 11) * (1.0 / 9007199254740992.0); }

// Our own generator and distributions so that every platform draws the same numbers.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(Mix(seed)) {}
  std::uint64_t Next() { return Mix(state_ += 0x632BE59BD9B4E019ull); }
  double Uniform() { return ToUnit(Next()); }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  int Int(int n) { return n <= 1 ? 0 : int(Next() % std::uint64_t(n)); }  // [0, n)
  bool Bernoulli(double p) { return Uniform() < p; }
  double Normal() {  // Box-Muller
    const double u1 = 1.0 - Uniform(), u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }

 private:
  std::uint64_t state_;
};

// ------------------------------------------------------------------------------------ meshes
// Reflectivity classes; the LiDAR intensity is reflectivity * |cos(incidence)|.
enum Material : std::uint8_t { kAsphalt, kConcrete, kFacade, kGlass, kBark, kLeaves, kMetal, kPaint, kCloth, kMaterialCount };
float Reflectivity(std::uint8_t material);

struct Mesh {
  std::vector<Eigen::Vector3f> v;
  std::vector<std::array<std::uint32_t, 3>> f;
  std::vector<std::uint8_t> mat;  // per triangle

  std::size_t triangles() const { return f.size(); }
  void Tri(std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint8_t m) {
    f.push_back({a, b, c});
    mat.push_back(m);
  }
  void Quad(std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint32_t d, std::uint8_t m) {
    Tri(a, b, c, m);
    Tri(a, c, d, m);
  }
  // Box centred at (cx, cy) with its bottom at z0, size (along yaw, across, height).
  void AddBox(const Eigen::Vector2d& c, double z0, const Eigen::Vector3d& size, double yaw,
              std::uint8_t m, bool bottom = false);
  // Vertical prism (cylinder) of `sides` sides.
  void AddCylinder(const Eigen::Vector2d& c, double z0, double radius, double height, int sides,
                   std::uint8_t m);
  // Ellipsoid from a subdivided icosahedron.
  void AddEllipsoid(const Eigen::Vector3d& c, const Eigen::Vector3d& radii, int subdivisions,
                    std::uint8_t m);
  void Append(const Mesh& other);
  Eigen::AlignedBox3d Bounds() const;
};

// ------------------------------------------------------------------------------------ terrain
// Gentle relief h(x, y); blocks (everything outside the roadways) are raised by the curb height.
struct Terrain {
  double amp = 0, k1 = 0, k2 = 0, k3 = 0, p1 = 0, p2 = 0, p3 = 0;
  double Height(double x, double y) const;
  Eigen::Vector2d Gradient(double x, double y) const;
};

// The street grid: street centre lines at coordinates `lines` along x and y.
struct Grid {
  std::vector<double> lines;
  double half_extent = 100;
  double road_half = 6, sidewalk = 3, curb = 0.15;
  // Inside a roadway (not raised)?
  bool OnRoad(double x, double y) const;
  double GroundZ(const Terrain& t, double x, double y) const {
    return t.Height(x, y) + (OnRoad(x, y) ? 0.0 : curb);
  }
};

// A 2D polyline parameterised by arc length.
struct Path {
  std::vector<Eigen::Vector2d> p;
  std::vector<double> s;  // cumulative length
  double length() const { return s.empty() ? 0.0 : s.back(); }
  void Finish();  // fills s
  // Point and unit tangent at arc length `at` (clamped).
  Eigen::Vector2d At(double at, Eigen::Vector2d* tangent = nullptr) const;
  Path Reversed() const;
  Path Offset(double right) const;  // lateral offset to the right of travel
  double Distance(const Eigen::Vector2d& q) const;  // to the nearest vertex (dense paths)
};

struct HdActor {
  int id = 0;
  bool pedestrian = false;
  Path path;          // centre line (maybe reversed)
  double offset = 0;  // [m] to the right of travel
  double s0 = 0;      // arc length at t = 0
  double speed = 0;   // [m/s]
  // Pose at time t; false when the actor is off its path (not in the world then).
  bool PoseAt(double t, const Grid& grid, const Terrain& terrain, Pose* T_world_actor) const;
};

struct LdObject {
  LdObjectInfo info;
  Mesh mesh;
};

struct SessionPlan {
  Path centre;                       // street centre line of the route
  std::vector<Pose> T_world_sensor;  // true keyframe poses
  Pose T_world_session = Pose::Identity();
  std::vector<Pose> T_session_sensor_drifted;
  double seconds_per_keyframe = 0.125;
  std::vector<HdActor> actors;
};

struct Scenario {
  SimConfig cfg;
  Terrain terrain;
  Grid grid;
  Mesh static_mesh;   // permanent structure, world frame
  std::vector<LdObject> ld;
  std::vector<SessionPlan> sessions;
  Mesh car_mesh, pedestrian_mesh;  // actor prototypes, x forward, origin on the ground
};

// world.cpp
Scenario BuildScenario(const SimConfig& cfg);
// trajectory.cpp
Terrain MakeTerrain(const SimConfig& cfg, Rng& rng);
Grid MakeGrid(const SimConfig& cfg);
// Route over the grid's intersections: street centre line with rounded corners, dense.
Path MakeRoute(const SimConfig& cfg, const Grid& grid, Rng& rng, double min_length,
               const Path* reference, double min_overlap);
double RouteOverlap(const Path& a, const Path& b, double tol);
// The part of a route's centre line its keyframes cover (KeyframePoses' arc lengths).
Path DrivenPart(const SimConfig& cfg, const Path& centre);
std::vector<Pose> KeyframePoses(const SimConfig& cfg, const Grid& grid, const Terrain& terrain,
                                const Path& centre);
std::vector<HdActor> MakeActors(const SimConfig& cfg, const Path& centre, int session,
                                int first_id, Rng& rng);
Pose YawPose(double x, double y, double z, double yaw);

}  // namespace ltm::sim::detail
