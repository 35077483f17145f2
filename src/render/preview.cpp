#include "render/preview.h"

#include <cmath>
#include <stdexcept>

#include "core/error.h"
#include "io/bitmap_text.h"
#include "io/slice_export.h"
#include "optics/material.h"
#include "render/ggx_material.h"
#include "render/shapes.h"
#include "render/tabulated_material.h"

namespace mbsdf {

Camera previewCamera(const RenderRequest& req) {
  // Far enough that the unit ball fills about 80 % of a 30° field.
  const double el = radians(req.cameraElevation_deg), az = radians(req.cameraAzimuth_deg);
  const double distance = 1.25 / std::sin(radians(req.fovY_deg) / 2);
  const Vec3 eye = distance * Vec3{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
  return Camera(eye, {0, 0, 0}, {0, 0, 1}, req.fovY_deg, req.size, req.size);
}

Environment previewEnvironment(const RenderRequest& req) {
  const std::string& e = req.environment;
  Environment env =
      (e.size() > 4 && e.substr(e.size() - 4) == ".exr") ? Environment::fromExr(e) : Environment::builtIn(e);
  if (req.environmentTurn_deg == 0) return env;
  // Turning the map by whole columns keeps its pixels (and their sampling) exact.
  const int shift = int(std::lround(req.environmentTurn_deg / 360 * env.width())) % env.width();
  std::vector<float> rgb(size_t(env.width()) * env.height() * 3);
  for (int r = 0; r < env.height(); ++r)
    for (int c = 0; c < env.width(); ++c) {
      const Colour3 L = env.radiance(env.pixelCentre(c, r));
      const size_t to = (size_t(r) * env.width() + size_t((c + shift + env.width()) % env.width())) * 3;
      for (int k = 0; k < 3; ++k) rgb[to + size_t(k)] = float(L[size_t(k)]);
    }
  return Environment(env.width(), env.height(), std::move(rgb), env.name());
}

namespace {

std::vector<Colour3> linearSrgbOfWavelengths(const std::vector<double>& lambda_nm) {
  try {
    return SpectrumToColour(lambda_nm).linearSrgbPerSample();
  } catch (const std::invalid_argument&) {  // no visible wavelength: grey
    const double w = 1.0 / double(lambda_nm.size());
    return std::vector<Colour3>(lambda_nm.size(), Colour3{w, w, w});
  }
}

}  // namespace

std::vector<PreviewPanel> renderPreview(const BsdfFileReader& file, const RenderRequest& req,
                                        const std::function<void(int, int)>& progress) {
  const std::vector<std::string> models = req.models.empty() ? availableModels(file) : req.models;
  if (models.empty() && !req.ggx) throw InputError("the file holds no complete model");
  const RenderScene scene(shapeByName(req.shape));
  const Camera camera = previewCamera(req);
  const Environment env = previewEnvironment(req);
  std::vector<PreviewPanel> panels;
  auto render = [&](const std::string& label, const RenderMaterial& material) {
    PreviewPanel p;
    p.label = label;
    RenderCounts counts;
    const int index = int(panels.size());
    p.image = renderImage(
        scene, camera, material, env, req.settings,
        [&](int rows) {
          if (progress) progress(index, rows);
        },
        &counts);
    p.dropped = counts.dropped;
    panels.push_back(std::move(p));
  };
  for (const std::string& model : models) {
    const TabulatedMaterial material(file, model, req.insideIor);
    render(model, material);
    panels.back().reciprocityUsed = material.reciprocityUsed();
    panels.back().etaFactorMissing = material.etaFactorMissing();
    panels.back().lightSliceInside = material.lightSliceInside();
    panels.back().nearestSlice = material.lookup().nearestOnly();
    panels.back().unfinishedReplaced = material.unfinishedReplaced();
  }
  if (req.ggx) {
    Material m;
    if (!builtinMaterial(req.ggx->material, &m) || !m.isConductor() || m.isPerfectConductor())
      throw InputError("--ggx-reference: \"" + req.ggx->material +
                       "\" is not a built-in conductor with an index (Al, Ag, Au, Cu)");
    std::vector<double> lambda_um;
    for (double nm : file.wavelengths_nm()) lambda_um.push_back(nm / 1000);
    std::vector<Complex> eta;
    for (const Complex& n : m.iorAt(lambda_um)) eta.push_back(n / m.outsideIor);
    const GgxConductorMaterial ggx(req.ggx->alpha, eta, linearSrgbOfWavelengths(file.wavelengths_nm()));
    render("GGX " + req.ggx->material, ggx);
  }
  return panels;
}

LinearImage composeLinear(const std::vector<PreviewPanel>& panels) {
  LinearImage out;
  if (panels.empty()) return out;
  const int S = panels.front().image.width, H = panels.front().image.height;
  out.width = S * int(panels.size());
  out.height = H;
  out.rgb.assign(size_t(out.width) * H * 3, 0.f);
  for (size_t i = 0; i < panels.size(); ++i)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < S; ++x)
        for (int k = 0; k < 3; ++k)
          out.rgb[(size_t(y) * out.width + i * S + size_t(x)) * 3 + size_t(k)] =
              panels[i].image.rgb[(size_t(y) * S + size_t(x)) * 3 + size_t(k)];
  return out;
}

RgbImage composePanels(const std::vector<PreviewPanel>& panels, double exposureStops, ToneCurve curve) {
  RgbImage img = toneMap(composeLinear(panels), exposureStops, curve);
  if (panels.empty()) return img;
  const int S = panels.front().image.width, scale = std::max(1, S / 192);
  for (size_t i = 0; i < panels.size(); ++i)
    drawText(img, int(i) * S + 4 * scale, 4 * scale, panels[i].label, scale, 235);
  return img;
}

}  // namespace mbsdf
