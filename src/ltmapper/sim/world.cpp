// The synthetic city: meshes, the permanent world with its slots for changes, LD objects placed
// near the routes, and BuildScenario() tying routes, actors and drift together.
#include "ltmapper/sim/internal.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace ltm::sim::detail {

float Reflectivity(std::uint8_t m) {
  static const float kR[kMaterialCount] = {0.12f, 0.30f, 0.45f, 0.08f, 0.25f,
                                           0.35f, 0.70f, 0.55f, 0.30f};
  return m < kMaterialCount ? kR[m] : 0.3f;
}

// --------------------------------------------------------------------------------- mesh parts
void Mesh::AddBox(const Eigen::Vector2d& c, double z0, const Eigen::Vector3d& size, double yaw,
                  std::uint8_t m, bool bottom) {
  const auto base = std::uint32_t(v.size());
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  for (int k = 0; k < 8; ++k) {
    const double lx = (k & 1 ? 0.5 : -0.5) * size.x(), ly = (k & 2 ? 0.5 : -0.5) * size.y();
    const double z = k & 4 ? z0 + size.z() : z0;
    v.emplace_back(float(c.x() + cy * lx - sy * ly), float(c.y() + sy * lx + cy * ly), float(z));
  }
  auto q = [&](int a, int b, int cc, int d) { Quad(base + a, base + b, base + cc, base + d, m); };
  q(0, 2, 6, 4);  // -x
  q(1, 5, 7, 3);  // +x
  q(0, 4, 5, 1);  // -y
  q(2, 3, 7, 6);  // +y
  q(4, 5, 7, 6);  // top
  if (bottom) q(0, 1, 3, 2);
}

void Mesh::AddCylinder(const Eigen::Vector2d& c, double z0, double radius, double height, int sides,
                       std::uint8_t m) {
  const auto base = std::uint32_t(v.size());
  for (int i = 0; i < sides; ++i) {
    const double a = 2 * M_PI * i / sides;
    const float x = float(c.x() + radius * std::cos(a)), y = float(c.y() + radius * std::sin(a));
    v.emplace_back(x, y, float(z0));
    v.emplace_back(x, y, float(z0 + height));
  }
  const auto top = std::uint32_t(v.size());
  v.emplace_back(float(c.x()), float(c.y()), float(z0 + height));
  for (int i = 0; i < sides; ++i) {
    const std::uint32_t a = base + 2 * i, b = base + 2 * ((i + 1) % sides);
    Quad(a, b, b + 1, a + 1, m);
    Tri(a + 1, b + 1, top, m);
  }
}

