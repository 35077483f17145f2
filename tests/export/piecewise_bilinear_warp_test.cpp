// The warp of an RGL file's vndf and luminance fields against its definition: the density is the
// bilinear interpolant of the grid normalised to 1, sample() and invert() are inverse maps, and
// samples distribute as the density (a χ² test on the patches with the estimator's own variance).
#include "export/piecewise_bilinear_warp.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace mbsdf {
namespace {

std::vector<float> testGrid(int nx, int ny) {
  std::vector<float> v;
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x < nx; ++x)
      v.push_back(float(0.2 + std::exp(-0.5 * ((x - 2.3) * (x - 2.3) + (y - 1.1) * (y - 1.1))) * (x != 4)));
  return v;
}

TEST(PiecewiseBilinearWarp, DensityIsTheNormalisedBilinearInterpolant) {
  const int nx = 7, ny = 5;
  const std::vector<float> values = testGrid(nx, ny);
  const std::vector<double> grid(values.begin(), values.end());
  const PiecewiseBilinearWarp w(values, nx, ny);
  // The integral of the bilinear interpolant: each patch holds the mean of its four corners.
  double integral = 0;
  for (int y = 0; y + 1 < ny; ++y)
    for (int x = 0; x + 1 < nx; ++x)
      integral += 0.25 *
                  (grid[y * nx + x] + grid[y * nx + x + 1] + grid[(y + 1) * nx + x] + grid[(y + 1) * nx + x + 1]) /
                  ((nx - 1) * (ny - 1));
  for (double x : {0.0, 0.13, 0.5, 0.77, 1.0})
    for (double y : {0.0, 0.31, 0.6, 1.0}) {
      const double px = x * (nx - 1), py = y * (ny - 1);
      const int i = std::min(int(px), nx - 2), j = std::min(int(py), ny - 2);
      const double tx = px - i, ty = py - j;
      const double bilinear = (1 - ty) * ((1 - tx) * grid[j * nx + i] + tx * grid[j * nx + i + 1]) +
                              ty * ((1 - tx) * grid[(j + 1) * nx + i] + tx * grid[(j + 1) * nx + i + 1]);
      EXPECT_NEAR(w.pdf(x, y), bilinear / integral, 1e-12) << x << "," << y;
    }
}

TEST(PiecewiseBilinearWarp, SampleAndInvertAreInverseMaps) {
  const PiecewiseBilinearWarp w(testGrid(9, 6), 9, 6);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.001, 0.999);
  for (int n = 0; n < 2000; ++n) {
    const double a = u(rng), b = u(rng);
    const WarpSample p = w.sample(a, b);
    const WarpSample back = w.invert(p.x, p.y);
    ASSERT_NEAR(back.x, a, 1e-9) << a << "," << b;
    ASSERT_NEAR(back.y, b, 1e-9) << a << "," << b;
    ASSERT_NEAR(back.pdf, p.pdf, 1e-9 * p.pdf);
  }
}

TEST(PiecewiseBilinearWarp, SamplesDistributeAsTheDensity) {
  const int nx = 7, ny = 5, n = 200000, cellsX = 12, cellsY = 8;
  const PiecewiseBilinearWarp w(testGrid(nx, ny), nx, ny);
  std::vector<double> count(cellsX * cellsY, 0.0), expected(cellsX * cellsY, 0.0);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int k = 0; k < n; ++k) {
    const WarpSample p = w.sample(u(rng), u(rng));
    count[std::min(int(p.y * cellsY), cellsY - 1) * cellsX + std::min(int(p.x * cellsX), cellsX - 1)] += 1;
  }
  const int q = 16;  // midpoint rule inside each cell
  for (int c = 0; c < cellsX * cellsY; ++c)
    for (int a = 0; a < q; ++a)
      for (int b = 0; b < q; ++b)
        expected[c] += w.pdf(((c % cellsX) + (a + 0.5) / q) / cellsX, ((c / cellsX) + (b + 0.5) / q) / cellsY) /
                       (q * q * cellsX * cellsY) * n;
  double chi2 = 0;
  for (int c = 0; c < cellsX * cellsY; ++c) chi2 += (count[c] - expected[c]) * (count[c] - expected[c]) / expected[c];
  // 95 dof: the 1e-6 upper quantile of χ² is about 180.
  EXPECT_LT(chi2, 180.0);
}

TEST(PiecewiseBilinearWarp, RefusesAGridWithoutMass) {
  EXPECT_THROW(PiecewiseBilinearWarp(std::vector<float>(6, 0.0f), 3, 2), std::invalid_argument);
  EXPECT_THROW(PiecewiseBilinearWarp(std::vector<float>(3, 1.0f), 3, 1), std::invalid_argument);
}

}  // namespace
}  // namespace mbsdf
