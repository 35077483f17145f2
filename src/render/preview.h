// `microbsdf render`: a preview of a tabulated BSDF on a sphere (the paper's Fig. 7 idea, without
// its scene): an orthographic camera looking down −z at a unit sphere (tessellated, intersected
// with Embree), lit by a directional light and a uniform environment, one sphere per model side by
// side. Shading at a point with normal n uses the local frame (t, b, n), t ⟂ n in the plane of +y:
//   L = f(ωi → ωo) E cos θi + L_env a(ωo)
// with f between the table's bins and incidences as every reader of a table sees it (io/bsdf_lookup.h) and a(ωo) the
// directional albedo of the slice nearest to ωo (by reciprocity, ∫ f(ωi → ωo) cos θi dωi = a(ωo) for a constant
// environment). Spectra → sRGB through CIE 1931 when a wavelength is visible, else grey.
#pragma once
#include <string>
#include <vector>

#include "io/bsdf_file.h"
#include "io/png_image.h"

namespace mbsdf {

struct RenderRequest {
  std::vector<std::string> models;  // empty: the GS, GM, WS, WM the file can form
  int size = 192;                   // pixels per sphere
  double lightTheta_deg = 45, lightPhi_deg = 0;
  double lightIrradiance = 1.0;  // E on a plane normal to the light
  double environment = 0.05;     // L_env (0: the light alone)
  double exposure = 1.0;
};

RgbImage renderPreview(const BsdfFileReader& file, const RenderRequest& req);

}  // namespace mbsdf
