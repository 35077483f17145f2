// A closed-form reference for the preview: the single-scattering microfacet BRDF of a conductor with
// the GGX distribution (Walter et al. 2007), f = F(wi·h) D(h) G2(wi, wo) / (4 cos θi cos θo), with
// the height-correlated Smith masking–shadowing G2 (Heitz 2014, Eq. 99) — the term a statistical GGX
// surface's coherent component (its depth-1 paths) estimates. Fresnel per wavelength of the table's
// material, turned into linear sRGB like the table's rows. Sampling: the half vector with density
// D(h) cos θh (Walter et al. 2007, Eqs. 35–36), wi its mirror image of wo.
#pragma once
#include <vector>

#include "microflake/ndf.h"
#include "optics/fresnel.h"
#include "render/render_material.h"

namespace mbsdf {

class GgxConductorMaterial : public RenderMaterial {
 public:
  // eta: the conductor's complex index per wavelength (relative to the outside); toRgb: each
  // wavelength's share of linear sRGB.
  GgxConductorMaterial(double alpha, std::vector<Complex> eta, std::vector<Colour3> toRgb);
  Colour3 eval(const Vec3& wi, const Vec3& wo) const override;
  std::optional<MaterialSample> sample(const Vec3& wo, Sampler& s) const override;
  double pdf(const Vec3& wo, const Vec3& wi) const override;

 private:
  double alpha_;
  MicroflakeDistribution ggx_;
  std::vector<Complex> eta_;
  std::vector<Colour3> toRgb_;
};

}  // namespace mbsdf
