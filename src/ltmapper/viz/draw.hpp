// Internal drawing primitives of the viz module (not part of the public API).
#pragma once

#include "ltmapper/viz/viz.hpp"

#include <string>

namespace ltm::viz::detail {

// Built-in 5x7 bitmap font: digits, A-Z (lower case drawn as upper case, except 'm'), and
// . - _ : / ( ) + ; unknown characters are drawn as '?'. Advance 6 font pixels per character.
constexpr int kGlyphW = 5, kGlyphH = 7, kAdvance = 6;
int TextWidth(const std::string& text, int scale);
int TextHeight(int scale);
// (x, y) = top-left corner of the text.
void DrawText(Image& img, int x, int y, const std::string& text, Rgb color, int scale);

void FillRect(Image& img, int x0, int y0, int w, int h, Rgb color);
void DrawRectOutline(Image& img, int x0, int y0, int w, int h, Rgb color);
// Line from (x0, y0) to (x1, y1) with a square pen of `width` pixels (Bresenham).
void DrawLine(Image& img, int x0, int y0, int x1, int y1, Rgb color, int width);

}  // namespace ltm::viz::detail
