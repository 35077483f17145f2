#include "render/tone_map.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "io/slice_export.h"

namespace mbsdf {

ToneCurve toneCurveFromName(const std::string& name) {
  if (name == "filmic") return ToneCurve::Filmic;
  if (name == "clip") return ToneCurve::Clip;
  throw InputError("--tone-curve: \"" + name + "\" is neither filmic nor clip");
}

double toneCurve(ToneCurve curve, double x) {
  x = std::max(0.0, x);
  if (curve == ToneCurve::Clip) return std::min(x, 1.0);
  return std::clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

RgbImage toneMap(const LinearImage& image, double exposureStops, ToneCurve curve) {
  RgbImage out;
  out.width = image.width;
  out.height = image.height;
  out.rgb.resize(image.rgb.size());
  const double scale = std::exp2(exposureStops);
  for (size_t i = 0; i < image.rgb.size(); ++i)
    out.rgb[i] = uint8_t(std::lround(255 * srgbEncode(toneCurve(curve, scale * image.rgb[i]))));
  return out;
}

}  // namespace mbsdf
