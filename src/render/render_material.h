// What the preview's path tracer asks of a material, in the local frame of a surface point (z the
// outward normal, either hemisphere). wi points towards the light, wo towards the viewer, as the
// tables' incidence and exit directions do. Values are linear sRGB. Implementations really vary: a
// tabulated BSDF read from an output file (tabulated_material.h) and closed-form references
// (ggx_material.h).
#pragma once
#include <optional>

#include "core/colour.h"
#include "core/rng.h"
#include "core/vecmath.h"

namespace mbsdf {

struct MaterialSample {
  Vec3 wi;         // unit, towards the light
  Colour3 weight;  // f(wi → wo) |cos θi| / pdf
  double pdf = 0;  // per unit solid angle
};

class RenderMaterial {
 public:
  virtual ~RenderMaterial() = default;
  // f(wi → wo) per colour channel (1/sr).
  virtual Colour3 eval(const Vec3& wi, const Vec3& wo) const = 0;
  // A direction wi drawn for the viewer at wo, with its density; empty when the draw leaves no
  // direction (the path ends). Draws at most four numbers from s.
  virtual std::optional<MaterialSample> sample(const Vec3& wo, Sampler& s) const = 0;
  // The density sample(wo) draws wi with.
  virtual double pdf(const Vec3& wo, const Vec3& wi) const = 0;
};

}  // namespace mbsdf
