// The scalar Kirchhoff table of a flat interface against its geometric-optics limit, in closed form.
//
// A flat periodic patch has one grating order with power, the specular one (every other order's
// integral over the cell vanishes), so the wave model's far field is the reflected and the
// transmitted beam of Fresnel's powers R and T, each spread by the coherence window's diffraction
// into a Gaussian spot of standard deviation 1 / (√2 σ_w n_o k0) in the plane of direction cosines
// of its medium (n_o its index; docs/physics.md §5), the part beyond the horizon evanescent. Geometric
// optics puts R and T in the bins of the mirror and the refracted direction. The surface is its own
// ensemble: there is no speckle, so the L1 distance of the two tables is the whole difference
// diffraction makes (the effects planner's decision, effects_planner.h).
#pragma once
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "core/direction_grid.h"
#include "core/vecmath.h"
#include "scattering/kirchhoff_ensemble.h"

namespace mbsdf {

// The media of a flat interface as light from one side meets them: the real index it comes from,
// the real index beyond where light passes (none for a conductor), and the unpolarised Fresnel
// reflectance at a cosine of incidence (total internal reflection included).
struct FlatInterfaceMedia {
  double nIncident;
  std::optional<double> nBeyond;
  std::function<double(double)> reflectance;
};

// One incidence: directions wi (unit, towards the light, all on one side) with weights summing to
// 1 (a collimated beam, or a quadrature over an incidence bin); lambda_um; the window's σ (0: none,
// the beams stay in their bins). Energy per cell (bins pooled by cellOf, −1: not counted) in
// `coherent` (the wave model) and `geometric`; `diffuse` is zero.
EnsembleSlice flatInterfaceSlice(const DirectionGrid& grid, const std::vector<std::pair<Vec3, double>>& wi,
                                 double lambda_um, const FlatInterfaceMedia& media, double windowSigma_um,
                                 const std::vector<int>& cellOf, int nCells);

}  // namespace mbsdf
