// The RGL material database's `.bsdf` file (Dupuy & Jakob 2018, "An Adaptive Parameterization for
// Efficient Material Acquisition and Rendering"), read by Mitsuba 3's and pbrt-v4's `measured`
// material, written from a stored table's reflection for renderers.
//
// The format stores a reflectance in a parameterisation adapted to it (Dupuy & Jakob 2018, §4–6):
// - `ndf` D(ωm) and `sigma` σ(ωi) = ∫ D(ωm) max(0, ωi·ωm) dωm on grids in u = (√(2θ/π), (φ + π)/2π)
//   (bilinear, values as they are);
// - per incidence (θi, φi) on the `theta_i` × `phi_i` grid (radians; one φi node = isotropic, whose
//   half vectors are then given relative to φi): `vndf`, the density in u of the half vector ωm,
//   D(ωm) max(0, ωi·ωm) / σ(ωi) times the Jacobian 2π² u_θ sin θm (so that its warp — the piecewise
//   bilinear warp of export/piecewise_bilinear_warp.h — maps the unit square onto half vectors as the
//   visible normals are distributed);
// - `spectra` (per wavelength) or `rgb`, on an n × n grid of that warp's unit square, and
//   `luminance`, the same table's luminance, which renderers sample before the warp.
// A renderer evaluates f(ωi, ωo) cos θo = spectra(warp⁻¹(u(ωm))) D(ωm) / (4 σ(ωi)) (`jacobian` = 1),
// with ωm the half vector, ωi the direction the table is parameterised by and ωo the one its sampler
// draws: the value powitacq's BRDF::eval returns and BRDF::sample divides by the pdf over ωo (the
// reference loader, rgl-epfl/brdf-loader powitacq.inl); Mitsuba 3's `measured` returns it as its
// cosine-weighted eval, pbrt-v4's MeasuredBxDF::f divides it by the cosine of its sampled direction.
// So each spectra node holds f(ωi, ωo) cos θo 4σ(ωi) / D(ωm) of
// the table (BsdfLookup) at the half vector the warp puts there, with D and σ as the renderer
// interpolates them: the file reproduces the table at its nodes whatever D is. D only decides where
// the nodes go, so it is taken from the table itself rather than from a facet model: at each half
// vector, the largest f(ωi, ωo) 4 cos θi cos θo over the table's incidences (for a microfacet surface
// F G D, for a grating its orders), floored at `ndfFloor` of its maximum so that light outside a
// narrow lobe (diffraction, multiple scattering) keeps nodes of its own (D > 0 wherever f > 0), and
// normalised so that ∫ D cos θm dωm = 1. Each incidence's values are then scaled so that the file's
// albedo there, as a renderer integrates it, is the table's hemispherical integral (the resampling
// would otherwise gain or lose the light of lobes narrower than the table's bins).
//
// The format holds reflection only. An isotropic table (the file's `symmetry` attribute) writes one
// φi node; an anisotropic one needs every incidence bin (incidence = "all") and writes φi nodes over
// [−π, π].
#pragma once
#include <string>
#include <vector>

#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"

namespace mbsdf {

struct RglExport {
  enum class Colour { spectral, rgb };
  Colour colour = Colour::spectral;
  std::vector<int> wavelengths;    // indices into the table's wavelengths (spectral: all when empty)
  int nTheta_m = 64, nPhi_m = 64;  // the ndf, sigma and vndf grids in (u_θ, u_φ)
  int nSample = 0;                 // the spectra and luminance grid per incidence (0: 64 isotropic, 48 anisotropic)
  double ndfFloor = 0.02;          // D's floor relative to its maximum
};

struct RglFile {
  std::string bytes;
  struct Unresolved {  // an incidence whose albedo the file misses by more than a factor 2 (left unscaled)
    double theta_deg, phi_deg;
    std::string band;  // "450 nm", or a colour table's channel
    double fileAlbedo, tableAlbedo;
  };
  std::vector<Unresolved> unresolved;
  double energyCorrection = 0;  // the largest relative scale that made an incidence's albedo the table's
  int negativeClamped = 0;      // spectra or rgb nodes below 0 (noise, or colours outside sRGB) stored as 0
  int nodes = 0;                // spectra or rgb nodes in all
};

// Throws InputError when the table holds no incidence above the surface, an anisotropic table lacks
// incidence bins, or a slice is unfinished.
RglFile rglBsdfFile(const BsdfFileReader& file, const BsdfLookup& lookup, const RglExport& options,
                    const std::string& description);

}  // namespace mbsdf
