// Sensor model: presets with real beam tables, explicit tables, estimation from scans.
#include "ltmapper/geometry/sensor.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <numeric>

namespace ltm::geometry {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToDeg = 180.0 / kPi;

// The direction [deg] of a finite return at least min_range_m away (the estimates skip nearer ones:
// the vehicle, and lasers whose vertical offsets bend their elevation at short range).
struct Direction {
  double elevation_deg, azimuth_deg;  // azimuth in [-180, 180] from +x
};
bool FarDirection(const PointXYZI& p, double min_range_m, Direction* d) {
  const double rxy = std::hypot(double(p.x), double(p.y));
  if (!std::isfinite(rxy) || !std::isfinite(p.z) || std::hypot(rxy, double(p.z)) < min_range_m) return false;
  d->elevation_deg = std::atan2(double(p.z), rxy) * kRadToDeg;
  d->azimuth_deg = std::atan2(double(p.y), double(p.x)) * kRadToDeg;
  return true;
}

// The 1 deg azimuth cell (0 .. 359) of an azimuth in [-180, 180] (GridFromDensity, EstimateAzimuthView).
constexpr int kAzimuthCells = 360;
int AzimuthCell(double azimuth_deg) { return std::clamp(int(azimuth_deg + 180.0), 0, kAzimuthCells - 1); }

std::vector<double> Uniform(int beams, double up_deg, double down_deg) {
  std::vector<double> e(static_cast<std::size_t>(beams));
  for (int b = 0; b < beams; ++b) e[std::size_t(b)] = up_deg - b * (up_deg - down_deg) / (beams - 1);
  return e;
}

// HDL-64E: two blocks of 32 lasers, the upper one +2 .. -8.33 deg (1/3 deg apart), the lower one
// -8.83 .. -24.83 deg (~1/2 deg apart), as in Velodyne's nominal table.
std::vector<double> Hdl64e() {
  std::vector<double> e = Uniform(32, 2.0, -8.333);
  const std::vector<double> lower = Uniform(32, -8.833, -24.833);
  e.insert(e.end(), lower.begin(), lower.end());
  return e;
}

struct Preset {
  std::vector<double> elevations_deg;
  double azimuth_step_deg;
};

// Beam tables from the manufacturers' manuals (elevations in degrees; any order).
const std::map<std::string, std::function<Preset()>>& Presets() {
  static const std::map<std::string, std::function<Preset()>> presets = {
      {"vlp16", [] { return Preset{Uniform(16, 15.0, -15.0), 0.2}; }},
      {"hdl32e", [] { return Preset{Uniform(32, 10.67, -30.67), 360.0 / 2048}; }},
      {"vlp32c",
       [] {
         return Preset{{15.0, 10.333, 7.0, 4.667, 3.333, 2.333, 1.667, 1.333, 1.0, 0.667, 0.333,
                        0.0, -0.333, -0.667, -1.0, -1.333, -1.667, -2.0, -2.333, -2.667, -3.0,
                        -3.333, -3.667, -4.0, -4.667, -5.333, -6.148, -7.254, -8.843, -11.31,
                        -15.639, -25.0},
                       0.2};
       }},
      {"hdl64e", [] { return Preset{Hdl64e(), 360.0 / 2048}; }},
      {"os1-64", [] { return Preset{Uniform(64, 22.5, -22.5), 360.0 / 1024}; }},
      {"os1-128", [] { return Preset{Uniform(128, 22.5, -22.5), 360.0 / 1024}; }},
      {"pandar64",
       [] {
         return Preset{{14.882, 11.032, 8.059, 5.057, 3.04, 2.028, 1.86, 1.688, 1.522, 1.351,
                        1.184, 1.013, 0.846, 0.675, 0.508, 0.337, 0.169, 0.0, -0.169, -0.337,
                        -0.508, -0.675, -0.845, -1.013, -1.184, -1.351, -1.522, -1.688, -1.86,
                        -2.028, -2.198, -2.365, -2.536, -2.7, -2.873, -3.04, -3.21, -3.375,
                        -3.548, -3.712, -3.884, -4.05, -4.221, -4.385, -4.558, -4.72, -4.892,
                        -5.057, -5.229, -5.391, -5.565, -5.726, -5.898, -6.061, -7.063, -8.059,
                        -9.06, -9.885, -11.032, -12.006, -12.974, -13.93, -18.862, -24.99},
                       0.2};
       }},
      {"sim64", [] { return Preset{Uniform(64, 15.0, -25.0), 360.0 / 1024}; }},
  };
  return presets;
}

std::string Fmt(const char* f, double a) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, a);
  return buf;
}

