// From a rendered radiance image to display pixels: exposure (a scale of 2^stops on the linear sRGB
// radiance), then a tone curve, then the sRGB transfer function (IEC 61966-2-1) to 8 bits.
//  - filmic: the fit of the ACES reference rendering transform by Narkowicz (2015, "ACES Filmic Tone
//    Mapping Curve"), f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), applied per channel:
//    highlights roll off instead of clipping (a highlight 16× brighter than mid-grey stays < 1).
//  - clip: f(x) = min(x, 1), the radiance as it is up to white.
#pragma once
#include <string>

#include "io/png_image.h"
#include "render/image_render.h"

namespace mbsdf {

enum class ToneCurve { Filmic, Clip };

// "filmic" or "clip" (InputError otherwise).
ToneCurve toneCurveFromName(const std::string& name);
double toneCurve(ToneCurve curve, double x);
RgbImage toneMap(const LinearImage& image, double exposureStops, ToneCurve curve);

}  // namespace mbsdf
