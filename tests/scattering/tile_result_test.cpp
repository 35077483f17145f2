// The L1 measure of a slice (sliceL1): its parts are the closed-form sums, and for normal bin
// errors the deviation it predicts is the mean of the L1 distance a noisy table actually has.
#include "scattering/tile_result.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "core/direction_grid.h"

using namespace mbsdf;

TEST(TileResult, SliceL1SumsTheBinsWeightedByProjectedSolidAngle) {
  const DirectionGrid grid(ThetaPhiGrid{3, 4});
  const int nB = grid.binCount(), nL = 2;
  std::vector<double> f(size_t(nL) * nB), err(f.size());
  double dev[2] = {0, 0}, mass[2] = {0, 0};
  for (int l = 0; l < nL; ++l)
    for (int b = 0; b < nB; ++b) {
      const size_t i = size_t(l) * nB + size_t(b);
      f[i] = (b % 3 == 0 ? -1.0 : 1.0) * (0.1 + 0.05 * b + l);  // signed, as `incoherent` is
      err[i] = 0.01 * (1 + b % 5);
      dev[l] += 0.5 * err[i] * grid.projectedSolidAngle(b);
      mass[l] += std::abs(f[i]) * grid.projectedSolidAngle(b);
    }
  // A bin that was not computed (NaN) counts for nothing.
  f[3] = std::numeric_limits<double>::quiet_NaN();
  dev[0] -= 0.5 * err[3] * grid.projectedSolidAngle(3);
  mass[0] -= (0.1 + 0.05 * 3) * grid.projectedSolidAngle(3);
  const SliceL1 s = sliceL1(f, err, nL, grid, 0.5);
  for (int l = 0; l < nL; ++l) {
    EXPECT_NEAR(s.deviation[size_t(l)], dev[l], 1e-15);
    EXPECT_NEAR(s.mass[size_t(l)], mass[l], 1e-14);
  }
  EXPECT_THROW(sliceL1(f, std::vector<double>(3), nL, grid, 1.0), std::logic_error);
}

// Tables drawn as f + σ Z with normal Z: the mean over draws of Σ|f̂ − f| Ω⊥ / Σ|f| Ω⊥ is
// sliceL1's deviation / mass with errorFactor √(2/π), within 4 standard errors of that mean.
TEST(TileResult, SliceL1PredictsTheL1DistanceOfNormalNoise) {
  const DirectionGrid grid(ThetaPhiGrid{10, 20});
  const int nB = grid.binCount();
  std::vector<double> f(static_cast<size_t>(nB)), err(f.size());
  for (int b = 0; b < nB; ++b) {
    f[size_t(b)] = 1.0 + std::sin(0.37 * b);
    err[size_t(b)] = 0.05 * (1 + b % 7);
  }
  const SliceL1 s = sliceL1(f, err, 1, grid, kMeanAbsPerSigma);
  const double predicted = s.deviation[0] / s.mass[0];
  std::mt19937_64 rng(11);
  std::normal_distribution<double> z;
  const int draws = 2000;
  double sum = 0, sum2 = 0;
  for (int k = 0; k < draws; ++k) {
    double d = 0;
    for (int b = 0; b < nB; ++b) d += std::abs(err[size_t(b)] * z(rng)) * grid.projectedSolidAngle(b);
    d /= s.mass[0];
    sum += d;
    sum2 += d * d;
  }
  const double mean = sum / draws, se = std::sqrt((sum2 / draws - mean * mean) / (draws - 1));
  EXPECT_NEAR(mean, predicted, 4 * se) << "predicted " << predicted << ", mean " << mean << " ± " << se;
}
