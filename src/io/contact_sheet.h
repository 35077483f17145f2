// A contact sheet: BSDF slice pictures over incidence angles (columns) and models (rows), like the
// paper's Figs. 9, 11, 13 and 14, with the row (model) and column (θi in degrees) written in the
// margins. Cells are the PNG pictures of `slice` (true or false colour, reflection and optionally
// transmission side by side).
#pragma once
#include <string>
#include <vector>

#include "io/png_image.h"
#include "io/slice_export.h"

namespace mbsdf {

struct SheetRequest {
  std::vector<std::string> models;  // empty: those of GS, GM, WS, WM the file can form
  std::vector<double> theta_deg;    // empty: every computed slice (nearest slices otherwise)
  double phi_deg = 0;
  SliceRequest cell;  // style, exposure, log2 range, size, both
};

RgbImage renderContactSheet(const BsdfFileReader& file, const SheetRequest& req);

}  // namespace mbsdf
