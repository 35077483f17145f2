#include "render/preview.h"

#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>

#include "core/colour.h"
#include "core/error.h"
#include "geometry/embree_scene.h"
#include "io/bsdf_lookup.h"
#include "io/bitmap_text.h"
#include "io/slice_export.h"
#include "scattering/components.h"

namespace mbsdf {

namespace {

// A unit sphere as a closed triangle mesh (latitude-longitude, nLat x nLon).
Microgeometry unitSphere(int nLat, int nLon) {
  Microgeometry g;
  g.sizeX = g.sizeY = 2.0;
  g.periodic = false;
  for (int i = 0; i <= nLat; ++i)
    for (int j = 0; j < nLon; ++j) {
      const double th = kPi * i / nLat, ph = 2 * kPi * j / nLon;
      g.addVertex(sphericalDirection(th, ph));
    }
  auto v = [&](int i, int j) { return uint32_t(i * nLon + (j % nLon)); };
  for (int i = 0; i < nLat; ++i)
    for (int j = 0; j < nLon; ++j) {
      // Counter-clockwise seen from outside (normals outward).
      if (i > 0) g.triangles.push_back({v(i, j), v(i + 1, j), v(i, j + 1)});
      if (i + 1 < nLat) g.triangles.push_back({v(i, j + 1), v(i + 1, j), v(i + 1, j + 1)});
    }
  return g;
}

}  // namespace

RgbImage renderPreview(const BsdfFileReader& file, const RenderRequest& req) {
  const std::vector<std::string> models = req.models.empty() ? availableModels(file) : req.models;
  if (models.empty()) throw std::runtime_error("the file holds no complete model");
  const int nL = file.channelCount();
  std::optional<SpectrumToColour> colour;
  try {
    colour.emplace(file.toColour());
  } catch (const std::invalid_argument&) {
  }
  const Microgeometry sphere = unitSphere(96, 192);
  const PeriodicScene scene(sphere);
  const Vec3 light = sphericalDirection(radians(req.lightTheta_deg), radians(req.lightPhi_deg));
  const Vec3 view{0, 0, 1};

  const int S = req.size, top = 7 * std::max(1, S / 96) + 8;
  RgbImage img;
  img.width = S * int(models.size());
  img.height = S + top;
  img.rgb.assign(size_t(img.width) * img.height * 3, 0);
  for (size_t mi = 0; mi < models.size(); ++mi) {
    // f between bins and incidences as every reader of a table sees it (io/bsdf_lookup.h); its slices
    // are read as pixels need them.
    const BsdfLookup lookup(file, models[mi]);
    // Directional albedo a(λ) of the model: the file's per-component energy_reflected of the slice
    // (no need to read the whole table for the environment term).
    const std::vector<Component> comps = *modelComponents(models[mi]);
    std::map<int, std::vector<double>> albedos;
    auto albedo = [&](int inc) -> const std::vector<double>& {
      auto it = albedos.find(inc);
      if (it != albedos.end()) return it->second;
      const SliceStats st = file.stats(inc);
      std::vector<double> a(nL, 0.0);
      for (Component c : comps) {
        const auto& e = st.energyReflected.at(componentName(c));
        for (int l = 0; l < nL; ++l) a[l] += e[l];
      }
      return albedos.emplace(inc, a).first->second;
    };
    auto nearestDone = [&](const Vec3& w) {
      const int inc = file.nearestIncidence(degrees(sphericalTheta(w)), degrees(sphericalPhi(w)));
      return file.done(inc) ? inc : -1;
    };
    std::vector<double> L(nL);
    for (int j = 0; j < S; ++j)
      for (int i = 0; i < S; ++i) {
        const double x = -1 + 2.0 * (i + 0.5) / S, y = 1 - 2.0 * (j + 0.5) / S;
        TraceResult hit = scene.trace({x, y, 3.0}, {0, 0, -1});
        if (hit.kind != TraceResult::Kind::Hit) continue;
        const Vec3 n = normalize(hit.p);  // the smooth sphere's normal at the hit
        Vec3 t = cross(Vec3{0, 1, 0}, n);
        t = length(t) > 1e-9 ? normalize(t) : Vec3{1, 0, 0};
        const Vec3 b = cross(n, t);
        auto local = [&](const Vec3& w) { return Vec3{dot(w, t), dot(w, b), dot(w, n)}; };
        const Vec3 wo = local(view), wi = local(light);
        std::fill(L.begin(), L.end(), 0.0);
        if (wo.z <= 0) continue;
        // A pixel whose slice the file does not hold yet (a partial file) is drawn as a magenta
        // and black checker, never as a dark surface.
        bool missing = false;
        if (wi.z > 0) {
          try {
            for (int l = 0; l < nL; ++l) L[l] += lookup.eval(wi, wo, l) * req.lightIrradiance * wi.z;
          } catch (const InputError&) {  // a slice the interpolation needs is not finished yet
            missing = true;
          }
        }
        if (req.environment > 0) {
          if (int inc = nearestDone(wo); inc >= 0) {
            const auto& a = albedo(inc);
            for (int l = 0; l < nL; ++l) L[l] += req.environment * a[l];
          } else {
            missing = true;
          }
        }
        if (missing) {
          const bool on = ((i / 8) + (j / 8)) % 2 == 0;
          const size_t p = (size_t(j + top) * img.width + size_t(mi) * S + i) * 3;
          img.rgb[p] = on ? 255 : 0, img.rgb[p + 1] = 0, img.rgb[p + 2] = on ? 255 : 0;
          continue;
        }
        Colour3 rgb;
        if (colour) {
          rgb = colour->linearSrgb(L.data());
        } else {
          double m = 0;
          for (double v : L) m += v / nL;
          rgb = {m, m, m};
        }
        const size_t p = (size_t(j + top) * img.width + size_t(mi) * S + i) * 3;
        for (int k = 0; k < 3; ++k)
          img.rgb[p + k] =
              uint8_t(std::lround(std::clamp(srgbEncode(std::max(0.0, rgb[k]) * req.exposure), 0.0, 1.0) * 255));
      }
    drawText(img, int(mi) * S + 4, 4, models[mi], std::max(1, S / 96), 235);
  }
  return img;
}

}  // namespace mbsdf