void Mesh::AddEllipsoid(const Eigen::Vector3d& c, const Eigen::Vector3d& radii, int subdivisions,
                        std::uint8_t m) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                    {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                    {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<std::uint32_t, 3>> tri = {
      {0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
      {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (auto& x : p) x.normalize();
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      p.push_back((p[a] + p[b]).normalized());
      const auto id = std::uint32_t(p.size() - 1);
      mid.emplace(key, id);
      return id;
    };
    std::vector<std::array<std::uint32_t, 3>> next;
    for (auto& f3 : tri) {
      const auto a = midpoint(f3[0], f3[1]), b = midpoint(f3[1], f3[2]), cc = midpoint(f3[2], f3[0]);
      next.push_back({f3[0], a, cc});
      next.push_back({f3[1], b, a});
      next.push_back({f3[2], cc, b});
      next.push_back({a, b, cc});
    }
    tri.swap(next);
  }
  const auto base = std::uint32_t(v.size());
  for (auto& x : p) v.push_back((c + x.cwiseProduct(radii)).cast<float>());
  for (auto& f3 : tri) Tri(base + f3[0], base + f3[1], base + f3[2], m);
}

void Mesh::Append(const Mesh& o) {
  const auto base = std::uint32_t(v.size());
  v.insert(v.end(), o.v.begin(), o.v.end());
  for (std::size_t i = 0; i < o.f.size(); ++i) {
    Tri(base + o.f[i][0], base + o.f[i][1], base + o.f[i][2], o.mat[i]);
  }
}

Eigen::AlignedBox3d Mesh::Bounds() const {
  Eigen::AlignedBox3d b;
  for (const auto& x : v) b.extend(x.cast<double>());
  return b;
}

namespace {

Eigen::Vector2d Rot(double yaw, double x, double y) {
  return {std::cos(yaw) * x - std::sin(yaw) * y, std::sin(yaw) * x + std::cos(yaw) * y};
}

// Car of length L and width W; origin at the ground under its centre.
void AddCar(Mesh& m, const Eigen::Vector2d& c, double z, double yaw, double L, double W,
            std::uint8_t paint) {
  m.AddBox(c, z + 0.3, {L, W, 0.72}, yaw, paint, true);
  m.AddBox(c + Rot(yaw, -0.05 * L, 0), z + 1.02, {0.55 * L, W - 0.16, 0.48}, yaw, kGlass);
  for (int sx : {-1, 1}) {
    for (int sy : {-1, 1}) {
      m.AddBox(c + Rot(yaw, sx * 0.33 * L, sy * (0.5 * W - 0.12)), z, {0.62, 0.22, 0.62}, yaw, kAsphalt);
    }
  }
}

void AddVan(Mesh& m, const Eigen::Vector2d& c, double z, double yaw) {
  m.AddBox(c, z + 0.3, {5.2, 2.0, 1.9}, yaw, kPaint, true);
  for (int sx : {-1, 1}) {
    for (int sy : {-1, 1}) m.AddBox(c + Rot(yaw, sx * 1.7, sy * 0.88), z, {0.7, 0.24, 0.7}, yaw, kAsphalt);
  }
}

void AddTruck(Mesh& m, const Eigen::Vector2d& c, double z, double yaw, double L) {
  m.AddBox(c + Rot(yaw, 0.5 * L - 1.1, 0), z + 0.4, {2.2, 2.4, 2.5}, yaw, kPaint, true);
  m.AddBox(c + Rot(yaw, -1.2, 0), z + 0.7, {L - 2.4, 2.5, 3.0}, yaw, kMetal, true);
  for (double x : {0.5 * L - 1.1, -0.2 * L, -0.4 * L}) {
    for (int sy : {-1, 1}) m.AddBox(c + Rot(yaw, x, sy * 1.0), z, {0.9, 0.3, 0.9}, yaw, kAsphalt);
  }
}

void AddTree(Mesh& m, const Eigen::Vector2d& c, double z, Rng& rng) {
  const double h = rng.Uniform(2.2, 3.5), r = rng.Uniform(0.15, 0.3);
  m.AddCylinder(c, z - 0.1, r, h + 0.6, 8, kBark);
  const double rxy = rng.Uniform(1.5, 2.8), rz = rng.Uniform(1.5, 2.5);
  m.AddEllipsoid({c.x(), c.y(), z + h + 0.8 * rz}, {rxy, rxy * rng.Uniform(0.85, 1.0), rz}, 2, kLeaves);
}

void AddPole(Mesh& m, const Eigen::Vector2d& c, double z, const Eigen::Vector2d& to_road) {
  m.AddCylinder(c, z - 0.1, 0.1, 7.1, 8, kMetal);
  m.AddBox(c + 0.75 * to_road, z + 6.8, {1.5, 0.12, 0.12}, std::atan2(to_road.y(), to_road.x()), kMetal, true);
}

// Panels along a line from a to b (gap between panels), height h, thickness th.
void AddPanels(Mesh& m, const Grid& grid, const Terrain& terrain, const Eigen::Vector2d& a,
               const Eigen::Vector2d& b, double panel, double gap, double h, double th,
               std::uint8_t mat) {
  const double len = (b - a).norm();
  const Eigen::Vector2d d = (b - a) / len;
  const double yaw = std::atan2(d.y(), d.x());
  for (double u = 0; u + 0.5 < len; u += panel + gap) {
    const double w = std::min(panel, len - u);
    const Eigen::Vector2d c = a + d * (u + 0.5 * w);
    const double z = grid.GroundZ(terrain, c.x(), c.y());
    m.AddBox(c, z + 0.05, {w, th, h}, yaw, mat);
    m.AddBox(a + d * u, z - 0.05, {0.25, 0.6, 0.18}, yaw, kConcrete);  // foot
  }
}

// A lot along a street: P(u, v) = origin + dir * u + in * v, u along the frontage, v inward
// from the building line.
struct Lot {
  Eigen::Vector2d origin, dir, in;
  double width = 0, depth = 0;
  bool used = false;
  Eigen::Vector2d P(double u, double v) const { return origin + dir * u + in * v; }
  double yaw() const { return std::atan2(dir.y(), dir.x()); }
};
struct Slot {
  Eigen::Vector2d c;
  double yaw = 0;
  bool used = false;
};
struct Slots {
  std::vector<Slot> park, trees;
  std::vector<Lot> lots;
};

struct Rect {
  Eigen::Vector2d lo, hi;
  bool Overlaps(const Rect& o) const {
    return lo.x() < o.hi.x() && o.lo.x() < hi.x() && lo.y() < o.hi.y() && o.lo.y() < hi.y();
  }
};

void AddHeightPatch(Mesh& m, const Terrain& t, double x0, double x1, double y0, double y1,
                    double cell, double lift, std::uint8_t mat) {
  const int nx = std::max(1, int(std::ceil((x1 - x0) / cell))), ny = std::max(1, int(std::ceil((y1 - y0) / cell)));
  const auto base = std::uint32_t(m.v.size());
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const double x = x0 + (x1 - x0) * i / nx, y = y0 + (y1 - y0) * j / ny;
      m.v.emplace_back(float(x), float(y), float(t.Height(x, y) + lift));
    }
  }
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const std::uint32_t a = base + j * (nx + 1) + i;
      m.Quad(a, a + 1, a + nx + 2, a + nx + 1, mat);
    }
  }
}

