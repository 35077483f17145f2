// The Kirchhoff ensemble of a Gaussian surface (scattering/kirchhoff_ensemble.h) against closed
// forms and conservation: the series' exponential-integral identity, its geometric-optics limit,
// the energy of the coherent and diffuse parts, the geometric table against a direct quadrature of
// the Beckmann BRDF, and a flat mirror's windowed specular against the Rayleigh distribution.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/direction_grid.h"
#include "core/quadrature.h"
#include "core/vecmath.h"
#include "scattering/kirchhoff_ensemble.h"

using namespace mbsdf;

namespace {

std::vector<int> identityCells(const DirectionGrid& grid) {
  std::vector<int> c(size_t(grid.binCount()));
  std::iota(c.begin(), c.end(), 0);
  return c;
}

double sum(const std::vector<double>& v) {
  return std::accumulate(v.begin(), v.end(), 0.0);
}

const auto mirror = [](double) { return 1.0; };

}  // namespace

// Σ_{m≥1} g^m / (m! m) = Ein(g) = Ei(g) − γ − ln g (Abramowitz & Stegun 5.1.10), so the series at
// X = 0 is g e^{−g} (Ei(g) − γ − ln g).
TEST(KirchhoffEnsemble, SeriesIsTheExponentialIntegralAtTheLobesCentre) {
  constexpr double eulerGamma = 0.57721566490153286;
  for (double g : {1e-6, 1e-3, 0.1, 1.0, 4.5, 30.0, 300.0}) {
    const double expected = g * std::exp(-g) * (std::expint(g) - eulerGamma - std::log(g));
    // (the reference cancels to about 1e-10 relative at g = 1e-6)
    EXPECT_NEAR(kirchhoffDiffuseSeries(g, 0.0) / expected, 1.0, 1e-8) << "g = " << g;
  }
}

// g → ∞: the series tends to the geometric-optics lobe e^{−X/g}, with a relative difference that
// falls as 1/g (the Poisson weights' spread about m = g).
TEST(KirchhoffEnsemble, SeriesTendsToGeometricOptics) {
  for (double t2 : {0.0, 1.0, 4.0}) {  // tan² θh / α² = X / g
    double previous = 1e300;
    for (double g : {10.0, 100.0, 1000.0, 5000.0}) {
      const double diff = std::abs(kirchhoffDiffuseSeries(g, t2 * g) / std::exp(-t2) - 1.0);
      EXPECT_LT(diff, 10.0 / g) << "g " << g << ", X/g " << t2;
      EXPECT_LT(diff, previous) << "g " << g << ", X/g " << t2;
      previous = diff;
    }
  }
}

// A perfect mirror of small slopes: the ensemble's coherent part carries e^{−g} of the energy and
// its diffuse part the rest, 1 − e^{−g} (the total integrated scatter), for every Rayleigh g, and
// geometric optics all of it (shadowing is negligible at α = 0.05 near the normal).
TEST(KirchhoffEnsemble, CoherentAndDiffusePartsConserveEnergy) {
  const DirectionGrid grid(ThetaPhiGrid{90, 180});
  const std::vector<int> cells = identityCells(grid);
  const double lambda = 0.5, alpha = 0.05;
  for (double theta_deg : {0.0, 30.0}) {
    const Vec3 wi = sphericalDirection(radians(theta_deg), 0.3);
    for (double g : {0.01, 0.3, 1.0, 3.0, 30.0}) {
      const double sigma = std::sqrt(g) / (2 * (2 * kPi / lambda) * wi.z);
      const KirchhoffEnsemble e(sigma, alpha, 0.0);
      const EnsembleSlice s = e.slice(grid, {{wi, 1.0}}, lambda, 1.0, mirror, cells, grid.binCount());
      EXPECT_NEAR(sum(s.coherent), std::exp(-g), 1e-9) << theta_deg << " deg, g " << g;
      EXPECT_NEAR(sum(s.diffuse), 1 - std::exp(-g), 0.01) << theta_deg << " deg, g " << g;
      EXPECT_NEAR(sum(s.geometric), 1.0, 0.01) << theta_deg << " deg, g " << g;
    }
  }
}

