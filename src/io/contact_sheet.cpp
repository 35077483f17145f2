#include "io/contact_sheet.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

#include "io/bitmap_text.h"

namespace mbsdf {

namespace {

// Short row labels for single components (the font has no lower case).
std::string label(const std::string& model) {
  static const std::map<std::string, std::string> m = {
      {"coherent", "C"}, {"incoherent", "I"}, {"multiple", "M"}, {"lost", "L"}};
  auto it = m.find(model);
  return it == m.end() ? model : it->second;
}

}  // namespace

// A slice the file does not hold yet (a partial file): hatched dark red, never drawn as if the
// surface were black.
RgbImage missingCell(int width, int height) {
  RgbImage img;
  img.width = width;
  img.height = height;
  img.rgb.assign(size_t(width) * height * 3, 0);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const bool stripe = ((x + y) / 6) % 2 == 0;
      uint8_t* p = &img.rgb[(size_t(y) * width + x) * 3];
      p[0] = stripe ? 140 : 60, p[1] = stripe ? 20 : 10, p[2] = stripe ? 20 : 10;
    }
  return img;
}

RgbImage renderContactSheet(const BsdfFileReader& file, const SheetRequest& req) {
  const std::vector<std::string> models = req.models.empty() ? availableModels(file) : req.models;
  // Every slice (or the nearest to each requested angle), computed or not: a partial file shows
  // its missing slices as hatched cells.
  std::vector<int> columns;
  if (req.theta_deg.empty()) {
    for (int i = 0; i < file.incidenceCount(); ++i) columns.push_back(i);
  } else {
    for (double t : req.theta_deg) columns.push_back(file.nearestIncidence(t, req.phi_deg));
  }
  const auto firstDone = std::find_if(columns.begin(), columns.end(), [&](int i) { return file.done(i); });
  if (models.empty() || firstDone == columns.end())
    throw std::runtime_error("nothing to draw (no model, or none of the slices asked for is computed yet)");

  std::vector<std::vector<RgbImage>> cells(models.size());
  for (size_t r = 0; r < models.size(); ++r) {
    SliceRequest c = req.cell;
    c.model = models[r];
    const RgbImage done = renderSliceImage(file, c, *firstDone);
    for (int inc : columns)
      cells[r].push_back(file.done(inc) ? (inc == *firstDone ? done : renderSliceImage(file, c, inc))
                                        : missingCell(done.width, done.height));
  }
  const int cw = cells[0][0].width, ch = cells[0][0].height, gap = 4, scale = std::max(1, req.cell.size / 64);
  const int left = 4 + 6 * scale * 2 + 8, top = 7 * scale + 8;
  RgbImage sheet;
  sheet.width = left + int(columns.size()) * (cw + gap);
  sheet.height = top + int(models.size()) * (ch + gap);
  sheet.rgb.assign(size_t(sheet.width) * sheet.height * 3, 40);
  for (size_t r = 0; r < models.size(); ++r) {
    const int y0 = top + int(r) * (ch + gap);
    drawText(sheet, 4, y0 + ch / 2 - 7 * scale / 2, label(models[r]), scale, 235);
    for (size_t c = 0; c < columns.size(); ++c) {
      const int x0 = left + int(c) * (cw + gap);
      const RgbImage& cell = cells[r][c];
      for (int j = 0; j < ch; ++j)
        std::copy_n(&cell.rgb[size_t(j) * cw * 3], size_t(cw) * 3, &sheet.rgb[(size_t(y0 + j) * sheet.width + x0) * 3]);
    }
  }
  for (size_t c = 0; c < columns.size(); ++c) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.0f°", file.incidenceTheta(columns[c]));
    drawText(sheet, left + int(c) * (cw + gap) + 2, 4, buf, scale, 235);
  }
  return sheet;
}

}  // namespace mbsdf