// Elevation histogram over the scans: per bin the count, sum and sum of squares of the point
// elevations [deg] (points nearer than min_range skipped).
struct ElevationHistogram {
  double bin_deg = 0.02;
  std::vector<double> n, sum, sum2;
  std::size_t points = 0;
  int Bins() const { return int(n.size()); }
  double Lo(int b) const { return -90.0 + b * bin_deg; }
};

ElevationHistogram Histogram(const std::vector<PointCloud>& scans, const SensorEstimateOptions& opt) {
  ElevationHistogram h;
  h.bin_deg = opt.bin_deg;
  const int bins = int(std::ceil(180.0 / opt.bin_deg)) + 1;
  h.n.assign(std::size_t(bins), 0.0);
  h.sum = h.n;
  h.sum2 = h.n;
  Direction d{};
  for (const PointCloud& scan : scans)
    for (const PointXYZI& p : scan.points) {
      if (!FarDirection(p, opt.min_range_m, &d)) continue;
      const double el = d.elevation_deg;
      const int b = std::clamp(int((el + 90.0) / opt.bin_deg), 0, bins - 1);
      h.n[std::size_t(b)] += 1.0;
      h.sum[std::size_t(b)] += el;
      h.sum2[std::size_t(b)] += el * el;
      ++h.points;
    }
  return h;
}

// Clusters of non-empty bins (runs joined across single empty bins). Per cluster: count, mean,
// second moment, width in bins.
struct Cluster {
  double n = 0, sum = 0, sum2 = 0;
  int width = 0;
  double Mean() const { return sum / n; }
};
std::vector<Cluster> Clusters(const ElevationHistogram& h) {
  std::vector<Cluster> out;
  int last = -10;
  for (int b = 0; b < h.Bins(); ++b) {
    if (h.n[std::size_t(b)] <= 0) continue;
    if (b - last > 2) out.emplace_back();
    Cluster& c = out.back();
    c.n += h.n[std::size_t(b)];
    c.sum += h.sum[std::size_t(b)];
    c.sum2 += h.sum2[std::size_t(b)];
    c.width += b - last > 2 ? 1 : b - last;
    last = b;
  }
  // Stray points (a few between beams) form tiny clusters: drop those far below the typical beam,
  // the cluster that holds the median point (strays may outnumber the beams, never their points).
  if (out.empty()) return out;
  double total = 0.0;
  for (const Cluster& c : out) total += c.n;
  std::vector<double> counts;
  for (const Cluster& c : out) counts.push_back(c.n);
  std::sort(counts.begin(), counts.end());
  double below = 0.0;
  std::size_t typical = 0;
  while (typical + 1 < counts.size() && below + counts[typical] < 0.5 * total) below += counts[typical++];
  constexpr double kStrayShare = 0.01;  // [-] of the typical beam's count
  const double floor = kStrayShare * counts[typical];
  out.erase(std::remove_if(out.begin(), out.end(), [&](const Cluster& c) { return c.n < floor; }), out.end());
  return out;
}

// Median horizontal step between consecutive points of one beam, over the beams of one scan.
double AzimuthStep(const PointCloud& scan, const std::vector<double>& elevations_deg, double min_range_m) {
  std::vector<std::vector<double>> az(elevations_deg.size());
  Direction d{};
  for (const PointXYZI& p : scan.points) {
    if (!FarDirection(p, min_range_m, &d)) continue;
    std::size_t best = 0;
    for (std::size_t b = 1; b < elevations_deg.size(); ++b)
      if (std::fabs(elevations_deg[b] - d.elevation_deg) < std::fabs(elevations_deg[best] - d.elevation_deg)) best = b;
    az[best].push_back(d.azimuth_deg);
  }
  std::vector<double> steps;
  for (auto& a : az) {
    std::sort(a.begin(), a.end());
    for (std::size_t i = 1; i < a.size(); ++i)
      if (a[i] - a[i - 1] > 1e-4) steps.push_back(a[i] - a[i - 1]);
  }
  if (steps.empty()) return 0.0;
  return UpperMedian(steps);
}

