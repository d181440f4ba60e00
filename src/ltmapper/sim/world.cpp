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

// The street-facing side of a raised block: the curb from curb0 along dir (len), inward `in`,
// with `avail` of depth for lots behind the sidewalk.
struct Side {
  Eigen::Vector2d curb0, dir, in;
  double len, avail;
  Eigen::Vector2d At(double u, double v) const { return curb0 + dir * u + in * v; }
};

// A block's extent along one axis, and whether a street lies on each end.
struct Interval {
  double lo, hi;
  bool street_lo, street_hi;
};

// The permanent world built block by block (the rng is drawn in a fixed order: same seed, same
// world): sidewalks with poles and trees, parking strips along the curbs, lots with buildings or
// open yards; the free slots are kept for the LD objects.
class StaticBuilder {
 public:
  StaticBuilder(const SimConfig& cfg, const Grid& grid, const Terrain& terrain, Rng& rng, Mesh& m)
      : cfg_(cfg), grid_(grid), terrain_(terrain), rng_(rng), m_(m), repetitive_(cfg.scenario == "repetitive") {}

  Slots Build() {
    const double H = grid_.half_extent;
    AddHeightPatch(m_, terrain_, -H, H, -H, H, cfg_.ground_cell_m, 0.0, kAsphalt);  // ground (roads)
    const std::vector<Interval> iv = Blocks();
    for (const auto& X : iv)
      for (const auto& Y : iv) Block(X, Y);
    return std::move(slots_);
  }

 private:
  // The raised blocks' extents between the streets (one axis; the grid is square).
  std::vector<Interval> Blocks() const {
    const double H = grid_.half_extent, r = grid_.road_half;
    std::vector<double> b = {-H};
    for (double l : grid_.lines) {
      b.push_back(l - r);
      b.push_back(l + r);
    }
    b.push_back(H);
    std::vector<Interval> iv;
    for (std::size_t i = 0; i + 1 < b.size(); i += 2)
      if (b[i + 1] - b[i] > 2.0) iv.push_back({b[i], b[i + 1], i > 0, i + 2 < b.size()});
    return iv;
  }

  // One raised block: its ground, then each street-facing side (x-facing first, full length).
  void Block(const Interval& X, const Interval& Y) {
    const double sw = grid_.sidewalk;
    AddHeightPatch(m_, terrain_, X.lo, X.hi, Y.lo, Y.hi, cfg_.ground_cell_m, cfg_.curb_m, kConcrete);
    std::vector<Side> sides;
    const double wx = X.hi - X.lo, wy = Y.hi - Y.lo;
    const double ax = (X.street_lo && X.street_hi ? 0.5 * (wx - 2 * sw) : wx - sw) - 0.5;
    const double ay = (Y.street_lo && Y.street_hi ? 0.5 * (wy - 2 * sw) : wy - sw) - 0.5;
    if (X.street_lo) sides.push_back({{X.lo, Y.lo}, {0, 1}, {1, 0}, wy, ax});
    if (X.street_hi) sides.push_back({{X.hi, Y.lo}, {0, 1}, {-1, 0}, wy, ax});
    if (Y.street_lo) sides.push_back({{X.lo, Y.lo}, {1, 0}, {0, 1}, wx, ay});
    if (Y.street_hi) sides.push_back({{X.lo, Y.hi}, {1, 0}, {0, -1}, wx, ay});
    for (const auto& s : sides) {
      AddCurb(m_, terrain_, s.curb0, s.curb0 + s.dir * s.len, cfg_.curb_m, cfg_.ground_cell_m);
      Sidewalk(s);
      ParkingStrip(s);
      if (s.avail >= 4.0) Lots(s);
    }
  }

