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

// planeIntegral (Faddeeva closed form) against Gauss–Legendre quadrature of what it stands for,
// ∫_patch copyFactor(x, y, q) e^{i q·x} dA, for a window narrower and wider than the patch, on
// a periodic patch and a single one, at q from the specular to far off it.
TEST(CoherenceWindow, PlaneIntegralMatchesQuadratureOfTheCopySum) {
  struct Case {
    double sigma, L;
    bool periodic;
  };
  for (const Case& c : {Case{8.3, 4.0, true}, Case{1.5, 6.0, true}, Case{2.0, 5.0, false}, Case{0.0, 3.0, true}}) {
    const CoherenceWindow w(c.sigma, c.L, 0.5 * c.L, c.periodic);
    for (double qx : {0.0, 0.05, 0.4, 3.0, 17.0})
      for (double qy : {0.0, 1.1}) {
        const int panels = 160;
        const QuadratureRule unit = gaussLegendre(12, 0.0, 1.0);
        const double Ly = 0.5 * c.L;
        Complex sum = 0;
        for (int i = 0; i < panels; ++i)
          for (size_t a = 0; a < unit.x.size(); ++a) {
            const double x = -0.5 * c.L + (i + unit.x[a]) * c.L / panels;
            for (int j = 0; j < panels / 4; ++j)
              for (size_t b = 0; b < unit.x.size(); ++b) {
                const double y = -0.5 * Ly + (j + unit.x[b]) * Ly / (panels / 4);
                sum += unit.w[a] * unit.w[b] * (c.L / panels) * (Ly / (panels / 4)) * w.copyFactor(x, y, qx, qy) *
                       std::polar(1.0, qx * x + qy * y);
              }
          }
        const double scale = std::max(1e-12, std::abs(w.planeIntegral(0, 0)));
        EXPECT_NEAR(sum.real(), w.planeIntegral(qx, qy), 1e-9 * scale)
            << c.sigma << " " << c.L << " " << qx << " " << qy;
        EXPECT_NEAR(sum.imag(), 0.0, 1e-9 * scale);
      }
  }
}
