// Helpers for the microflake tests: analytic references averaged over grid bins, and z-scores.
#pragma once
#include <cmath>
#include <functional>

#include "core/direction_grid.h"
#include "core/quadrature.h"
#include "microflake/ndf.h"

namespace mbsdf::test {

// Cosine-weighted average of f(wo) over a bin — what the Monte Carlo estimator estimates
// (docs/physics.md §3) — by a 24 x 24 stratified midpoint rule on the bin's cosine-distributed map.
inline double binAverage(const DirectionGrid& grid, int bin, const std::function<double(const Vec3&)>& f) {
  const int n = 24;
  double sum = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) sum += f(grid.sampleCosine(bin, (i + 0.5) / n, (j + 0.5) / n).w);
  return sum / (n * n);
}

// ∫_{S²} g(m) dm by composite Gauss–Legendre in (cos θ, φ); `upperOnly` restricts to m_z > 0.
inline double sphereIntegral(const std::function<double(const Vec3&)>& g, bool upperOnly, int panels = 256) {
  QuadratureRule q = gaussLegendre(6, 0.0, 1.0);
  double sum = 0;
  const double z0 = upperOnly ? 0.0 : -1.0, dz = (1.0 - z0) / panels, dphi = 2 * kPi / panels;
  for (int a = 0; a < panels; ++a)
    for (size_t i = 0; i < q.x.size(); ++i) {
      const double z = z0 + dz * (a + q.x[i]), s = std::sqrt(std::max(0.0, 1 - z * z));
      for (int b = 0; b < panels; ++b)
        for (size_t j = 0; j < q.x.size(); ++j) {
          const double phi = dphi * (b + q.x[j]);
          sum += q.w[i] * q.w[j] * dz * dphi * g({s * std::cos(phi), s * std::sin(phi), z});
        }
    }
  return sum;
}

}  // namespace mbsdf::test