  // Poles, then trees clear of them (a tree slot left empty is free for LD trees).
  void Sidewalk(const Side& s) {
    std::vector<double> poles;
    for (double u = rng_.Uniform(2.0, cfg_.pole_spacing_m); u < s.len - 2.0; u += cfg_.pole_spacing_m) {
      const Eigen::Vector2d p = s.At(u, 0.4);
      AddPole(m_, p, grid_.GroundZ(terrain_, p.x(), p.y()), -s.in);
      poles.push_back(u);
    }
    for (double u = rng_.Uniform(3.0, cfg_.tree_spacing_m); u < s.len - 3.0; u += cfg_.tree_spacing_m) {
      bool near_pole = false;
      for (double pu : poles) near_pole |= std::abs(pu - u) < 2.0;
      if (near_pole) continue;
      const Eigen::Vector2d p = s.At(u, 1.4);
      if (rng_.Bernoulli(cfg_.tree_fill))
        AddTree(m_, p, grid_.GroundZ(terrain_, p.x(), p.y()), rng_);
      else
        slots_.trees.push_back({p, 0.0});
    }
  }

  // Parking strip on the road next to the curb, clear of the intersections.
  void ParkingStrip(const Side& s) {
    const double clear = cfg_.corner_radius_m + 2.0;
    const double yaw = std::atan2(s.dir.y(), s.dir.x());
    for (double u = clear; u + clear < s.len; u += 6.5) {
      const Eigen::Vector2d p = s.At(u, -1.25);
      const double z = terrain_.Height(p.x(), p.y());
      if (!rng_.Bernoulli(cfg_.parking_fill)) {
        slots_.park.push_back({p, yaw});
        continue;
      }
      const double kind = rng_.Uniform();
      if (kind < 0.8) {
        AddCar(m_, p, z, yaw, rng_.Uniform(4.0, 4.8), rng_.Uniform(1.7, 1.9), kPaint);
      } else if (kind < 0.95) {
        AddVan(m_, p, z, yaw);
      } else if (u + 6.5 + clear < s.len) {
        AddTruck(m_, s.At(u + 3.0, -1.25), z, yaw, 9.0);
        u += 6.5;
      }
    }
  }

  // Lots along the building line, each open (a yard, walled, fenced) or built.
  void Lots(const Side& s) {
    const double sw = grid_.sidewalk;
    Lot proto;
    proto.origin = s.At(0, sw);
    proto.dir = s.dir;
    proto.in = s.in;
    for (double u = sw; u + 8.0 < s.len - sw;) {
      const double w = std::min(repetitive_ ? 16.0 : rng_.Uniform(12.0, 24.0), s.len - sw - u);
      const bool open = rng_.Bernoulli(cfg_.open_lot_fraction);
      const double depth = open ? std::min(14.0, s.avail)
                                : (repetitive_ ? std::min(12.0, s.avail) : rng_.Uniform(8.0, std::min(16.0, s.avail)));
      const Eigen::Vector2d p0 = proto.P(u, 0), p1 = proto.P(u + w, depth);
      const Rect rect{p0.cwiseMin(p1), p0.cwiseMax(p1)};
      bool overlap = false;
      for (const auto& f : footprints_) overlap |= rect.Overlaps(f);
      if (overlap) {
        u += 2.0;
        continue;
      }
      footprints_.push_back(rect);
      if (open)
        OpenLot(proto, u, w, depth);
      else
        BuiltLot(proto, u, w, depth);
      u += w + (repetitive_ ? 4.0 : 0.0);
    }
  }

  void OpenLot(const Lot& proto, double u, double w, double depth) {
    const double kind = rng_.Uniform();
    if (kind < 0.7) {  // free for LD objects
      Lot lot = proto;
      lot.origin = proto.P(u, 0);
      lot.width = w;
      lot.depth = depth;
      slots_.lots.push_back(lot);
    } else if (kind < 0.9) {  // walled yard with a gate
      const double gate = rng_.Uniform(2.0, w - 6.0), h = rng_.Uniform(1.8, 2.6);
      const Eigen::Vector2d a = proto.P(u + 0.3, 0.2), g0 = proto.P(u + gate, 0.2), g1 = proto.P(u + gate + 4.0, 0.2),
                            e = proto.P(u + w - 0.3, 0.2);
      for (auto [pa, pb] : {std::make_pair(a, g0), std::make_pair(g1, e)}) {
        const Eigen::Vector2d c = 0.5 * (pa + pb);
        m_.AddBox(c, grid_.GroundZ(terrain_, c.x(), c.y()) - 0.2, {(pb - pa).norm(), 0.3, h + 0.2}, proto.yaw(),
                  kConcrete);
      }
    } else {  // fenced yard
      AddPanels(m_, grid_, terrain_, proto.P(u + 0.5, 0.3), proto.P(u + w - 0.5, 0.3), 2.5, 0.15, 1.6, 0.05, kMetal);
    }
  }

