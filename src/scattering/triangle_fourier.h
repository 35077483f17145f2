// The Fourier integral of a flat triangle, ∫_T e^{i q·x} dA, in closed form: the phase of the Kirchhoff integrand
// (docs/physics.md §5) is linear over a flat facet, so over a fully visible facet under a constant window the integral
// is exact.
//
// With x = a + u e1 + v e2 (e1 = b − a, e2 = c − a; u, v >= 0, u + v <= 1), dA = 2A du dv:
//   ∫_T e^{i q·x} dA = 2A e^{i q·a} F(q·e1, q·e2),   F(α, β) = ∫∫ e^{i(αu + βv)} du dv,
// and F is minus the second divided difference of e^{ix} at the nodes 0, α, β (Hermite–Genocchi):
//   F(α, β) = −e^{ix}[0, α, β].
// Evaluated without cancellation in every regime:
//   - nodes spread < 1: the Taylor series about their mean c,
//       e^{ix}[x0, x1, x2] = e^{ic} Σ_{k>=2} i^k / k! · h_{k−2}(x0 − c, x1 − c, x2 − c),
//     h_m the complete homogeneous symmetric polynomial (|x_j − c| < 1: terms fall as 3^m/k!);
//   - otherwise with the extreme nodes x0 < x2 apart by >= 1:
//       e^{ix}[x0, x1, x2] = (e^{ix}[x1, x2] − e^{ix}[x0, x1]) / (x2 − x0),
//     each first difference as e^{ix}[a, b] = i e^{i(a+b)/2} sinc((b − a)/2) (exact, no 1 − cos).
// A degenerate triangle (zero area) gives 0.
#pragma once
#include <complex>

#include "core/vecmath.h"

namespace mbsdf {

// F(α, β) = ∫_0^1 ∫_0^{1−u} e^{i(αu + βv)} dv du (F(0, 0) = 1/2).
std::complex<double> triangleUnitFourier(double alpha, double beta);

// ∫_T e^{i q·x} dA over the triangle (a, b, c), q in 1/µm, lengths in µm.
std::complex<double> triangleFourier(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& q);

}  // namespace mbsdf
