// `microbsdf render`: a material preview of a tabulated BSDF, one panel per model side by side
// (the paper's Figs. 7 and 12 idea). Each panel is path traced (image_render.h): an object (a
// sphere, a shader ball, or the user's OBJ/PLY mesh; shapes.h) with the model's table on its
// surface (tabulated_material.h: f from the interpolation every reader of a table uses), under an
// environment at infinity (environment.h: built-in studio or sky, or an equirectangular EXR), seen by
// a pinhole camera. Optionally a closed-form GGX conductor beside them (ggx_material.h) — the
// reference a statistical GGX table's coherent component should look like.
#pragma once
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "io/bsdf_file.h"
#include "render/image_render.h"
#include "render/tone_map.h"

namespace mbsdf {

struct GgxReference {
  double alpha = 0.3;
  std::string material = "Al";  // a built-in conductor (optics/material.h)
};

struct RenderRequest {
  std::vector<std::string> models;     // empty: the GS, GM, WS, WM the file can form
  int size = 512;                      // pixels per panel (square)
  std::string shape = "sphere";        // sphere, ball, plane, or an .obj / .ply file
  std::string environment = "studio";  // studio, sky, or an equirectangular .exr
  double environmentTurn_deg = 0;      // the environment turned about z (moves the highlights)
  double cameraElevation_deg = 20;     // above the horizon, looking at the origin
  double cameraAzimuth_deg = -90;      // −90: from −y, the x axis to the right
  double fovY_deg = 30;
  RenderSettings settings;
  std::optional<GgxReference> ggx;
  // The index below the table's surface relative to above, for light from a side the table holds no
  // incidence on (tabulated_material.h); 0: not known.
  double insideIor = 0;
};

struct PreviewPanel {
  std::string label;
  LinearImage image;
  bool reciprocityUsed = false;     // light from a side the table holds no incidence on (tabulated_material.h)
  bool etaFactorMissing = false;    // and through the surface, without the index to scale it
  bool lightSliceInside = false;    // a list of incidences lit a viewer inside through the light's slice
  bool unfinishedReplaced = false;  // a slice not finished yet stood in for by the nearest finished one
  bool nearestSlice = false;        // the table's incidences have no rule between them (BsdfLookup::nearestOnly)
  uint64_t dropped = 0;             // non-finite samples left out
};

// progress(panel, rowsDone) from the rendering threads.
std::vector<PreviewPanel> renderPreview(const BsdfFileReader& file, const RenderRequest& req,
                                        const std::function<void(int, int)>& progress = {});
// The panels side by side, tone mapped, each labelled at its top left.
RgbImage composePanels(const std::vector<PreviewPanel>& panels, double exposureStops, ToneCurve curve);
// The panels side by side in linear radiance (for EXR).
LinearImage composeLinear(const std::vector<PreviewPanel>& panels);
// The camera renderPreview uses for a request.
Camera previewCamera(const RenderRequest& req);
// The environment of a request, turned by environmentTurn_deg.
Environment previewEnvironment(const RenderRequest& req);

}  // namespace mbsdf
