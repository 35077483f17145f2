// Texture parameters against the closed forms of a sampled sine z = A sin(2π i / M) (M samples per
// period, whole periods on the grid): Sq = A/√2, Sa = A (2/M) cot(π/M), Ssk = 0, Sku = 3/2,
// Sdq = √2 A sin(π/M) / dx (forward differences), Sal = the first lag m with cos(2π m/M) <= 0.2;
// its seam; the seam of a ramp, and the slopes of a plane.
#include <gtest/gtest.h>

#include <cmath>

#include "geometry/topography_stats.h"

namespace mbsdf {
namespace {

TEST(TopographyStats, SampledSineClosedForms) {
  const int M = 40, periods = 3, nx = M * periods, ny = 16;
  const double A = 0.07, dx = 0.05, dy = 0.08;
  Topography t;
  t.nx = nx;
  t.ny = ny;
  t.dx_um = dx;
  t.dy_um = dy;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) t.z_um.push_back(A * std::sin(2 * M_PI * i / M));
  const TopographyStats s = topographyStats(t);
  EXPECT_NEAR(s.Sq_um, A / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(s.Sa_um, A * 2.0 / M / std::tan(M_PI / M), 1e-12);
  EXPECT_NEAR(s.Ssk, 0, 1e-9);
  EXPECT_NEAR(s.Sku, 1.5, 1e-9);
  EXPECT_NEAR(s.Sdq, std::sqrt(2.0) * A * std::sin(M_PI / M) / dx, 1e-9);
  EXPECT_NEAR(s.Sz_um, 2 * A, 1e-12);
  int m = 0;
  while (std::cos(2 * M_PI * m / M) > 0.2) ++m;
  EXPECT_NEAR(s.Sal_um, m * dx, 1e-12);
  // The seam of a periodic sine: the step there, 2A cos(π/M) sin(π/M), over the rms of the other
  // nx − 1 steps of a row (all nx steps have mean square 2A² sin²(π/M)).
  const double c2 = std::cos(M_PI / M) * std::cos(M_PI / M);
  EXPECT_NEAR(s.seamRatioX, std::sqrt(2 * c2 * (nx - 1) / (nx - 2 * c2)), 1e-9);
  EXPECT_FALSE(s.seamStands());
}

TEST(TopographyStats, RampSeamAndPlaneSlopes) {
  const int n = 32;
  const double slope = 0.2;
  Topography t;
  t.nx = t.ny = n;
  t.dx_um = t.dy_um = 0.5;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) t.z_um.push_back(slope * i * t.dx_um);
  const TopographyStats s = topographyStats(t);
  EXPECT_NEAR(s.seamRatioX, n - 1, 1e-9);  // the wrap falls by (n − 1) steps at once
  EXPECT_EQ(s.seamRatioY, 1.0);            // no steps in y at all
  EXPECT_TRUE(s.seamStands());
  // Every texel of a plane (but the seam column) has the plane's inclination.
  EXPECT_NEAR(s.slope_deg[0], std::atan(slope) * 180 / M_PI, 1e-9);
  EXPECT_NEAR(s.slope_deg[1], std::atan(slope) * 180 / M_PI, 1e-9);
}

}  // namespace
}  // namespace mbsdf