  void BuiltLot(const Lot& proto, double u, double w, double depth) {
    if (repetitive_) {
      const double h = 0.5 * (cfg_.building_min_height_m + cfg_.building_max_height_m);
      AddBuilding(m_, grid_, terrain_, proto, u + 1.0, w - 2.0, 1.0, depth - 1.0, h,
                  {{{u + 0.25 * w, 3.0, 0.8, 3.0, h - 1.0}}, {{u + 0.75 * w, 3.0, 0.8, 3.0, h - 1.0}}});
      return;
    }
    const double setback = rng_.Uniform(0.8, 2.5), gap = rng_.Uniform(0.0, 2.0);
    const double h = rng_.Uniform(cfg_.building_min_height_m, cfg_.building_max_height_m);
    std::vector<std::array<double, 5>> bays;
    const int nb = rng_.Int(4);
    for (int k = 0; k < nb; ++k) {
      const double bw = rng_.Uniform(2.0, 4.5);
      const double bu = u + gap + rng_.Uniform(0.5 * bw, std::max(0.5 * bw, w - 2 * gap - 0.5 * bw));
      const double z0 = rng_.Uniform(0.0, 4.0);
      bays.push_back({bu, bw, rng_.Uniform(0.3, setback), z0, std::max(z0 + 2.0, h - rng_.Uniform(0.0, 3.0))});
    }
    AddBuilding(m_, grid_, terrain_, proto, u + gap, w - 2 * gap, setback, depth - setback, h, bays);
  }

  const SimConfig& cfg_;
  const Grid& grid_;
  const Terrain& terrain_;
  Rng& rng_;
  Mesh& m_;
  const bool repetitive_;
  Slots slots_;
  std::vector<Rect> footprints_;
};