// Vertical strip from the road surface up to the raised block along a block edge.
void AddCurb(Mesh& m, const Terrain& t, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
             double curb, double cell) {
  const int n = std::max(1, int(std::ceil((b - a).norm() / cell)));
  const auto base = std::uint32_t(m.v.size());
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector2d p = a + (b - a) * (double(i) / n);
    const double h = t.Height(p.x(), p.y());
    m.v.emplace_back(float(p.x()), float(p.y()), float(h - 0.02));
    m.v.emplace_back(float(p.x()), float(p.y()), float(h + curb));
  }
  for (int i = 0; i < n; ++i) m.Quad(base + 2 * i, base + 2 * i + 2, base + 2 * i + 3, base + 2 * i + 1, kConcrete);
}

// Building on a lot: main block set back from the building line plus bays protruding towards
// the street (facades of varied depth).
void AddBuilding(Mesh& m, const Grid& grid, const Terrain& terrain, const Lot& lot, double u0,
                 double w, double setback, double depth, double height,
                 const std::vector<std::array<double, 5>>& bays) {
  const Eigen::Vector2d c = lot.P(u0 + 0.5 * w, setback + 0.5 * depth);
  const double z = grid.GroundZ(terrain, c.x(), c.y()) - 0.6;
  m.AddBox(c, z, {w, depth, height + 0.6}, lot.yaw(), kFacade);
  for (const auto& b : bays) {  // {u centre, width, protrusion, z from, z to} relative to lot
    const Eigen::Vector2d bc = lot.P(b[0], setback - 0.5 * b[2] + 0.05);
    const double bz = grid.GroundZ(terrain, bc.x(), bc.y());
    const std::uint8_t mat = b[1] > 3.0 ? kGlass : kFacade;
    m.AddBox(bc, bz + b[3], {b[1], b[2] + 0.1, b[4] - b[3]}, lot.yaw(), mat, true);
  }
}

