// Chandrasekhar's H function for isotropic scattering and the reflectance of a semi-infinite
// isotropically scattering medium (Chandrasekhar, "Radiative Transfer", 1960, Ch. IV–V).
// Source: the closed form quoted by Dupuy, Heitz & d'Eon 2016 (Dupuy et al. 2016, Eq. 31, after
// Stibbs & Weir 1959):
//   H(u) = exp( −(u/π) ∫_0^{π/2} log(1 − a t cot t) / (u² sin² t + cos² t) dt ).
// docs/physics.md §9. Used as the reference for the microflake walk with the constant full-sphere NDF.
#pragma once

namespace mbsdf {

// H(u) for single-scattering albedo a ∈ [0, 1] and u = cos θ ∈ [0, 1]. Accurate to ~1e-12 for
// every a including the conservative case a = 1, where the integrand is log-singular at t = 0.
double chandrasekharH(double u, double a);

// Single-scattering BRDF of the medium, Dupuy et al. 2016, Eq. 25: a / (4π (μi + μo)).
double isotropicMediumSingleBRDF(double mu_i, double mu_o, double a);
// Full BRDF, Dupuy et al. 2016, Eq. 30: (a/4π) H(μi) H(μo) / (μi + μo).
double isotropicMediumBRDF(double mu_i, double mu_o, double a);

}  // namespace mbsdf
