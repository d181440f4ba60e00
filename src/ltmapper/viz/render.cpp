// Top-down renderer: bounds pass, one splat pass per cloud with a per-pixel priority buffer,
// trajectories, scale bar, legend.
#include "draw.hpp"
#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <tuple>

namespace ltm::viz {

namespace {

constexpr Rgb kWhite{255, 255, 255};
constexpr Rgb kBlack{0, 0, 0};
constexpr Rgb kFrame{150, 150, 150};
constexpr int kNumClasses = 7;
constexpr double kEmptyExtentM = 10.0;  // [m] map side when there is nothing to draw
constexpr int kAutoTextPxPerScale = 700;  // auto font: +1 font scale per this many map pixels
constexpr int kHeightBins = 1024;       // histogram bins for the automatic height range
constexpr double kHeightLoQuantile = 0.01, kHeightHiQuantile = 0.99;

// Draw priority per class: dense static first, changes on top (strong above weak).
constexpr std::array<int, kNumClasses> kClassPriority = {
    /*unknown*/ 0, /*static*/ 1, /*HD*/ 2, /*PD strong*/ 6, /*PD weak*/ 4, /*ND strong*/ 5,
    /*ND weak*/ 3};
// Legend order.
constexpr std::array<PointClass, kNumClasses> kLegendOrder = {
    PointClass::kStatic,   PointClass::kHD,       PointClass::kPDStrong, PointClass::kPDWeak,
    PointClass::kNDStrong, PointClass::kNDWeak,   PointClass::kUnknown};

inline bool Finite(const PointXYZI& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

inline int ClassIndex(PointClass c) {
  const int k = static_cast<int>(c);
  return (k >= 0 && k < kNumClasses) ? k : 0;
}

std::string Upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::string ClassLabel(PointClass c) {
  switch (c) {
    case PointClass::kStatic: return "STATIC";
    case PointClass::kHD: return "HD";
    case PointClass::kPDStrong: return "PD STRONG";
    case PointClass::kPDWeak: return "PD WEAK";
    case PointClass::kNDStrong: return "ND STRONG";
    case PointClass::kNDWeak: return "ND WEAK";
    case PointClass::kUnknown: break;
  }
  return "UNKNOWN";
}

// Short decimal: 20, 0.5, 12.35.
std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.2f", v);
  std::string s = buf;
  while (!s.empty() && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  if (s == "-0") s = "0";
  return s;
}

// Largest 1/2/5 x 10^k not above `target`.
double NiceLength(double target) {
  if (!(target > 0)) return 0;
  const double p = std::pow(10.0, std::floor(std::log10(target)));
  for (double m : {5.0, 2.0, 1.0})
    if (m * p <= target) return m * p;
  return p;
}

struct Scan {
  double x_min = std::numeric_limits<double>::infinity(), x_max = -x_min;
  double y_min = x_min, y_max = -x_min;
  double z_min = x_min, z_max = -x_min;
  std::size_t finite = 0;
  std::array<std::size_t, kNumClasses> class_count{};
  std::set<int> sessions;
  void Add(double x, double y) {
    x_min = std::min(x_min, x);
    x_max = std::max(x_max, x);
    y_min = std::min(y_min, y);
    y_max = std::max(y_max, y);
  }
};

int LayerSession(const Layer& l, std::size_t i) {
  return l.default_session >= 0 ? l.default_session : int(i);
}

struct LegendEntry {
  Rgb color;
  std::string label;
  bool line = false;  // trajectory: line swatch
};

}  // namespace

// ------------------------------------------------------------------------------------ colours
Rgb ClassColor(PointClass c) {
  switch (c) {
    case PointClass::kStatic: return {165, 165, 165};
    case PointClass::kHD: return {220, 30, 30};
    case PointClass::kPDStrong: return {20, 60, 220};
    case PointClass::kPDWeak: return {120, 175, 255};
    case PointClass::kNDStrong: return {245, 130, 0};
    case PointClass::kNDWeak: return {255, 200, 130};
    case PointClass::kUnknown: break;
  }
  return {70, 70, 70};
}

Rgb SessionColor(int session) {
  static constexpr std::array<Rgb, 10> kPalette = {{{31, 119, 180},
                                                    {255, 127, 14},
                                                    {44, 160, 44},
                                                    {214, 39, 40},
                                                    {148, 103, 189},
                                                    {140, 86, 75},
                                                    {227, 119, 194},
                                                    {110, 110, 110},
                                                    {188, 189, 34},
                                                    {23, 190, 207}}};
  const int n = int(kPalette.size());
  return kPalette[std::size_t(((session % n) + n) % n)];
}

Rgb TrajectoryColor(int index) {
  static constexpr std::array<Rgb, 6> kPalette = {
      {{0, 0, 0}, {130, 0, 170}, {0, 120, 50}, {0, 95, 120}, {150, 75, 0}, {190, 0, 120}}};
  const int n = int(kPalette.size());
  return kPalette[std::size_t(((index % n) + n) % n)];
}

namespace {
constexpr int kHeightLut = 1024;  // colormap entries; HeightColor quantises t to them

Rgb HeightRamp(double t) {
  // Piecewise-linear ramp: dark blue, blue, cyan-green, yellow-green, orange, dark red.
  static constexpr std::array<std::array<double, 3>, 6> kStops = {
      {{40, 30, 140}, {40, 120, 230}, {30, 200, 160}, {170, 220, 50}, {250, 170, 30}, {180, 20, 10}}};
  const double s = t * (kStops.size() - 1);
  const std::size_t i = std::min<std::size_t>(std::size_t(s), kStops.size() - 2);
  const double f = s - double(i);
  auto mix = [&](int c) {
    return std::uint8_t(std::lround(kStops[i][std::size_t(c)] * (1 - f) + kStops[i + 1][std::size_t(c)] * f));
  };
  return {mix(0), mix(1), mix(2)};
}

const std::array<Rgb, kHeightLut>& HeightLut() {
  static const std::array<Rgb, kHeightLut> lut = [] {
    std::array<Rgb, kHeightLut> l;
    for (int k = 0; k < kHeightLut; ++k) l[std::size_t(k)] = HeightRamp(double(k) / (kHeightLut - 1));
    return l;
  }();
  return lut;
}

inline int HeightIndex(double t) {
  if (!(t > 0)) return 0;  // also NaN
  if (t >= 1) return kHeightLut - 1;
  return int(t * (kHeightLut - 1) + 0.5);
}
}  // namespace

Rgb HeightColor(double t) { return HeightLut()[std::size_t(HeightIndex(t))]; }

PointClass ClassFromFileName(const std::string& path) {
  const std::string stem = std::filesystem::path(path).stem().string();
  auto has = [&](const char* s) { return stem.find(s) != std::string::npos; };
  if (has("pd_strong")) return PointClass::kPDStrong;
  if (has("pd_weak")) return PointClass::kPDWeak;
  if (has("nd_strong")) return PointClass::kNDStrong;
  if (has("nd_weak")) return PointClass::kNDWeak;
  if (has("hd")) return PointClass::kHD;
  if (has("static")) return PointClass::kStatic;
  return PointClass::kUnknown;
}

bool RenderResult::WorldToPixel(double x, double y, int* px, int* py) const {
  if (!(meters_per_pixel > 0)) return false;
  const double fx = std::floor((x - x_min) / meters_per_pixel);
  const double fy = std::floor((y_max - y) / meters_per_pixel);
  if (!(fx >= 0 && fy >= 0 && fx < map.w && fy < map.h)) return false;
  *px = map.x0 + int(fx);
  *py = map.y0 + int(fy);
  return true;
}

// ------------------------------------------------------------------------------------ render
namespace {
enum class Mode { kClass, kSession, kHeight };

void CheckLayers(const std::vector<Layer>& layers) {
  for (std::size_t i = 0; i < layers.size(); ++i) {
    if (!layers[i].cloud) throw Error("Render: layer " + std::to_string(i) + " has no cloud");
    layers[i].cloud->CheckConsistent("Render layer " + std::to_string(i));
  }
}

// Pass 1: bounds, classes and sessions present (an empty scene gets a default extent).
Scan ScanLayers(const std::vector<Layer>& layers, const std::vector<Trajectory>& trajectories) {
  Scan scan;
  for (std::size_t li = 0; li < layers.size(); ++li) {
    const PointCloud& c = *layers[li].cloud;
    const bool has_cls = !c.cls.empty(), has_ses = !c.session.empty();
    std::array<std::size_t, kNumClasses> cc{};
    std::vector<bool> ses_seen(has_ses ? 65536 : 0, false);
    std::size_t finite = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      const PointXYZI& p = c.points[i];
      if (!Finite(p)) continue;
      ++finite;
      scan.Add(p.x, p.y);
      scan.z_min = std::min(scan.z_min, double(p.z));
      scan.z_max = std::max(scan.z_max, double(p.z));
      if (has_cls) ++cc[std::size_t(ClassIndex(c.cls[i]))];
      if (has_ses) ses_seen[c.session[i]] = true;
    }
    scan.finite += finite;
    if (!has_cls) cc[std::size_t(ClassIndex(layers[li].default_class))] += finite;
    for (int k = 0; k < kNumClasses; ++k) scan.class_count[std::size_t(k)] += cc[std::size_t(k)];
    if (has_ses) {
      for (std::size_t s = 0; s < ses_seen.size(); ++s)
        if (ses_seen[s]) scan.sessions.insert(int(s));
    } else if (finite > 0) {
      scan.sessions.insert(LayerSession(layers[li], li));
    }
  }
  for (const Trajectory& t : trajectories)
    for (const auto& p : t.positions)
      if (p.allFinite()) scan.Add(p.x(), p.y());
  if (!(scan.x_min <= scan.x_max)) {
    scan.x_min = scan.y_min = -kEmptyExtentM / 2;
    scan.x_max = scan.y_max = kEmptyExtentM / 2;
  }
  return scan;
}

// The height colour range: the configured one, else the kHeightLoQuantile..kHeightHiQuantile
// quantiles of the points' heights (a histogram of kHeightBins).
std::pair<double, double> HeightRange(const std::vector<Layer>& layers, const Scan& scan, const RenderConfig& cfg,
                                      Mode mode) {
  double h_lo = cfg.height_min_m, h_hi = cfg.height_max_m;
  if (mode != Mode::kHeight || h_lo < h_hi) return {h_lo, h_hi};
  h_lo = scan.z_min;
  h_hi = scan.z_max;
  if (scan.finite > 0 && h_hi > h_lo) {
    std::vector<std::size_t> hist(kHeightBins, 0);
    const double inv = kHeightBins / (h_hi - h_lo);
    for (const Layer& l : layers)
      for (const PointXYZI& p : l.cloud->points)
        if (Finite(p)) ++hist[std::size_t(std::min(kHeightBins - 1, int((p.z - h_lo) * inv)))];
    auto quantile = [&](double q) {
      const double want = q * double(scan.finite);
      double acc = 0;
      for (int b = 0; b < kHeightBins; ++b) {
        acc += double(hist[std::size_t(b)]);
        if (acc >= want) return h_lo + (b + 0.5) / inv;
      }
      return h_hi;
    };
    const double lo = quantile(kHeightLoQuantile), hi = quantile(kHeightHiQuantile);
    if (hi > lo) h_lo = lo, h_hi = hi;
  }
  if (!(h_hi > h_lo)) h_hi = h_lo + 1.0;
  return {h_lo, h_hi};
}

// Legend title and rows: the classes or sessions present (a session layer's name when it has
// one), then one line swatch per trajectory.
std::string LegendEntries(const std::vector<Layer>& layers, const std::vector<Trajectory>& trajectories,
                          const Scan& scan, Mode mode, std::vector<LegendEntry>* entries) {
  std::string title = "HEIGHT";
  if (mode == Mode::kClass) {
    title = "CLASS";
    for (PointClass c : kLegendOrder)
      if (scan.class_count[std::size_t(ClassIndex(c))] > 0) entries->push_back({ClassColor(c), ClassLabel(c)});
  } else if (mode == Mode::kSession) {
    title = "SESSION";
    for (int ses : scan.sessions) {
      std::string label = "SESSION " + std::to_string(ses);
      for (std::size_t li = 0; li < layers.size(); ++li)
        if (layers[li].cloud->session.empty() && LayerSession(layers[li], li) == ses && !layers[li].name.empty())
          label = Upper(layers[li].name);
      entries->push_back({SessionColor(ses), label});
    }
  }
  for (std::size_t t = 0; t < trajectories.size(); ++t)
    entries->push_back({TrajectoryColor(int(t)),
                        trajectories[t].name.empty() ? "TRAJ " + std::to_string(t) : Upper(trajectories[t].name), true});
  return title;
}

// Everything the drawing steps share: colouring, map placement and scale, text metrics, legend.
struct Canvas {
  Mode mode = Mode::kClass;
  double mpp = 0, h_lo = 0, h_hi = 0;
  int map_w = 0, map_h = 0, m = 0;  // map size, margin
  int s = 1, text_h = 0, row_h = 0, pad = 0, swatch = 0, ramp_h = 0;
  std::string title;
  std::vector<LegendEntry> entries;
};

// Resolution and map size (cfg.meters_per_pixel, or fit cfg.max_size_px); the text scale, fixed
// or automatic (0) so the legend stays readable on big maps.
void PlaceMap(const Scan& scan, const RenderConfig& cfg, Canvas* c, RenderResult* res) {
  const double ext_x = scan.x_max - scan.x_min, ext_y = scan.y_max - scan.y_min;
  const double ext = std::max({ext_x, ext_y, 1e-6});
  double mpp = cfg.meters_per_pixel;
  if (!(mpp > 0) || ext / mpp > cfg.max_size_px - 1) mpp = ext / (cfg.max_size_px - 1);
  c->mpp = mpp;
  c->map_w = std::min(cfg.max_size_px, int(std::floor(ext_x / mpp)) + 1);
  c->map_h = std::min(cfg.max_size_px, int(std::floor(ext_y / mpp)) + 1);
  c->s = cfg.text_scale > 0 ? cfg.text_scale : std::clamp(std::max(c->map_w, c->map_h) / kAutoTextPxPerScale, 2, 6);
  res->meters_per_pixel = mpp;
  res->x_min = scan.x_min;
  res->y_max = scan.y_max;
}

// Legend and scale bar sizes, the panels' rectangles and the white image.
void LayOut(const RenderConfig& cfg, Canvas* c, RenderResult* res) {
  const int s = c->s;
  c->text_h = detail::TextHeight(s);
  c->row_h = c->text_h + 3 * s;
  c->pad = 4 * s;
  c->swatch = c->text_h;
  c->ramp_h = 6 * c->row_h;  // height colour bar
  int legend_w = 0, legend_h = 0;
  if (cfg.legend) {
    int text_w = detail::TextWidth(c->title, s);
    for (const auto& e : c->entries) text_w = std::max(text_w, c->swatch + 2 * s + detail::TextWidth(e.label, s));
    const std::string lo_label = Num(c->h_lo) + " m", hi_label = Num(c->h_hi) + " m";
    if (c->mode == Mode::kHeight)
      text_w = std::max(text_w, 3 * c->swatch + 2 * s +
                                    std::max(detail::TextWidth(lo_label, s), detail::TextWidth(hi_label, s)));
    legend_w = text_w + 2 * c->pad;
    legend_h = c->pad + c->row_h * (1 + int(c->entries.size())) +
               (c->mode == Mode::kHeight ? c->ramp_h + c->row_h : 0) + c->pad;
  }
  const int bar_h = cfg.scale_bar ? c->text_h + 4 * s : 0;
  const int m = c->m = cfg.margin_px;
  const int width = m + c->map_w + (cfg.legend ? m + legend_w : 0) + m;
  const int height = m + std::max(c->map_h, legend_h) + (cfg.scale_bar ? m + bar_h : 0) + m;
  res->map = {m, m, c->map_w, c->map_h};
  if (cfg.legend) res->legend = {m + c->map_w + m, m, legend_w, legend_h};
  if (cfg.scale_bar) res->scale_bar = {m, m + std::max(c->map_h, legend_h) + m, c->map_w, bar_h};
  res->image = Image(width, height, kWhite);
}

// Pass 2: splat, keeping per pixel the highest priority seen (class priority, session, or
// height; a height colour is computed only when the point wins a pixel).
void SplatPoints(const std::vector<Layer>& layers, const RenderConfig& cfg, const Canvas& c, RenderResult* res) {
  const int map_w = c.map_w, map_h = c.map_h, m = c.m;
  std::vector<float> prio(std::size_t(map_w) * map_h, -std::numeric_limits<float>::infinity());
  const double inv_mpp = 1.0 / c.mpp;
  const float h_scale = float(1.0 / (c.h_hi - c.h_lo));
  const std::array<Rgb, kHeightLut>& height_lut = HeightLut();
  auto height_rgb = [&](float z) { return height_lut[std::size_t(HeightIndex(double((z - float(c.h_lo)) * h_scale)))]; };
  const int half = (cfg.point_size_px - 1) / 2;
  std::array<Rgb, kNumClasses> class_rgb;
  for (int k = 0; k < kNumClasses; ++k) class_rgb[std::size_t(k)] = ClassColor(PointClass(k));
  Image& img = res->image;
  for (std::size_t li = 0; li < layers.size(); ++li) {
    const PointCloud& cl = *layers[li].cloud;
    const bool has_cls = !cl.cls.empty(), has_ses = !cl.session.empty();
    const int def_cls = ClassIndex(layers[li].default_class), def_ses = LayerSession(layers[li], li);
    for (std::size_t i = 0; i < cl.size(); ++i) {
      const PointXYZI& p = cl.points[i];
      if (!Finite(p)) continue;
      const int px = std::min(int((p.x - res->x_min) * inv_mpp), map_w - 1);
      const int py = std::min(int((res->y_max - p.y) * inv_mpp), map_h - 1);
      float pr = p.z;
      Rgb col;
      if (c.mode == Mode::kClass) {
        const int k = has_cls ? ClassIndex(cl.cls[i]) : def_cls;
        pr = float(kClassPriority[std::size_t(k)]);
        col = class_rgb[std::size_t(k)];
      } else if (c.mode == Mode::kSession) {
        const int ses = has_ses ? int(cl.session[i]) : def_ses;
        pr = float(ses);
        col = SessionColor(ses);
      }
      ++res->points_drawn;
      if (cfg.point_size_px == 1) {
        float& slot = prio[std::size_t(py) * map_w + px];
        if (pr < slot) continue;
        slot = pr;
        img.Set(m + px, m + py, c.mode == Mode::kHeight ? height_rgb(p.z) : col);
        continue;
      }
      if (c.mode == Mode::kHeight) col = height_rgb(p.z);
      for (int dy = -half; dy < cfg.point_size_px - half; ++dy)
        for (int dx = -half; dx < cfg.point_size_px - half; ++dx) {
          const int qx = px + dx, qy = py + dy;
          if (qx < 0 || qy < 0 || qx >= map_w || qy >= map_h) continue;
          float& slot = prio[std::size_t(qy) * map_w + qx];
          if (pr < slot) continue;
          slot = pr;
          img.Set(m + qx, m + qy, col);
        }
    }
  }
}

// Trajectories over the points, with a tick per keyframe across the local direction.
void DrawTrajectories(const std::vector<Trajectory>& trajectories, const RenderConfig& cfg, const Canvas& c,
                      RenderResult* res) {
  const double inv_mpp = 1.0 / c.mpp;
  auto to_px = [&](const Eigen::Vector3d& p, int* x, int* y) {
    *x = c.m + std::min(c.map_w - 1, int(std::floor((p.x() - res->x_min) * inv_mpp)));
    *y = c.m + std::min(c.map_h - 1, int(std::floor((res->y_max - p.y()) * inv_mpp)));
  };
  for (std::size_t t = 0; t < trajectories.size(); ++t) {
    const Rgb col = TrajectoryColor(int(t));
    std::vector<Eigen::Vector3d> pts;
    for (const auto& p : trajectories[t].positions)
      if (p.allFinite()) pts.push_back(p);
    for (std::size_t k = 0; k + 1 < pts.size(); ++k) {
      int x0, y0, x1, y1;
      to_px(pts[k], &x0, &y0);
      to_px(pts[k + 1], &x1, &y1);
      detail::DrawLine(res->image, x0, y0, x1, y1, col, cfg.trajectory_width_px);
    }
    if (cfg.tick_half_length_px <= 0) continue;
    for (std::size_t k = 0; k < pts.size(); ++k) {
      // Tick perpendicular to the local direction (image y points down: flip).
      const Eigen::Vector3d d = pts[std::min(k + 1, pts.size() - 1)] - pts[k > 0 ? k - 1 : 0];
      Eigen::Vector2d n(-d.y(), d.x());
      if (n.norm() < 1e-12) n = Eigen::Vector2d(1, 0);
      n.normalize();
      int x, y;
      to_px(pts[k], &x, &y);
      const int L = cfg.tick_half_length_px;
      const int ox = int(std::lround(n.x() * L)), oy = int(std::lround(-n.y() * L));
      detail::DrawLine(res->image, x - ox, y - oy, x + ox, y + oy, col, std::max(1, cfg.trajectory_width_px - 1));
    }
  }
}

// Scale bar: a 1/2/5 x 10^k length of at most a quarter of the map width.
void DrawScaleBar(const Canvas& c, RenderResult* res) {
  const int s = c.s, text_h = c.text_h;
  const double L = NiceLength(std::max(1, c.map_w / 4) * c.mpp);
  const int len = std::max(1, int(std::lround(L * (1.0 / c.mpp))));
  const int x0 = res->scale_bar.x0, y0 = res->scale_bar.y0;
  const int th = std::max(2, s);
  const int ybar = y0 + text_h / 2;
  Image& img = res->image;
  detail::FillRect(img, x0, ybar - th / 2, len, th, kBlack);
  detail::FillRect(img, x0, ybar - text_h / 2, th, text_h, kBlack);
  detail::FillRect(img, x0 + len - th, ybar - text_h / 2, th, text_h, kBlack);
  detail::DrawText(img, x0 + len + 3 * s, y0, Num(L) + " m", kBlack, s);
}

// Legend panel: title, the height ramp (height mode), the entries.
void DrawLegend(const Canvas& c, RenderResult* res) {
  Image& img = res->image;
  const Rect& r = res->legend;
  const int s = c.s, swatch = c.swatch;
  detail::FillRect(img, r.x0, r.y0, r.w, r.h, kWhite);
  detail::DrawRectOutline(img, r.x0, r.y0, r.w, r.h, kFrame);
  int y = r.y0 + c.pad;
  const int x = r.x0 + c.pad;
  detail::DrawText(img, x, y, c.title, kBlack, s);
  y += c.row_h;
  if (c.mode == Mode::kHeight) {
    const int bw = 2 * swatch;
    for (int k = 0; k < c.ramp_h; ++k)
      detail::FillRect(img, x, y + k, bw, 1, HeightColor(1.0 - double(k) / std::max(1, c.ramp_h - 1)));
    detail::DrawRectOutline(img, x - 1, y - 1, bw + 2, c.ramp_h + 2, kFrame);
    detail::DrawText(img, x + bw + 3 * s, y, Num(c.h_hi) + " m", kBlack, s);
    detail::DrawText(img, x + bw + 3 * s, y + c.ramp_h - c.text_h, Num(c.h_lo) + " m", kBlack, s);
    y += c.ramp_h + c.row_h;
  }
  for (const auto& e : c.entries) {
    if (e.line)
      detail::FillRect(img, x, y + swatch / 2 - s / 2, swatch, std::max(2, s), e.color);
    else
      detail::FillRect(img, x, y, swatch, swatch, e.color);
    detail::DrawText(img, x + swatch + 2 * s, y, e.label, kBlack, s);
    y += c.row_h;
  }
}
}  // namespace

RenderResult Render(const std::vector<Layer>& layers, const std::vector<Trajectory>& trajectories,
                    const RenderConfig& cfg) {
  ValidateConfig(cfg, "render config");
  CheckLayers(layers);
  Canvas c;
  c.mode = cfg.color_by == "class" ? Mode::kClass : cfg.color_by == "session" ? Mode::kSession : Mode::kHeight;
  const Scan scan = ScanLayers(layers, trajectories);
  RenderResult res;
  PlaceMap(scan, cfg, &c, &res);
  std::tie(c.h_lo, c.h_hi) = HeightRange(layers, scan, cfg, c.mode);
  res.height_min_m = c.h_lo;
  res.height_max_m = c.h_hi;
  c.title = LegendEntries(layers, trajectories, scan, c.mode, &c.entries);
  LayOut(cfg, &c, &res);
  SplatPoints(layers, cfg, c, &res);
  DrawTrajectories(trajectories, cfg, c, &res);
  detail::DrawRectOutline(res.image, c.m - 1, c.m - 1, c.map_w + 2, c.map_h + 2, kFrame);  // frame around the map
  if (cfg.scale_bar) DrawScaleBar(c, &res);
  if (cfg.legend) DrawLegend(c, &res);
  return res;
}

RenderResult RenderTopDown(const std::vector<Layer>& layers,
                           const std::vector<Trajectory>& trajectories, const RenderConfig& cfg,
                           const std::string& png_path) {
  RenderResult r = Render(layers, trajectories, cfg);
  WritePng(png_path, r.image);
  return r;
}

}  // namespace ltm::viz