// Permanent world and its free slots.
Slots BuildStatic(const SimConfig& cfg, const Grid& grid, const Terrain& terrain, Rng& rng, Mesh& m) {
  return StaticBuilder(cfg, grid, terrain, rng, m).Build();
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

// The LD objects placed kind by kind into the free slots, those near the routes first (the rng
// is drawn in a fixed order: same seed, same objects).
class LdPlacer {
 public:
  LdPlacer(const SimConfig& cfg, const Grid& grid, const Terrain& terrain, Slots& slots, const std::vector<Path>& routes,
           Rng& rng)
      : cfg_(cfg), grid_(grid), terrain_(terrain), slots_(slots), routes_(routes), rng_(rng), N_(cfg.sessions) {
    const Picker pick{&routes, cfg.ld_route_distance_m, &rng};
    std::vector<Eigen::Vector2d> pp, tp, lp;
    for (auto& s : slots.park) pp.push_back(s.c);
    for (auto& s : slots.trees) tp.push_back(s.c);
    for (auto& l : slots.lots) lp.push_back(l.P(0.5 * l.width, 0));
    park_order_ = pick.Order(pp);
    tree_order_ = pick.Order(tp);
    lot_order_ = pick.Order(lp);
  }

  std::vector<LdObject> Place() {
    ParkedCars();
    for (int i = 0; i < cfg_.ld_trees_cut && tree_i_ < tree_order_.size(); ++i) {
      const Slot& s = slots_.trees[tree_order_[tree_i_++]];
      AddTree(Add("tree", Range(0, ChangeSession()), "open"), s.c, Gz(s.c), rng_);
    }
    Fences();
    Containers();
    Structures();
    WallReveals();
    Occluded();
    for (auto& o : out_) {
      const auto bb = o.mesh.Bounds();
      o.info.box_min = bb.min();
      o.info.box_max = bb.max();
      o.info.centroid = bb.center();
    }
    return std::move(out_);
  }

 private:
  // The next unused lot (route order) at least this wide and deep, or null.
  Lot* NextLot(double min_w, double min_depth) {
    for (; lot_i_ < lot_order_.size(); ++lot_i_) {
      Lot& l = slots_.lots[lot_order_[lot_i_]];
      if (!l.used && l.width >= min_w && l.depth >= min_depth) {
        l.used = true;
        ++lot_i_;
        return &l;
      }
    }
    return nullptr;
  }
  int ChangeSession() { return 1 + rng_.Int(N_ - 1); }  // in [1, N-1]
  Mesh& Add(const std::string& cls, std::vector<int> present, const std::string& placement) {
    LdObject o;
    o.info.id = int(out_.size());
    o.info.cls = cls;
    o.info.present_in = std::move(present);
    o.info.placement = placement;
    out_.push_back(std::move(o));
    return out_.back().mesh;
  }
  double Gz(const Eigen::Vector2d& p) const { return grid_.GroundZ(terrain_, p.x(), p.y()); }

  // Parked cars come and go at random, except that the first car whose slot lies near both the
  // central and the last route is new in the last session (a parked car the live map must show
  // and the meta map must not) and the next such car left after session 0.
  void ParkedCars() {
    std::vector<int> forced_new = {N_ - 1}, forced_gone = {0};
    std::vector<std::vector<int>*> forced = {&forced_new, &forced_gone};
    std::size_t forced_i = 0;
    for (int i = 0; i < cfg_.ld_parked_cars && park_i_ < park_order_.size(); ++i) {
      const Slot& s = slots_.park[park_order_[park_i_++]];
      std::vector<int> present;
      do {
        present.clear();
        for (int k = 0; k < N_; ++k)
          if (rng_.Bernoulli(0.5)) present.push_back(k);
      } while (present.empty() || int(present.size()) == N_);
      if (N_ >= 2 && forced_i < forced.size() && routes_[0].Distance(s.c) <= cfg_.ld_route_distance_m &&
          routes_[std::size_t(N_ - 1)].Distance(s.c) <= cfg_.ld_route_distance_m)
        present = *forced[forced_i++];
      AddCar(Add("car", present, "open"), s.c, terrain_.Height(s.c.x(), s.c.y()), s.yaw, rng_.Uniform(4.0, 4.8),
             rng_.Uniform(1.7, 1.9), kPaint);
    }
  }

  void Fences() {
    for (int i = 0; i < cfg_.ld_fences; ++i) {
      Lot* l = NextLot(8.0, 3.0);
      if (!l) break;
      const int m = ChangeSession();
      Mesh& mesh = Add("fence", i % 2 == 0 ? Range(m, N_) : Range(0, m), "open");
      AddPanels(mesh, grid_, terrain_, l->P(1.0, 0.4), l->P(l->width - 1.0, 0.4), 3.4, 0.1, 2.0, 0.05, kMetal);
    }
  }

  // A container moved from one lot to another at a change session.
  void Containers() {
    for (int i = 0; i < cfg_.ld_containers; ++i) {
      Lot* a = NextLot(8.0, 6.0);
      Lot* b = a ? NextLot(8.0, 6.0) : nullptr;
      if (!b) break;
      const int m = ChangeSession();
      const int first = int(out_.size());
      for (auto [lot, present] : {std::make_pair(a, Range(0, m)), std::make_pair(b, Range(m, N_))}) {
        const Eigen::Vector2d c = lot->P(0.5 * lot->width, 4.0);
        Add("container", present, "open").AddBox(c, Gz(c) - 0.05, {6.06, 2.44, 2.64}, lot->yaw(), kMetal);
      }
      // The two places are one container: each names the other (truth objects.csv's partner).
      out_[std::size_t(first)].info.partner = first + 1;
      out_[std::size_t(first) + 1].info.partner = first;
    }
  }

  // Kiosks appearing in open yards.
  void Structures() {
    for (int i = 0; i < cfg_.ld_structures; ++i) {
      Lot* l = NextLot(6.0, 7.0);
      if (!l) break;
      const Eigen::Vector2d c = l->P(0.5 * l->width, 5.0);
      Mesh& mesh = Add("structure", Range(ChangeSession(), N_), "open");
      mesh.AddBox(c, Gz(c) - 0.05, {3.0, 3.0, 2.85}, l->yaw(), kPaint);
      mesh.AddBox(c, Gz(c) + 2.8, {3.6, 3.6, 0.2}, l->yaw(), kMetal, true);
    }
  }

  // The central session sees a wall; later sessions see the wall gone and a shed behind it, in
  // space the central could not observe (strong PD). The walls close the lot on all four sides
  // (front on the building line): no ray of the central session reaches inside.
  void WallReveals() {
    for (int i = 0; i < cfg_.ld_wall_reveals; ++i) {
      Lot* l = NextLot(12.0, 12.0);
      if (!l) break;
      Mesh& wall = Add("wall", {0}, "open");
      const double wd = 11.0, wh = 3.4;
      const Eigen::Vector2d front = l->P(0.5 * l->width, 0.35), back = l->P(0.5 * l->width, wd);
      wall.AddBox(front, Gz(front) - 0.2, {l->width - 0.6, 0.3, wh}, l->yaw(), kConcrete);
      wall.AddBox(back, Gz(back) - 0.2, {l->width - 0.6, 0.3, wh}, l->yaw(), kConcrete);
      for (double u : {0.45, l->width - 0.45}) {
        const Eigen::Vector2d c = l->P(u, 0.5 * (0.35 + wd));
        wall.AddBox(c, Gz(c) - 0.2, {0.3, wd - 0.35, wh}, l->yaw(), kConcrete);
      }
      const Eigen::Vector2d sc = l->P(0.5 * l->width, 7.0);
      Add("structure", Range(1, N_), "revealed")
          .AddBox(sc, Gz(sc) - 0.05, {std::min(8.0, l->width - 3.0), 5.0, 3.35}, l->yaw(), kFacade);
    }
  }

  // A hoarding goes up around a lot (all four sides, as around a building site) while the object
  // inside disappears: the later sessions cannot see through it, so the absence is weak ND.
  void Occluded() {
    for (int i = 0; i < cfg_.ld_occluded; ++i) {
      Lot* l = NextLot(14.0, 8.0);
      if (!l) break;
      const int m = ChangeSession();
      Mesh& h = Add("hoarding", Range(m, N_), "open");
      const double hd = std::min(l->depth - 0.5, 8.0);
      const Eigen::Vector2d q0 = l->P(0.3, 0.3), q1 = l->P(l->width - 0.3, 0.3), q2 = l->P(l->width - 0.3, hd),
                            q3 = l->P(0.3, hd);
      for (auto [a, b] : {std::make_pair(q0, q1), std::make_pair(q1, q2), std::make_pair(q2, q3), std::make_pair(q3, q0)})
        AddPanels(h, grid_, terrain_, a, b, 4.0, 0.0, 3.0, 0.08, kPaint);
      const Eigen::Vector2d c = l->P(0.5 * l->width, 4.0);
      if (i % 2 == 0)
        Add("container", Range(0, m), "occluded").AddBox(c, Gz(c) - 0.05, {6.06, 2.44, 2.4}, l->yaw(), kMetal);
      else
        AddCar(Add("car", Range(0, m), "occluded"), c, Gz(c), l->yaw(), 4.5, 1.8, kPaint);
    }
  }

  const SimConfig& cfg_;
  const Grid& grid_;
  const Terrain& terrain_;
  Slots& slots_;
  const std::vector<Path>& routes_;
  Rng& rng_;
  const int N_;
  std::vector<std::size_t> park_order_, tree_order_, lot_order_;
  std::size_t park_i_ = 0, tree_i_ = 0, lot_i_ = 0;
  std::vector<LdObject> out_;
};

std::vector<LdObject> PlaceLd(const SimConfig& cfg, const Grid& grid, const Terrain& terrain,
                              Slots& slots, const std::vector<Path>& routes, Rng& rng) {
  if (cfg.sessions < 2) return {};
  return LdPlacer(cfg, grid, terrain, slots, routes, rng).Place();
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
