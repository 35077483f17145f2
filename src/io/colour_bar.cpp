#include "io/colour_bar.h"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "io/bitmap_text.h"
#include "io/slice_export.h"

namespace mbsdf {
namespace {

int rampHeight(int size) {
  return std::max(8, size / 16);
}
int textScale(int size) {
  return std::max(1, size / 128);
}

// f = 10^k as written under its tick: plain decimals from 0.001 to 1000, 1E-4 and beyond.
std::string decadeLabel(int k) {
  if (k >= 0 && k <= 3) return fmt::format("{}", int(std::lround(std::pow(10.0, k))));
  if (k < 0 && k >= -3) return "0." + std::string(size_t(-k - 1), '0') + "1";
  return fmt::format("1E{}", k);
}

void fill(RgbImage& img, int x0, int y0, int w, int h, uint8_t grey) {
  for (int y = std::max(0, y0); y < std::min(img.height, y0 + h); ++y)
    for (int x = std::max(0, x0); x < std::min(img.width, x0 + w); ++x)
      for (int k = 0; k < 3; ++k) img.rgb[(size_t(y) * img.width + x) * 3 + k] = grey;
}

}  // namespace

int colourBarHeight(int size) {
  const int s = textScale(size);
  return rampHeight(size) + 3 * s + 2 * (7 * s + 3 * s);  // ramp, ticks, numbers, unit
}

void drawColourBar(RgbImage& img, int y0, int size, double log2Min, double log2Max) {
  const int W = img.width, ramp = rampHeight(size), s = textScale(size);
  fill(img, 0, y0, W, colourBarHeight(size), 0);
  for (int j = y0; j < y0 + ramp; ++j)
    for (int i = 0; i < W; ++i) {
      const Colour3 c = falseColour((i + 0.5) / W);
      for (int k = 0; k < 3; ++k)
        img.rgb[(size_t(j) * W + i) * 3 + k] = uint8_t(std::lround(std::clamp(c[k], 0.0, 1.0) * 255));
    }
  // Decades of f inside the range, thinned until their numbers keep a glyph's gap between them.
  const double lo = log2Min * std::log10(2.0), hi = log2Max * std::log10(2.0);
  const int kFirst = int(std::ceil(lo - 1e-9)), kLast = int(std::floor(hi + 1e-9));
  auto xOf = [&](int k) { return (k / std::log10(2.0) - log2Min) / (log2Max - log2Min) * W; };
  int widest = 0;
  for (int k = kFirst; k <= kLast; ++k) widest = std::max(widest, textWidth(decadeLabel(k), s));
  int step = 1;
  for (int candidate : {1, 2, 5, 10, 20, 50, 100}) {
    step = candidate;
    if (kLast <= kFirst || xOf(kFirst + step) - xOf(kFirst) >= widest + 6 * s) break;
  }
  // A number pushed inwards at the picture's edge may reach its neighbour's: it is left out (its
  // tick stays).
  const int tickTop = y0 + ramp, textTop = tickTop + 3 * s + 2;
  int freeFrom = 0;  // the first column a number may use
  for (int k = kFirst; k <= kLast; ++k) {
    if (((k % step) + step) % step != 0) continue;
    const int x = std::clamp(int(std::lround(xOf(k))), 0, W - 1);
    fill(img, x - s / 2, tickTop, std::max(1, s), 3 * s, 235);
    const std::string label = decadeLabel(k);
    const int w = textWidth(label, s), left = std::clamp(x - w / 2, 0, std::max(0, W - w));
    if (left < freeFrom) continue;
    drawText(img, left, textTop, label, s, 235);
    freeFrom = left + w + 6 * s;
  }
  const std::string unit = "BSDF 1/SR";
  drawText(img, std::max(0, (W - textWidth(unit, s)) / 2), textTop + 10 * s, unit, s, 170);
}

}  // namespace mbsdf
