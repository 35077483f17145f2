// The scalar Kirchhoff reflection of an ensemble of Gaussian random surfaces, against its
// geometric-optics limit, integrated over the bins of a direction grid.
//
// Surface: Gaussian heights of rms σ with Gaussian autocorrelation σ² exp(−τ²/ℓ²), which makes the
// slopes Gaussian with <tan² θm> = α² = 4σ²/ℓ² (the Beckmann NDF of width α). Beckmann &
// Spizzichino 1963 (ch. 5, Eq. 47) give the ensemble's scattered power as a coherent part e^{−g}
// (the specular reflection, here blurred by the coherence window) plus a diffuse part
//   ∝ F² e^{−g} Σ_{m≥1} g^m / (m! m) exp(−X / m),   g = σ² v_z²,  X = v_xy² ℓ² / 4,
// with v = k0 n (ωi + ωo) (ωi, ωo away from the surface). For g → ∞ the series tends to
// exp(−X/g) / g, which is the geometric-optics (stationary phase) reflection
// f_GO = R G D_α(h) / (4 cos θi cos θo) with X/g = tan² θh / α²; the same prefactor therefore gives
//   f_K = f_GO · g S(g, X) e^{X/g},   S(g, X) = e^{−g} Σ_{m≥1} g^m / (m! m) e^{−X/m}.
// R (unpolarised Fresnel at the microfacet angle) and Smith's uncorrelated shadowing G1(ωi) G1(ωo)
// (Beckmann Λ; Walter et al. 2007, Eq. 27) multiply both alike.
//
// Two tables of one incidence result, in energy per bin (∫_bin f cos θo dωo, albedo units): the wave
// model's coherent and diffuse parts and geometric optics'. Their L1 distance is what the effects
// planner compares with the tolerance (effects_planner.h), a deterministic evaluation in place of
// a Monte Carlo wave pilot on random rough surfaces. Valid where Kirchhoff is (radii of curvature
// >> λ) and for patches of many correlation areas (a realisation's slope histogram is then the
// ensemble's); a realisation's speckle is not in it (it lives in the diffuse part, whose total
// energy bounds it).
#pragma once
#include <functional>
#include <utility>
#include <vector>

#include "core/direction_grid.h"
#include "core/vecmath.h"

namespace mbsdf {

// Energy per cell (bins pooled by cellOf; identity for the grid's own bins) of one incidence.
struct EnsembleSlice {
  std::vector<double> coherent, diffuse, geometric;
  // Σ |coherent + diffuse − geometric|: the L1 distance of the wave table from geometric optics.
  double l1() const;
  // Σ |coherent − geometric| + Σ diffuse: an upper bound of that distance for any distribution of
  // the diffuse energy (a realisation's speckle included).
  double upperBound() const;
};

// The ensemble's diffuse series g S(g, X) (see above); tends to e^{−X/g} as g → ∞.
double kirchhoffDiffuseSeries(double g, double X);

// Deterministic stratified samples of a 2D Gaussian of unit standard deviation per axis (polar
// strata: radius from the Rayleigh quantile, angle uniform), equal weights.
std::vector<std::pair<double, double>> gaussianStrata(int nRadius, int nAngle);

class KirchhoffEnsemble {
 public:
  // sigma_um: rms height; alpha: rms slope sqrt(<tan² θm>) (ℓ = 2σ/α); windowSigma_um: the
  // coherence window's σ (0: none), whose diffraction blurs the specular part with a Gaussian of
  // standard deviation 1 / (√2 σ_w k) in the xy plane of ωo (coherence_window.h).
  KirchhoffEnsemble(double sigma_um, double alpha, double windowSigma_um);
  double rmsHeight_um() const { return sigma_; }
  double rmsSlope() const { return alpha_; }
  double correlationLength_um() const { return alpha_ > 0 ? 2 * sigma_ / alpha_ : 0.0; }

  // One incidence: directions wi (unit, z > 0, away from the surface) with weights summing to 1
  // (a collimated beam, or a quadrature over an incidence bin); lambda_um and the incident medium's
  // index n; reflectance(cos) the unpolarised Fresnel reflectance at a local angle.
  EnsembleSlice slice(const DirectionGrid& grid, const std::vector<std::pair<Vec3, double>>& wi, double lambda_um,
                      double n, const std::function<double(double)>& reflectance, const std::vector<int>& cellOf,
                      int nCells) const;

 private:
  double sigma_, alpha_, windowSigma_;
};

}  // namespace mbsdf
