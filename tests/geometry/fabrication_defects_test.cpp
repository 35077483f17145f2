// Fabrication defects against closed forms and the laws of morphology: a ridge opened by a ball of
// radius r loses r²(1 − π/4) per top corner (a quarter circle), closing fills the same at each foot;
// opened by a cone of slope s it loses H²/s (a trapezoid with the same base), its walls exactly s
// along the axes; openings are anti-extensive and idempotent, closings extensive and idempotent; a
// surface smoother than the ball is left as it is; the raster of a generated grating holds its heights.
#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "geometry/fabrication_defects.h"
#include "geometry/generators.h"

namespace mbsdf {
namespace {

// Ridges along y: height H for x in [x0, x0 + W), 0 elsewhere, nx x 4 texels.
Topography ridge(int nx, double dx, double H, double x0, double W) {
  Topography t;
  t.nx = nx;
  t.ny = 4;
  t.dx_um = t.dy_um = dx;
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < nx; ++i) t.z_um.push_back(i * dx >= x0 && i * dx < x0 + W ? H : 0.0);
  return t;
}

double crossSection(const Topography& t) {  // ∫ z dx of the first row
  double a = 0;
  for (int i = 0; i < t.nx; ++i) a += t.z_um[i] * t.dx_um;
  return a;
}

TEST(FabricationDefects, BallRoundsCornersToQuarterCircles) {
  const double dx = 0.002, H = 0.3, r = 0.1;
  Topography t = ridge(1000, dx, H, 0.5, 1.0);
  const double before = crossSection(t);
  Topography opened = t;
  openWithBall(opened, r);
  for (size_t k = 0; k < t.size(); ++k) ASSERT_LE(opened.z_um[k], t.z_um[k] + 1e-15);  // anti-extensive
  EXPECT_NEAR(before - crossSection(opened), 2 * r * r * (1 - M_PI / 4), 2 * r * dx);
  // The quarter circle itself, away from the wall's texel: z = H − r + √(r² − (r − u)²), u from the edge.
  for (int i = 0; i < 1000; ++i) {
    const double u = (0.5 + 1.0 - dx) - i * dx;  // distance to the last ridge texel
    if (u > 2 * dx && u < r) {
      EXPECT_NEAR(opened.z_um[i], H - r + std::sqrt(r * r - (r - u) * (r - u)), 0.02 * r) << u;
    }
  }
  Topography twice = opened;
  openWithBall(twice, r);
  for (size_t k = 0; k < t.size(); ++k) ASSERT_NEAR(twice.z_um[k], opened.z_um[k], 1e-12);  // idempotent
  Topography closed = t;
  closeWithBall(closed, r);
  for (size_t k = 0; k < t.size(); ++k) ASSERT_GE(closed.z_um[k], t.z_um[k] - 1e-15);  // extensive
  EXPECT_NEAR(crossSection(closed) - before, 2 * r * r * (1 - M_PI / 4), 2 * r * dx);
}

TEST(FabricationDefects, ConeTapersWallsKeepingTheBase) {
  const double dx = 0.002, H = 0.2, s = std::tan(80 * M_PI / 180);
  Topography t = ridge(1000, dx, H, 0.5, 1.0);
  const double before = crossSection(t);
  openWithCone(t, s);
  EXPECT_NEAR(before - crossSection(t), H * H / s, 2 * H * dx);
  double steepest = 0;
  for (int i = 0; i + 1 < t.nx; ++i) steepest = std::max(steepest, std::abs(t.z_um[i + 1] - t.z_um[i]) / dx);
  EXPECT_LE(steepest, s * (1 + 1e-12));
  EXPECT_GT(steepest, 0.99 * s);
  EXPECT_NEAR(t.z_um[int(1.0 / dx)], H, 1e-12);  // the middle of the top is kept
}

TEST(FabricationDefects, SmoothSurfaceIsLeftAlone) {
  // A sine whose smallest radius of curvature 1/(A k²) = 0.5 µm is five times the ball's radius.
  Topography t;
  t.nx = 400;
  t.ny = 4;
  t.dx_um = t.dy_um = 0.005;
  const double k = 2 * M_PI / 2.0, A = 1 / (0.5 * k * k);
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) t.z_um.push_back(A * std::sin(k * i * t.dx_um));
  Topography o = t;
  openWithBall(o, 0.1);
  closeWithBall(o, 0.1);
  double worst = 0;
  for (size_t q = 0; q < t.size(); ++q) worst = std::max(worst, std::abs(o.z_um[q] - t.z_um[q]));
  EXPECT_LT(worst, 1e-3 * A);  // the ball's discretisation only
}

TEST(FabricationDefects, RasterOfAGeneratedGratingAndDepthScale) {
  Microgeometry g = makeBinaryGrating(4.0, 4.0, 2.0, 0.2, 0.5, 0.05);
  Topography t = rasteriseHeights(g, 0.05, "test");
  ASSERT_EQ(t.nx, 80);
  ASSERT_EQ(t.ny, 80);
  double lo = 1e300, hi = -1e300;
  for (double z : t.z_um) lo = std::min(lo, z), hi = std::max(hi, z);
  EXPECT_NEAR(hi - lo, 0.2, 1e-9);
  FabricationDefects d;
  d.depthScale = 0.95;
  applyFabricationDefects(t, d, "test");
  double lo2 = 1e300, hi2 = -1e300;
  for (double z : t.z_um) lo2 = std::min(lo2, z), hi2 = std::max(hi2, z);
  EXPECT_NEAR(hi2 - lo2, 0.19, 1e-9);
  EXPECT_NEAR(lo2, lo, 1e-15);
  d.depthScale = 1;
  d.edgeRadius_um = 0.01;  // below the texel: refused, not silently ignored
  EXPECT_THROW(applyFabricationDefects(t, d, "test"), InputError);
}

}  // namespace
}  // namespace mbsdf