// Permanent world and its free slots. Raised blocks between the streets carry sidewalks with
// poles and trees, parking strips along the curbs, and lots with buildings or open yards.
Slots BuildStatic(const SimConfig& cfg, const Grid& grid, const Terrain& terrain, Rng& rng, Mesh& m) {
  Slots slots;
  const double H = grid.half_extent, r = grid.road_half, sw = grid.sidewalk;
  // Ground (roads) and raised blocks.
  AddHeightPatch(m, terrain, -H, H, -H, H, cfg.ground_cell_m, 0.0, kAsphalt);
  std::vector<double> b = {-H};
  for (double l : grid.lines) {
    b.push_back(l - r);
    b.push_back(l + r);
  }
  b.push_back(H);
  struct Interval {
    double lo, hi;
    bool street_lo, street_hi;
  };
  std::vector<Interval> iv;
  for (std::size_t i = 0; i + 1 < b.size(); i += 2) {
    if (b[i + 1] - b[i] > 2.0) iv.push_back({b[i], b[i + 1], i > 0, i + 2 < b.size()});
  }
  const bool repetitive = cfg.scenario == "repetitive";
  std::vector<Rect> footprints;
  for (const auto& X : iv) {
    for (const auto& Y : iv) {
      AddHeightPatch(m, terrain, X.lo, X.hi, Y.lo, Y.hi, cfg.ground_cell_m, cfg.curb_m, kConcrete);
      // Sides facing streets: x-facing first (full length), then y-facing.
      struct Side {
        Eigen::Vector2d curb0, dir, in;
        double len, avail;
      };
      std::vector<Side> sides;
      const double wx = X.hi - X.lo, wy = Y.hi - Y.lo;
      const double ax = (X.street_lo && X.street_hi ? 0.5 * (wx - 2 * sw) : wx - sw) - 0.5;
      const double ay = (Y.street_lo && Y.street_hi ? 0.5 * (wy - 2 * sw) : wy - sw) - 0.5;
      if (X.street_lo) sides.push_back({{X.lo, Y.lo}, {0, 1}, {1, 0}, wy, ax});
      if (X.street_hi) sides.push_back({{X.hi, Y.lo}, {0, 1}, {-1, 0}, wy, ax});
      if (Y.street_lo) sides.push_back({{X.lo, Y.lo}, {1, 0}, {0, 1}, wx, ay});
      if (Y.street_hi) sides.push_back({{X.lo, Y.hi}, {1, 0}, {0, -1}, wx, ay});
      for (const auto& s : sides) {
        AddCurb(m, terrain, s.curb0, s.curb0 + s.dir * s.len, cfg.curb_m, cfg.ground_cell_m);
        auto at = [&](double u, double v) { return Eigen::Vector2d(s.curb0 + s.dir * u + s.in * v); };
        // Poles and trees on the sidewalk.
        std::vector<double> poles;
        for (double u = rng.Uniform(2.0, cfg.pole_spacing_m); u < s.len - 2.0; u += cfg.pole_spacing_m) {
          const Eigen::Vector2d p = at(u, 0.4);
          AddPole(m, p, grid.GroundZ(terrain, p.x(), p.y()), -s.in);
          poles.push_back(u);
        }
        for (double u = rng.Uniform(3.0, cfg.tree_spacing_m); u < s.len - 3.0; u += cfg.tree_spacing_m) {
          bool near_pole = false;
          for (double pu : poles) near_pole |= std::abs(pu - u) < 2.0;
          if (near_pole) continue;
          const Eigen::Vector2d p = at(u, 1.4);
          if (rng.Bernoulli(cfg.tree_fill)) {
            AddTree(m, p, grid.GroundZ(terrain, p.x(), p.y()), rng);
          } else {
            slots.trees.push_back({p, 0.0});
          }
        }
        // Parking strip on the road next to the curb, clear of the intersections.
        const double clear = cfg.corner_radius_m + 2.0;
        const double yaw = std::atan2(s.dir.y(), s.dir.x());
        for (double u = clear; u + clear < s.len; u += 6.5) {
          const Eigen::Vector2d p = at(u, -1.25);
          const double z = terrain.Height(p.x(), p.y());
          if (rng.Bernoulli(cfg.parking_fill)) {
            const double kind = rng.Uniform();
            if (kind < 0.8) {
              AddCar(m, p, z, yaw, rng.Uniform(4.0, 4.8), rng.Uniform(1.7, 1.9), kPaint);
            } else if (kind < 0.95) {
              AddVan(m, p, z, yaw);
            } else if (u + 6.5 + clear < s.len) {
              AddTruck(m, at(u + 3.0, -1.25), z, yaw, 9.0);
              u += 6.5;
            }
          } else {
            slots.park.push_back({p, yaw});
          }
        }
        // Lots along the building line.
        if (s.avail < 4.0) continue;
        Lot proto;
        proto.origin = at(0, sw);
        proto.dir = s.dir;
        proto.in = s.in;
        for (double u = sw; u + 8.0 < s.len - sw;) {
          const double w = std::min(repetitive ? 16.0 : rng.Uniform(12.0, 24.0), s.len - sw - u);
          const bool open = rng.Bernoulli(cfg.open_lot_fraction);
          const double depth = open ? std::min(14.0, s.avail)
                                    : (repetitive ? std::min(12.0, s.avail) : rng.Uniform(8.0, std::min(16.0, s.avail)));
          const Eigen::Vector2d p0 = proto.P(u, 0), p1 = proto.P(u + w, depth);
          const Rect rect{p0.cwiseMin(p1), p0.cwiseMax(p1)};
          bool overlap = false;
          for (const auto& f : footprints) overlap |= rect.Overlaps(f);
          if (overlap) {
            u += 2.0;
            continue;
          }
          footprints.push_back(rect);
          if (open) {
            const double kind = rng.Uniform();
            if (kind < 0.7) {
              Lot lot = proto;
              lot.origin = proto.P(u, 0);
              lot.width = w;
              lot.depth = depth;
              slots.lots.push_back(lot);
            } else if (kind < 0.9) {  // walled yard with a gate
              const double gate = rng.Uniform(2.0, w - 6.0), h = rng.Uniform(1.8, 2.6);
              const Eigen::Vector2d a = proto.P(u + 0.3, 0.2), g0 = proto.P(u + gate, 0.2),
                                    g1 = proto.P(u + gate + 4.0, 0.2), e = proto.P(u + w - 0.3, 0.2);
              for (auto [pa, pb] : {std::make_pair(a, g0), std::make_pair(g1, e)}) {
                const Eigen::Vector2d c = 0.5 * (pa + pb);
                m.AddBox(c, grid.GroundZ(terrain, c.x(), c.y()) - 0.2, {(pb - pa).norm(), 0.3, h + 0.2},
                         proto.yaw(), kConcrete);
              }
            } else {  // fenced yard
              AddPanels(m, grid, terrain, proto.P(u + 0.5, 0.3), proto.P(u + w - 0.5, 0.3), 2.5,
                        0.15, 1.6, 0.05, kMetal);
            }
          } else if (repetitive) {
            const double h = 0.5 * (cfg.building_min_height_m + cfg.building_max_height_m);
            AddBuilding(m, grid, terrain, proto, u + 1.0, w - 2.0, 1.0, depth - 1.0, h,
                        {{{u + 0.25 * w, 3.0, 0.8, 3.0, h - 1.0}}, {{u + 0.75 * w, 3.0, 0.8, 3.0, h - 1.0}}});
          } else {
            const double setback = rng.Uniform(0.8, 2.5), gap = rng.Uniform(0.0, 2.0);
            const double h = rng.Uniform(cfg.building_min_height_m, cfg.building_max_height_m);
            std::vector<std::array<double, 5>> bays;
            const int nb = rng.Int(4);
            for (int k = 0; k < nb; ++k) {
              const double bw = rng.Uniform(2.0, 4.5);
              const double bu = u + gap + rng.Uniform(0.5 * bw, std::max(0.5 * bw, w - 2 * gap - 0.5 * bw));
              const double z0 = rng.Uniform(0.0, 4.0);
              bays.push_back({bu, bw, rng.Uniform(0.3, setback), z0, std::max(z0 + 2.0, h - rng.Uniform(0.0, 3.0))});
            }
            AddBuilding(m, grid, terrain, proto, u + gap, w - 2 * gap, setback, depth - setback, h, bays);
          }
          u += w + (repetitive ? 4.0 : 0.0);
        }
      }
    }
  }
  return slots;
}

