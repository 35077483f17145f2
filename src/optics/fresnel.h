// Fresnel amplitude coefficients for a planar interface between a real incident medium n1 and a
// (possibly complex) medium n2 = eta + i kappa. Convention: fields ∝ exp(i(k·x − ωt)), so an
// absorbing medium has kappa > 0 and the transmitted wave must decay: we pick the branch of
// n2 cos θt = sqrt(n2² − n1² sin² θi) with Im ≥ 0 (Born & Wolf §1.5, §14.1). The s/p amplitudes are
// the ones the Kirchhoff integrand needs (docs/physics.md §5); powers for unpolarised light are the mean
// of s and p (docs/physics.md §4).
#pragma once
#include <complex>

namespace mbsdf {

using Complex = std::complex<double>;

struct FresnelAmplitudes {
  Complex rs, rp, ts, tp;
  Complex cosTheta_t;  // complex cosine in medium 2 (purely imaginary part under TIR)
  bool totalInternalReflection = false;
};

// cosTheta_i in [0, 1], measured in medium n1 (real, > 0).
FresnelAmplitudes fresnelAmplitudes(double cosTheta_i, double n1, Complex n2);

// Unpolarised power reflectance (|rs|² + |rp|²)/2.
double fresnelReflectance(double cosTheta_i, double n1, Complex n2);

// Perfect conductor (kappa → ∞): rs = −1, rp = +1, reflectance 1.
FresnelAmplitudes perfectConductorAmplitudes();

}  // namespace mbsdf