// The horizontal field of view: the arc of azimuths with returns, the complement of the widest run
// of 1 deg cells (GridFromDensity's) none of the scans' points fell in; all around when every cell
// holds some. A forward cone (a rosette scanner) is its cone; a ring sensor whose rear the vehicle
// hides keeps the rest.
void EstimateAzimuthView(const std::vector<PointCloud>& scans, double min_range_m, SensorModel* m) {
  constexpr int kCells = kAzimuthCells;
  std::vector<char> cell(kCells, 0);
  Direction d{};
  for (const PointCloud& scan : scans)
    for (const PointXYZI& p : scan.points)
      if (FarDirection(p, min_range_m, &d)) cell[std::size_t(AzimuthCell(d.azimuth_deg))] = 1;
  int best_len = 0, best_end = 0;  // the widest empty run (circular), ending before cell best_end
  for (int start = 0, len = 0; start < 2 * kCells; ++start) {
    len = cell[std::size_t(start % kCells)] ? 0 : len + 1;
    if (len > best_len && len <= kCells) best_len = len, best_end = start + 1;
  }
  if (best_len == 0) return;  // all around (the default)
  if (best_len >= kCells) return;  // no returns: nothing to tell
  const double arc = double(kCells - best_len);  // [deg] cells with returns, from best_end on
  m->azimuth_half_fov_deg = 0.5 * arc;
  double center = double(best_end) + 0.5 * arc - 180.0;
  while (center > 180.0) center -= 360.0;
  m->azimuth_center_deg = center;
}

// Non-repetitive scanners: the angular grid that spreads a scan's points evenly over the solid
// angle they cover (1 x 1 deg cells with points).
double GridFromDensity(const std::vector<PointCloud>& scans, double min_range_m) {
  std::vector<char> cell(180 * kAzimuthCells, 0);
  std::size_t points = 0;
  Direction d{};
  for (const PointCloud& scan : scans)
    for (const PointXYZI& p : scan.points) {
      if (!FarDirection(p, min_range_m, &d)) continue;
      const int r = std::clamp(int(d.elevation_deg + 90.0), 0, 179);
      cell[std::size_t(r) * kAzimuthCells + std::size_t(AzimuthCell(d.azimuth_deg))] = 1;
      ++points;
    }
  const double area = double(std::count(cell.begin(), cell.end(), 1));  // [deg^2]
  return std::sqrt(area * double(scans.size()) / double(std::max<std::size_t>(points, 1)));
}

// Rings from the order of the points: drivers and savers (KITTI's .bin, most ring LiDAR drivers)
// store a scan ring after ring, each ring one full turn. The azimuth, unwrapped along the point
// order, counts the turns: turn k is ring k. A ring's elevation is the mean apparent elevation
// of its returns: the range images are built from apparent angles, and a laser's vertical offset
// from the sensor origin (which bends the apparent elevation of near returns by offset / range)
// is shared by its neighbours, so the spacing between rings holds. Empty when the order shows
// no turns (column-major scans, shuffled points).
struct RingFit {
  std::vector<double> elevations_deg;
  double spread_deg = 0.0;  // robust sigma (1.4826 x median absolute deviation) of the elevations
                            // about their ring's mean: near returns, few and bent most by the
                            // lasers' offsets (or a deskewed sweep's moving origin), do not set it
};
RingFit RingsFromOrder(const PointCloud& scan, double min_range_m) {
  struct Acc {
    double n = 0, y = 0;  // y = elevation [deg]
    std::vector<float> ys;
  };
  std::vector<Acc> rings;
  double unwrapped = 0.0, prev = 0.0;
  bool first = true;
  Direction d{};
  for (const PointXYZI& p : scan.points) {
    if (!FarDirection(p, min_range_m, &d)) continue;
    const double az = d.azimuth_deg;
    if (!first) unwrapped += std::remainder(az - prev, 360.0);
    first = false;
    prev = az;
    const auto turn = std::size_t(std::max(0.0, std::floor(std::fabs(unwrapped) / 360.0)));
    if (turn >= rings.size()) rings.resize(turn + 1);
    Acc& a = rings[turn];
    const double y = d.elevation_deg;
    a.n += 1, a.y += y;
    a.ys.push_back(float(y));
  }
  RingFit fit;
  constexpr std::size_t kMinRings = 4;       // fewer turns: not a ring-ordered scan
  constexpr double kMinRingShare = 0.1;      // [-] of the largest ring: smaller ones are seams
  if (rings.size() < kMinRings) return fit;
  double largest = 0.0;
  for (const Acc& a : rings) largest = std::max(largest, a.n);
  std::vector<double> dev;
  for (const Acc& a : rings) {
    if (a.n < kMinRingShare * largest) continue;
    const double mean = a.y / a.n;
    fit.elevations_deg.push_back(mean);
    for (float y : a.ys) dev.push_back(std::fabs(y - float(mean)));
  }
  constexpr double kMadToSigma = 1.4826;  // sigma of a normal distribution per median absolute deviation
  if (!dev.empty()) fit.spread_deg = kMadToSigma * UpperMedian(dev);
  return fit;
}