// ------------------------------------------------------------------------------- LD objects
struct Picker {
  const std::vector<Path>* routes;
  double near_m;
  Rng* rng;
  // Order: near route 0 and a query route, then near route 0, then near any route; shuffled
  // within each tier. Returns indices.
  std::vector<std::size_t> Order(const std::vector<Eigen::Vector2d>& pts) const {
    std::vector<std::vector<std::size_t>> tiers(3);
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const bool n0 = (*routes)[0].Distance(pts[i]) <= near_m;
      bool nq = false;
      for (std::size_t r = 1; r < routes->size(); ++r) nq |= (*routes)[r].Distance(pts[i]) <= near_m;
      if (n0 && (nq || routes->size() == 1)) tiers[0].push_back(i);
      else if (n0) tiers[1].push_back(i);
      else if (nq) tiers[2].push_back(i);
    }
    std::vector<std::size_t> out;
    for (auto& t : tiers) {
      for (std::size_t i = t.size(); i > 1; --i) std::swap(t[i - 1], t[std::size_t(rng->Int(int(i)))]);
      out.insert(out.end(), t.begin(), t.end());
    }
    return out;
  }
};

std::vector<int> Range(int a, int b) {  // [a, b)
  std::vector<int> r;
  for (int i = a; i < b; ++i) r.push_back(i);
  return r;
}

