// ltmapper viz: top-down PNG pictures of maps and scans (world frame, north = +y up).
//
// Points are splatted in one pass over each cloud, no sorting: every pixel keeps the point with
// the highest draw priority seen so far (class mode: unknown < static < HD < weak changes <
// strong changes, so changes are drawn on top of the dense static map; session mode: later
// sessions on top; height mode: the highest point, as seen from above). Trajectories are drawn
// over the points, then a scale bar below the map and a legend panel to its right (neither
// covers the data). libpng is used only inside the .cpp files.
#pragma once

#include "ltmapper/core/core.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace ltm::viz {

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }
  bool operator!=(const Rgb& o) const { return !(*this == o); }
};

// 8-bit RGB image, row-major, row 0 at the top.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // width * height * 3
  Image() = default;
  Image(int w, int h, Rgb fill);
  Rgb At(int x, int y) const {
    const std::size_t k = (std::size_t(y) * width + x) * 3;
    return {rgb[k], rgb[k + 1], rgb[k + 2]};
  }
  void Set(int x, int y, Rgb c) {
    if (x < 0 || y < 0 || x >= width || y >= height) return;
    const std::size_t k = (std::size_t(y) * width + x) * 3;
    rgb[k] = c.r;
    rgb[k + 1] = c.g;
    rgb[k + 2] = c.b;
  }
};

// PNG (8-bit RGB) through libpng; the write is atomic (temporary name, then rename). ReadPng
// accepts any PNG libpng decodes and returns RGB. Both throw ltm::Error naming the file.
void WritePng(const std::string& path, const Image& image);
Image ReadPng(const std::string& path);

struct RenderConfig {
  double meters_per_pixel = 0.2;  // [m/px] map resolution; 0 = fit the longer side to max_size_px
  int max_size_px = 4096;         // [px] the map area's longer side never exceeds this (the
                                  // resolution is coarsened when needed)
  int margin_px = 16;             // [px] white border around the map area
  std::string color_by = "class";  // class | session | height
  double height_min_m = 0.0;      // [m] colormap range; min >= max = automatic (1st..99th
  double height_max_m = 0.0;      // [m]  percentile of the drawn points' z)
  int point_size_px = 1;          // [px] square splat edge
  int trajectory_width_px = 2;    // [px] polyline thickness
  int tick_half_length_px = 4;    // [px] keyframe tick half length (0 = no ticks)
  int text_scale = 0;             // [px per font pixel] 5x7 glyphs; 0 = automatic (2..6 by map size)
  bool legend = true;             // legend panel right of the map
  bool scale_bar = true;          // scale bar below the map

  template <class V>
  void Visit(V& v) {
    v("meters_per_pixel", meters_per_pixel, "m/px", 0.0, 1000.0);
    v("max_size_px", max_size_px, "px", 32, 30000);
    v("margin_px", margin_px, "px", 0, 1000);
    v("color_by", color_by, {"class", "session", "height"});
    v("height_min_m", height_min_m, "m", -1e5, 1e5);
    v("height_max_m", height_max_m, "m", -1e5, 1e5);
    v("point_size_px", point_size_px, "px", 1, 9);
    v("trajectory_width_px", trajectory_width_px, "px", 1, 20);
    v("tick_half_length_px", tick_half_length_px, "px", 0, 50);
    v("text_scale", text_scale, "px", 0, 10);
    v("legend", legend);
    v("scale_bar", scale_bar);
  }
};

// One cloud to draw (world frame). Per-point `cls` / `session` arrays are used when present,
// else the layer's defaults.
struct Layer {
  const PointCloud* cloud = nullptr;
  std::string name;                               // legend label in session mode
  PointClass default_class = PointClass::kUnknown;
  int default_session = -1;                       // -1 = the layer's position in the list
};

struct Trajectory {
  std::vector<Eigen::Vector3d> positions;  // keyframe positions, world frame [m]
  std::string name;                        // legend label
};

// Pixel rectangle [x0, x0 + w) x [y0, y0 + h).
struct Rect {
  int x0 = 0, y0 = 0, w = 0, h = 0;
  bool Contains(int x, int y) const { return x >= x0 && y >= y0 && x < x0 + w && y < y0 + h; }
};

struct RenderResult {
  Image image;
  double meters_per_pixel = 0.0;  // [m/px] resolved resolution
  double x_min = 0.0, y_max = 0.0;  // [m] world coordinates of the map area's top-left corner
  Rect map, legend, scale_bar;      // where each part was drawn (legend/scale_bar empty when off)
  double height_min_m = 0.0, height_max_m = 0.0;  // resolved colormap range (height mode)
  std::size_t points_drawn = 0;     // finite points splatted
  // Pixel of a world position (x right = +x, up = +y); false outside the map area.
  bool WorldToPixel(double x, double y, int* px, int* py) const;
};

RenderResult Render(const std::vector<Layer>& layers, const std::vector<Trajectory>& trajectories,
                    const RenderConfig& cfg);
// Render + WritePng.
RenderResult RenderTopDown(const std::vector<Layer>& layers,
                           const std::vector<Trajectory>& trajectories, const RenderConfig& cfg,
                           const std::string& png_path);

// Palettes (exposed for tests and reports).
Rgb ClassColor(PointClass c);  // static gray, HD red, PD blue, ND orange, weak lighter
Rgb SessionColor(int session);  // 10 distinct colours, cycling
Rgb TrajectoryColor(int index);  // dark colours that stand out over the points
Rgb HeightColor(double t);       // t in [0, 1], blue (low) .. red (high)

// Class of a cloud file from its base name when the file carries no class field:
// "pd_strong" / "pd_weak" / "nd_strong" / "nd_weak" / "hd" / "static" in the name, else kUnknown.
PointClass ClassFromFileName(const std::string& path);

}  // namespace ltm::viz