void Finish(SensorModel& m) {
  std::sort(m.elevations_deg.begin(), m.elevations_deg.end(), std::greater<double>());
  if (!m.elevations_deg.empty()) {
    m.fov_up_deg = m.elevations_deg.front();
    m.fov_down_deg = m.elevations_deg.back();
  }
}

}  // namespace

double SensorModel::SpacingAt(double elevation_deg) const {
  if (!ring_based || elevations_deg.size() < 2) return grid_deg;
  const auto& e = elevations_deg;  // decreasing
  std::size_t i = 1;
  while (i + 1 < e.size() && e[i] > elevation_deg) ++i;
  return e[i - 1] - e[i];
}

double SensorModel::MaxSpacing() const {
  if (!ring_based || elevations_deg.size() < 2) return grid_deg;
  double m = 0.0;
  for (std::size_t i = 1; i < elevations_deg.size(); ++i) m = std::max(m, elevations_deg[i - 1] - elevations_deg[i]);
  return m;
}

double SensorModel::MedianSpacing() const {
  if (!ring_based || elevations_deg.size() < 2) return grid_deg;
  std::vector<double> gaps;
  for (std::size_t i = 1; i < elevations_deg.size(); ++i) gaps.push_back(elevations_deg[i - 1] - elevations_deg[i]);
  return UpperMedian(gaps);
}

std::string SensorModel::Describe() const {
  std::string s = source + ": ";
  const std::string view = azimuth_half_fov_deg < 180.0 ? ", azimuth " + Fmt("%+.0f", azimuth_center_deg) + " +- " +
                                                             Fmt("%.0f", azimuth_half_fov_deg) + " deg"
                                                       : std::string();
  if (!ring_based) {
    return s + "non-repetitive (no rings), " + Fmt("%+.2f", fov_up_deg) + " .. " + Fmt("%+.2f", fov_down_deg) +
           " deg, point grid " + Fmt("%.3f", grid_deg) + " deg" + view;
  }
  s += std::to_string(beams()) + " beams " + Fmt("%+.3f", fov_up_deg) + " .. " + Fmt("%+.3f", fov_down_deg) +
       " deg, beam spacing median " + Fmt("%.3f", MedianSpacing()) + " / max " + Fmt("%.3f", MaxSpacing()) + " deg";
  if (azimuth_step_deg > 0) s += ", azimuth step " + Fmt("%.3f", azimuth_step_deg) + " deg";
  if (source == "estimated") s += ", spread " + Fmt("%.3f", spread_deg) + " deg";
  return s + view;
}

std::vector<std::string> SensorPresetNames() {
  std::vector<std::string> names;
  for (const auto& [name, make] : Presets()) names.push_back(name);
  return names;
}

SensorModel SensorPreset(const std::string& name) {
  const auto it = Presets().find(name);
  if (it == Presets().end()) {
    std::string known;
    for (const auto& n : SensorPresetNames()) known += (known.empty() ? "" : ", ") + n;
    throw Error("unknown sensor preset '" + name + "' (known: " + known + ", auto, table)");
  }
  const Preset p = it->second();
  SensorModel m = SensorFromTable(p.elevations_deg, p.azimuth_step_deg, "sensor preset " + name);
  m.source = name;
  return m;
}

SensorModel SensorFromTable(const std::vector<double>& elevations_deg, double azimuth_step_deg,
                            const std::string& key) {
  if (elevations_deg.size() < 2) throw Error(key + ": a beam table needs at least 2 elevations");
  SensorModel m;
  m.source = "table";
  m.elevations_deg = elevations_deg;
  m.azimuth_step_deg = azimuth_step_deg;
  for (double e : elevations_deg)
    if (!std::isfinite(e) || std::fabs(e) >= 90.0) throw Error(key + ": elevation " + Fmt("%g", e) + " deg outside (-90, 90)");
  Finish(m);
  for (std::size_t i = 1; i < m.elevations_deg.size(); ++i)
    if (m.elevations_deg[i - 1] - m.elevations_deg[i] < 1e-6)
      throw Error(key + ": elevation " + Fmt("%g", m.elevations_deg[i]) + " deg appears twice");
  return m;
}