// The geometric table is the Beckmann microfacet BRDF D G1 G1 / (4 cos θi cos θo) (R = 1)
// integrated over each bin: against a 24 x 24 midpoint quadrature of it per bin, bin by bin.
TEST(KirchhoffEnsemble, GeometricTableIsTheBeckmannBrdfPerBin) {
  const DirectionGrid grid(ThetaPhiGrid{9, 18});
  const std::vector<int> cells = identityCells(grid);
  const double alpha = 0.4;
  const Vec3 wi = sphericalDirection(radians(40.0), radians(10.0));
  const KirchhoffEnsemble e(1.0, alpha, 0.0);
  const EnsembleSlice s = e.slice(grid, {{wi, 1.0}}, 0.5, 1.0, mirror, cells, grid.binCount());
  auto g1 = [&](double c) {
    const double a = c / (alpha * std::sqrt(1 - c * c));
    return 1 / (1 + 0.5 * (std::erf(a) - 1) + std::exp(-a * a) / (2 * a * std::sqrt(kPi)));
  };
  double worst = 0, total = 0;
  for (int it = 0; it < 9; ++it)
    for (int ip = 0; ip < 18; ++ip) {
      const int n = 24;
      double e_bin = 0;
      const double dt = kPi / 2 / 9 / n, dp = 2 * kPi / 18 / n;
      for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) {
          const double t = (it * n + a + 0.5) * dt, p = (ip * n + b + 0.5) * dp;
          const Vec3 wo = sphericalDirection(t, p);
          const Vec3 h = normalize(wi + wo);
          const double tan2 = (h.x * h.x + h.y * h.y) / (h.z * h.z);
          const double D = std::exp(-tan2 / (alpha * alpha)) / (kPi * alpha * alpha * std::pow(h.z, 4));
          e_bin += D * g1(wi.z) * g1(wo.z) / (4 * wi.z * wo.z) * wo.z * std::sin(t) * dt * dp;
        }
      const int bin = grid.binOf(sphericalDirection((it + 0.5) * kPi / 2 / 9, (ip + 0.5) * 2 * kPi / 18));
      worst = std::max(worst, std::abs(s.geometric[size_t(bin)] - e_bin));
      total += e_bin;
    }
  EXPECT_LT(worst, 0.01 * total) << "largest per-bin difference";
  EXPECT_NEAR(sum(s.geometric), total, 0.01 * total);
}

// A flat mirror under a window of σ_w: the coherent part is the specular direction blurred by a
// Gaussian of 1/(√2 σ_w k) per axis in the xy plane, so at normal incidence the energy within
// sin θ < s is the Rayleigh distribution 1 − exp(−s² / (2 b²)); geometric optics puts everything
// in the specular bin, and the L1 distance is twice what the coherent part puts elsewhere.
TEST(KirchhoffEnsemble, FlatMirrorsWindowedSpecularIsRayleighDistributed) {
  const DirectionGrid grid(ThetaPhiGrid{90, 8});
  const std::vector<int> cells = identityCells(grid);
  const double lambda = 0.5, sigmaW = 2.0;
  const double b = 1 / (std::sqrt(2.0) * sigmaW * 2 * kPi / lambda);
  const KirchhoffEnsemble e(0.0, 0.0, sigmaW);
  const EnsembleSlice s = e.slice(grid, {{Vec3{0, 0, 1}, 1.0}}, lambda, 1.0, mirror, cells, grid.binCount());
  double inside = 0;
  for (int ring = 0; ring < 3; ++ring) {
    for (int ip = 0; ip < 8; ++ip)
      inside += s.coherent[size_t(grid.binOf(sphericalDirection((ring + 0.5) * kPi / 180, (ip + 0.5) * kPi / 4)))];
    const double sMax = std::sin((ring + 1) * kPi / 2 / 90);
    EXPECT_NEAR(inside, 1 - std::exp(-sMax * sMax / (2 * b * b)), 0.02) << "within ring " << ring;
  }
  const auto specularBin = std::max_element(s.geometric.begin(), s.geometric.end()) - s.geometric.begin();
  EXPECT_DOUBLE_EQ(s.geometric[size_t(specularBin)], 1.0);
  const double specular = s.coherent[size_t(specularBin)];
  EXPECT_NEAR(s.l1(), 2 * (1 - specular), 1e-12);
}
