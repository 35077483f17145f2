// The coherence length of a disk source (van Cittert–Zernike, coherence_window.h) against an
// independent quadrature of the coherence area of γ(d) = 2 J1(v)/v.
#include <gtest/gtest.h>

#include <cmath>

#include "core/quadrature.h"
#include "core/vecmath.h"
#include "scattering/coherence_window.h"

using namespace mbsdf;

// ∫ |γ(d)|² 2π d dd for a source of angular diameter θ, by Gauss–Legendre over v (with the
// analytic tail 4/(π V) of ∫_V^∞ (2J1(v)/v)² v dv, J1² ≈ 2 cos²(...)/(π v) averaged), equals the
// window's 2πσ² for σ = δc/6.
TEST(CoherenceLength, DiskSourceMatchesCoherenceArea) {
  const double V = 4000.0;
  double integral = 0;  // ∫_0^V (2 J1(v)/v)² v dv in 4000 unit panels
  const QuadratureRule unit = gaussLegendre(16, 0.0, 1.0);
  for (int k = 0; k < int(V); ++k)
    for (size_t q = 0; q < unit.x.size(); ++q) {
      const double v = k + unit.x[q], g = 2 * std::cyl_bessel_j(1.0, v) / v;
      integral += unit.w[q] * g * g * v;
    }
  integral += 4 / (kPi * V);
  for (double theta_deg : {0.1, 0.533, 2.0}) {
    for (double lambda_um : {0.4, 0.55, 0.7}) {
      const double theta = radians(theta_deg);
      // d = v λ / (π θ): area = 2π (λ/(πθ))² ∫ |γ|² v dv.
      const double area = 2 * kPi * std::pow(lambda_um / (kPi * theta), 2) * integral;
      const double sigma = coherenceLengthOfDiskSource(theta, lambda_um) / 6.0;
      EXPECT_NEAR(2 * kPi * sigma * sigma / area, 1.0, 1e-4) << theta_deg << " deg, " << lambda_um << " um";
    }
  }
  // The sun at 550 nm.
  EXPECT_NEAR(coherenceLengthOfDiskSource(radians(kSunAngularDiameter_deg), 0.55), 159.7, 0.1);
}