namespace {
// EstimateSensor's vertical sampling: the beams of a ring sensor, or a non-repetitive grid.
SensorModel EstimateBeams(const std::vector<PointCloud>& scans, const SensorEstimateOptions& opt) {
  const ElevationHistogram h = Histogram(scans, opt);
  constexpr std::size_t kMinPoints = 1000;  // fewer points cannot show the beams
  if (h.points < kMinPoints)
    throw Error("sensor estimate: " + std::to_string(h.points) + " points beyond " + Fmt("%g", opt.min_range_m) +
                " m in " + std::to_string(scans.size()) + " scans; need at least " + std::to_string(kMinPoints) +
                " (set `sensor` to a preset or a table)");
  const std::vector<Cluster> cl = Clusters(h);
  int filled = 0;
  for (const Cluster& c : cl) filled += c.width;
  const double span_bins = cl.size() < 2 ? 1.0 : (cl.back().Mean() - cl.front().Mean()) / h.bin_deg + 1.0;
  SensorModel m;
  m.source = "estimated";
  if (cl.size() >= 2 && filled <= opt.ring_fill_max * span_bins) {
    double sq = 0, n = 0;
    for (const Cluster& c : cl) {
      m.elevations_deg.push_back(c.Mean());
      sq += c.sum2 - c.sum * c.sum / c.n;
      n += c.n;
    }
    m.spread_deg = std::sqrt(std::max(0.0, sq / n));
    Finish(m);
    m.azimuth_step_deg = AzimuthStep(scans.front(), m.elevations_deg, opt.min_range_m);
    return m;
  }
  // Peaks blurred together (lasers offset inside the housing): the rings of the point order.
  const RingFit rf = RingsFromOrder(scans.front(), opt.min_range_m);
  if (!rf.elevations_deg.empty()) {
    m.elevations_deg = rf.elevations_deg;
    m.spread_deg = rf.spread_deg;
    Finish(m);
    m.azimuth_step_deg = AzimuthStep(scans.front(), m.elevations_deg, opt.min_range_m);
    return m;
  }
  m.ring_based = false;
  m.grid_deg = GridFromDensity(scans, opt.min_range_m);
  int lo = h.Bins(), hi = -1;
  for (int b = 0; b < h.Bins(); ++b)
    if (h.n[std::size_t(b)] > 0) lo = std::min(lo, b), hi = b;
  m.fov_down_deg = h.Lo(lo);
  m.fov_up_deg = h.Lo(hi) + h.bin_deg;
  return m;
}

}  // namespace

SensorModel EstimateSensor(const std::vector<PointCloud>& scans, const SensorEstimateOptions& opt) {
  SensorModel m = EstimateBeams(scans, opt);
  EstimateAzimuthView(scans, opt.min_range_m, &m);
  return m;
}

bool InAzimuthArc(double azimuth_deg, double center_deg, double half_deg) {
  return half_deg >= 180.0 || std::fabs(std::remainder(azimuth_deg - center_deg, 360.0)) <= half_deg;
}

bool SensorModel::InAzimuthView(double azimuth_deg) const {
  return InAzimuthArc(azimuth_deg, azimuth_center_deg, azimuth_half_fov_deg);
}

SensorModel ResolveSensor(const std::string& sensor, const std::vector<double>& elevations_deg,
                          const std::vector<PointCloud>& scans, const std::string& key) {
  if (sensor == "table") return SensorFromTable(elevations_deg, 0.0, key + ".elevations_deg");
  if (!elevations_deg.empty())
    throw Error(key + ".elevations_deg is given but " + key + ".model is '" + sensor + "' (set " + key +
                ".model: table)");
  if (sensor != "auto") {
    try {
      return SensorPreset(sensor);
    } catch (const Error& e) {
      throw Error(key + ".model: " + e.what());
    }
  }
  if (scans.empty()) throw Error(key + ".model: auto needs scans to estimate the sensor from");
  return EstimateSensor(scans);
}

}  // namespace ltm::geometry
