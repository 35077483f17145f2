// The mean plane's Kirchhoff field as a control variate for the Monte Carlo wave estimators
// (`area`, `orders`; docs/physics.md §5, "Control variate").
//
// A point x drawn by area (pdf 1/A) gives X = A w(x) g(x) e^{i q·x} V V, whose mean is I(ωo). The
// same point also gives
//   Z = A n_z(x) C(x, q) h e^{i q_xy·x_xy},
// the field of the flat plane z = 0 (amplitude h: the integrand with m = ẑ) at x's projection,
// weighted by the signed projected area n_z dA = dA_xy. Over a surface that covers its footprint
// once (overhangs cancel), E[Z] = h ∫ w e^{i q·x} dA_xy = h · planeIntegral(q) exactly
// (CoherenceWindow::planeIntegral), so
//   Y = X − c (Z − E[Z])
// has mean I(ωo) for any c fixed before the points are drawn. With c = χ(q_z), the characteristic
// function of the surface's heights (Σ_T A_T n_z,T e^{i q_z z_T} / A_footprint over the facets),
// a flat surface gives Y = E[Z] e^{i q_z z0} with no variance at all, a shallow one nearly so, and
// a rough one (|χ| → 0, Beckmann & Spizzichino's coherent attenuation) the estimator as it was.
#pragma once
#include <complex>
#include <vector>

#include "geometry/microgeometry.h"

namespace mbsdf {

class MeanPlaneControl {
 public:
  explicit MeanPlaneControl(const Microgeometry& g);
  MeanPlaneControl() = default;  // no control (c = 0)
  // False when the surface does not cover its footprint exactly once (holes, overlapping sheets:
  // E[Z] is not known) or has facets facing down (overhangs: Z there adds variance that X does
  // not share); the control is then not used (c = 0).
  bool usable() const { return usable_; }
  // c = χ(q_z) (0 when not usable).
  std::complex<double> coefficient(double qz) const;

 private:
  // Facet heights and signed projected areas (a deterministic subset of at most kMaxHeights
  // facets on large meshes: c needs only to be fixed, not exact).
  std::vector<double> z_, weight_;
  bool usable_ = false;
};

}  // namespace mbsdf