std::vector<LdObject> PlaceLd(const SimConfig& cfg, const Grid& grid, const Terrain& terrain,
                              Slots& slots, const std::vector<Path>& routes, Rng& rng) {
  std::vector<LdObject> out;
  const int N = cfg.sessions;
  if (N < 2) return out;
  Picker pick{&routes, cfg.ld_route_distance_m, &rng};
  std::vector<Eigen::Vector2d> pp, tp, lp;
  for (auto& s : slots.park) pp.push_back(s.c);
  for (auto& s : slots.trees) tp.push_back(s.c);
  for (auto& l : slots.lots) lp.push_back(l.P(0.5 * l.width, 0));
  const auto park_order = pick.Order(pp), tree_order = pick.Order(tp), lot_order = pick.Order(lp);
  std::size_t park_i = 0, tree_i = 0, lot_i = 0;
  auto next_lot = [&](double min_w, double min_depth) -> Lot* {
    for (; lot_i < lot_order.size(); ++lot_i) {
      Lot& l = slots.lots[lot_order[lot_i]];
      if (!l.used && l.width >= min_w && l.depth >= min_depth) {
        l.used = true;
        ++lot_i;
        return &l;
      }
    }
    return nullptr;
  };
  auto change_session = [&]() { return 1 + rng.Int(N - 1); };  // in [1, N-1]
  auto add = [&](const std::string& cls, std::vector<int> present, const std::string& placement) -> Mesh& {
    LdObject o;
    o.info.id = int(out.size());
    o.info.cls = cls;
    o.info.present_in = std::move(present);
    o.info.placement = placement;
    out.push_back(std::move(o));
    return out.back().mesh;
  };
  auto gz = [&](const Eigen::Vector2d& p) { return grid.GroundZ(terrain, p.x(), p.y()); };

  // Parked cars come and go at random, except that (with 2+ sessions) the first car whose slot
  // lies near both the central and the last route is new in the last session (a parked car the
  // live map must show and the meta map must not) and the next such car left after session 0.
  std::vector<int> forced_new = {N - 1}, forced_gone = {0};
  std::vector<std::vector<int>*> forced = {&forced_new, &forced_gone};
  std::size_t forced_i = 0;
  for (int i = 0; i < cfg.ld_parked_cars && park_i < park_order.size(); ++i) {
    const Slot& s = slots.park[park_order[park_i++]];
    std::vector<int> present;
    do {
      present.clear();
      for (int k = 0; k < N; ++k) {
        if (rng.Bernoulli(0.5)) present.push_back(k);
      }
    } while (present.empty() || int(present.size()) == N);
    if (N >= 2 && forced_i < forced.size() && routes[0].Distance(s.c) <= cfg.ld_route_distance_m &&
        routes[std::size_t(N - 1)].Distance(s.c) <= cfg.ld_route_distance_m)
      present = *forced[forced_i++];
    AddCar(add("car", present, "open"), s.c, terrain.Height(s.c.x(), s.c.y()), s.yaw,
           rng.Uniform(4.0, 4.8), rng.Uniform(1.7, 1.9), kPaint);
  }
  for (int i = 0; i < cfg.ld_trees_cut && tree_i < tree_order.size(); ++i) {
    const Slot& s = slots.trees[tree_order[tree_i++]];
    AddTree(add("tree", Range(0, change_session()), "open"), s.c, gz(s.c), rng);
  }
  for (int i = 0; i < cfg.ld_fences; ++i) {
    Lot* l = next_lot(8.0, 3.0);
    if (!l) break;
    const int m = change_session();
    Mesh& mesh = add("fence", i % 2 == 0 ? Range(m, N) : Range(0, m), "open");
    AddPanels(mesh, grid, terrain, l->P(1.0, 0.4), l->P(l->width - 1.0, 0.4), 3.4, 0.1, 2.0, 0.05, kMetal);
  }
  for (int i = 0; i < cfg.ld_containers; ++i) {
    Lot* a = next_lot(8.0, 6.0);
    Lot* b = a ? next_lot(8.0, 6.0) : nullptr;
    if (!b) break;
    const int m = change_session();
    for (auto [lot, present] : {std::make_pair(a, Range(0, m)), std::make_pair(b, Range(m, N))}) {
      const Eigen::Vector2d c = lot->P(0.5 * lot->width, 4.0);
      add("container", present, "open").AddBox(c, gz(c) - 0.05, {6.06, 2.44, 2.64}, lot->yaw(), kMetal);
    }
  }
  for (int i = 0; i < cfg.ld_structures; ++i) {
    Lot* l = next_lot(6.0, 7.0);
    if (!l) break;
    const Eigen::Vector2d c = l->P(0.5 * l->width, 5.0);
    Mesh& mesh = add("structure", Range(change_session(), N), "open");
    mesh.AddBox(c, gz(c) - 0.05, {3.0, 3.0, 2.85}, l->yaw(), kPaint);
    mesh.AddBox(c, gz(c) + 2.8, {3.6, 3.6, 0.2}, l->yaw(), kMetal, true);
  }
  for (int i = 0; i < cfg.ld_wall_reveals; ++i) {
    // The central session sees a wall; later sessions see the wall gone and a shed behind it,
    // in space the central could not observe (strong PD).
    Lot* l = next_lot(12.0, 12.0);
    if (!l) break;
    // Walls closing the lot on all four sides (front on the building line): no ray of the
    // central session reaches inside.
    Mesh& wall = add("wall", {0}, "open");
    const double wd = 11.0, wh = 3.4;
    const Eigen::Vector2d front = l->P(0.5 * l->width, 0.35), back = l->P(0.5 * l->width, wd);
    wall.AddBox(front, gz(front) - 0.2, {l->width - 0.6, 0.3, wh}, l->yaw(), kConcrete);
    wall.AddBox(back, gz(back) - 0.2, {l->width - 0.6, 0.3, wh}, l->yaw(), kConcrete);
    for (double u : {0.45, l->width - 0.45}) {
      const Eigen::Vector2d c = l->P(u, 0.5 * (0.35 + wd));
      wall.AddBox(c, gz(c) - 0.2, {0.3, wd - 0.35, wh}, l->yaw(), kConcrete);
    }
    const Eigen::Vector2d sc = l->P(0.5 * l->width, 7.0);
    add("structure", Range(1, N), "revealed").AddBox(sc, gz(sc) - 0.05, {std::min(8.0, l->width - 3.0), 5.0, 3.35}, l->yaw(), kFacade);
  }
  for (int i = 0; i < cfg.ld_occluded; ++i) {
    // A hoarding goes up around a lot while the object inside disappears: the later sessions
    // cannot see through the hoarding, so the object's absence is weak ND.
    Lot* l = next_lot(14.0, 8.0);
    if (!l) break;
    const int m = change_session();
    // The hoarding closes the lot on all four sides, as around a building site.
    Mesh& h = add("hoarding", Range(m, N), "open");
    const double hd = std::min(l->depth - 0.5, 8.0);
    const Eigen::Vector2d q0 = l->P(0.3, 0.3), q1 = l->P(l->width - 0.3, 0.3), q2 = l->P(l->width - 0.3, hd),
                          q3 = l->P(0.3, hd);
    for (auto [a, b] : {std::make_pair(q0, q1), std::make_pair(q1, q2), std::make_pair(q2, q3), std::make_pair(q3, q0)}) {
      AddPanels(h, grid, terrain, a, b, 4.0, 0.0, 3.0, 0.08, kPaint);
    }
    const Eigen::Vector2d c = l->P(0.5 * l->width, 4.0);
    if (i % 2 == 0) {
      add("container", Range(0, m), "occluded").AddBox(c, gz(c) - 0.05, {6.06, 2.44, 2.4}, l->yaw(), kMetal);
    } else {
      AddCar(add("car", Range(0, m), "occluded"), c, gz(c), l->yaw(), 4.5, 1.8, kPaint);
    }
  }
  for (auto& o : out) {
    const auto bb = o.mesh.Bounds();
    o.info.box_min = bb.min();
    o.info.box_max = bb.max();
    o.info.centroid = bb.center();
  }
  return out;
}

}  // namespace

