// Deterministic quadrature rules used for analytic references and tables.
//  - Gauss–Legendre nodes (Golub–Welsch-free Newton iteration on P_n, Numerical Recipes §4.6).
//  - Tanh–sinh (double-exponential) quadrature (Takahasi & Mori 1974; Bailey, "Tanh-sinh
//    high-precision quadrature", 2006): converges exponentially even with integrable endpoint
//    singularities such as the log singularity of Chandrasekhar's H integrand (docs/physics.md §9).
#pragma once
#include <functional>
#include <vector>

namespace mbsdf {

struct QuadratureRule {
  std::vector<double> x, w;  // nodes and weights on [a, b]
};

// n-point Gauss–Legendre rule on [a, b] (exact for polynomials of degree 2n − 1).
QuadratureRule gaussLegendre(int n, double a = -1.0, double b = 1.0);

// The n-point Gauss–Legendre rule repeated over `cells` equal cells of [0, 1] (composite rule).
QuadratureRule compositeGaussLegendre(int n, int cells);

// ∫_a^b f(x) dx by tanh–sinh, halving the step until two levels agree to `relTol` (or level 12).
// f is never evaluated at the endpoints; it receives (x, distance to the nearer endpoint) so that
// an integrand with a singular endpoint can be evaluated without cancellation near it.
double tanhSinh(const std::function<double(double x, double fromEnd)>& f, double a, double b, double relTol = 1e-13,
                double* errorEstimate = nullptr);

}  // namespace mbsdf