Scenario BuildScenario(const SimConfig& user_cfg) {
  Scenario sc;
  sc.cfg = ResolveLidar(user_cfg);
  const SimConfig& cfg = sc.cfg;
  const auto seed = std::uint64_t(cfg.seed);
  Rng terrain_rng(Hash(seed, 1));
  sc.terrain = MakeTerrain(cfg, terrain_rng);
  sc.grid = MakeGrid(cfg);

  // Routes first: LD objects are placed where the sessions drive.
  Rng route_rng(Hash(seed, 2));
  const double min_len = 30.0 + (cfg.keyframes - 1) * cfg.keyframe_spacing_m + 40.0;
  std::vector<Path> routes;
  for (int s = 0; s < cfg.sessions; ++s) {
    routes.push_back(MakeRoute(cfg, sc.grid, route_rng, min_len, s == 0 ? nullptr : &routes[0],
                               cfg.min_route_overlap));
  }

  Rng world_rng(Hash(seed, 3));
  Slots slots = BuildStatic(cfg, sc.grid, sc.terrain, world_rng, sc.static_mesh);
  Rng ld_rng(Hash(seed, 4));
  sc.ld = PlaceLd(cfg, sc.grid, sc.terrain, slots, routes, ld_rng);

  AddCar(sc.car_mesh, {0, 0}, 0.0, 0.0, 4.5, 1.8, kPaint);
  sc.pedestrian_mesh.AddBox({0, 0}, 0.0, {0.25, 0.38, 0.86}, 0.0, kCloth, true);
  sc.pedestrian_mesh.AddBox({0, 0}, 0.86, {0.3, 0.46, 0.6}, 0.0, kCloth, true);
  sc.pedestrian_mesh.AddEllipsoid({0, 0, 1.6}, {0.1, 0.1, 0.12}, 1, kCloth);

  int next_actor_id = int(sc.ld.size());
  for (int s = 0; s < cfg.sessions; ++s) {
    SessionPlan plan;
    plan.centre = routes[s];
    plan.T_world_sensor = KeyframePoses(cfg, sc.grid, sc.terrain, plan.centre);
    if (cfg.tilt_deg != 0.0) {  // the sensor pitched on its mount: rotation about its own y axis
      const Eigen::Matrix3d tilt = Eigen::AngleAxisd(cfg.tilt_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
      for (Pose& T : plan.T_world_sensor) T.linear() = T.linear() * tilt;
    }
    Rng origin_rng(Hash(seed, 5, std::uint64_t(s)));
    plan.T_world_session =
        YawPose(origin_rng.Uniform(-1, 1) * cfg.origin_offset_m, origin_rng.Uniform(-1, 1) * cfg.origin_offset_m,
                origin_rng.Uniform(-1, 1) * cfg.origin_offset_z_m, origin_rng.Uniform(-M_PI, M_PI));
    std::vector<Pose> local;
    for (const auto& T : plan.T_world_sensor) local.push_back(plan.T_world_session.inverse() * T);
    plan.T_session_sensor_drifted = DriftPoses(local, cfg, Hash(seed, 6, std::uint64_t(s)));
    plan.seconds_per_keyframe = cfg.keyframe_spacing_m / cfg.ego_speed_mps;
    Rng actor_rng(Hash(seed, 7, std::uint64_t(s)));
    plan.actors = MakeActors(cfg, plan.centre, s, next_actor_id, actor_rng);
    next_actor_id += int(plan.actors.size());
    sc.sessions.push_back(std::move(plan));
  }
  return sc;
}

}  // namespace ltm::sim::detail
