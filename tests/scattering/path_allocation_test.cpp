// The allocation of paths per slice for pairs stored once (scattering/path_allocation.h): the
// property that defines it, checked bin by bin with no grouping (every slice's predicted folded L1
// equal), its figures on the paper's grid, and what it gives where the fold cannot help.
#include "scattering/path_allocation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "scattering/reciprocity.h"

namespace mbsdf {
namespace {

std::vector<int> upperBins(const DirectionGrid& grid) {
  std::vector<int> bins(size_t(grid.binsPerHemisphere()));
  std::iota(bins.begin(), bins.end(), 0);
  return bins;
}

// The predicted L1 of slice i's folded table, for a table constant over the exit bins, up to a
// common factor: Σ_o σ_io Ω⊥(o) / Σ_o Ω⊥(o) with σ_io² = w_io / (N_i Ω⊥(o)) and w_io the writer's
// weight (reciprocalPairWeight with the slices' paths) where o is another incidence bin of i's side.
double predictedL1(const DirectionGrid& grid, const std::vector<int>& bins, const std::vector<double>& paths, size_t i,
                   bool transmits) {
  double num = 0, den = 0;
  std::vector<int> incidenceOf(size_t(grid.binCount()), -1);
  for (size_t j = 0; j < bins.size(); ++j) incidenceOf[size_t(bins[j])] = int(j);
  for (int o = 0; o < grid.binCount(); ++o) {
    const double omega = grid.projectedSolidAngle(o);
    const bool sameSide = grid.isUpper(o) == grid.isUpper(bins[i]);
    if (!(omega > 0) || (!sameSide && !transmits)) continue;
    const int j = incidenceOf[size_t(o)];
    const double w = sameSide && j >= 0 && size_t(j) != i
                         ? reciprocalPairWeight(grid, o, bins[i], paths[size_t(j)] / paths[i])
                         : 1.0;
    num += std::sqrt(w / (paths[i] * omega)) * omega;
    den += omega;
  }
  return num / den;
}

TEST(PathAllocation, EverySlicesPredictedFoldedErrorIsTheSame) {
  // A small theta-phi grid, bin by bin: the shares make the predicted L1 equal to 1e-6 over all
  // slices, where with the same paths everywhere they differ by a third.
  for (bool transmits : {false, true}) {
    const DirectionGrid grid(ThetaPhiGrid{6, 12});
    const std::vector<int> bins = upperBins(grid);
    const std::vector<double> share = equalErrorPathShares(grid, bins, transmits);
    const std::vector<double> uniform(bins.size(), 1.0);
    double lo = 1e300, hi = 0, uLo = 1e300, uHi = 0;
    for (size_t i = 0; i < bins.size(); ++i) {
      const double e = predictedL1(grid, bins, share, i, transmits), u = predictedL1(grid, bins, uniform, i, transmits);
      lo = std::min(lo, e), hi = std::max(hi, e), uLo = std::min(uLo, u), uHi = std::max(uHi, u);
    }
    EXPECT_LT(hi / lo - 1, 1e-6) << transmits;
    EXPECT_GT(uHi / uLo - 1, transmits ? 0.05 : 0.2) << transmits;
    // The largest share is exactly 1, the slice the fold helps least keeps its error: the worst
    // predicted error is the uniform allocation's worst within a few per cent (its partners have fewer paths).
    EXPECT_EQ(*std::max_element(share.begin(), share.end()), 1.0);
    EXPECT_NEAR(hi / uHi, 1.0, 0.05) << transmits;
  }
}

TEST(PathAllocation, PaperGridFigures) {
  // 75 x 300 bins: the pole and horizon rings keep every path, the 45° ring about a third, the mean
  // 0.55 (docs/accuracy.md); every bin of a ring alike.
  const DirectionGrid grid(ThetaPhiGrid{75, 300});
  const std::vector<int> bins = upperBins(grid);
  const std::vector<double> share = equalErrorPathShares(grid, bins, false);
  auto ring = [&](int r) { return share[size_t(r) * 300]; };
  EXPECT_NEAR(ring(0), 1.0, 1e-3);
  EXPECT_NEAR(ring(74), 1.0, 1e-3);
  EXPECT_NEAR(ring(37), 0.33, 0.01);
  for (int r = 0; r < 75; ++r)
    for (int k = 1; k < 300; ++k) ASSERT_EQ(share[size_t(r) * 300 + size_t(k)], ring(r)) << r << " " << k;
  const double mean = std::accumulate(share.begin(), share.end(), 0.0) / double(share.size());
  EXPECT_NEAR(mean, 0.554, 0.005);
  const std::vector<uint64_t> paths = equalErrorSlicePaths(grid, bins, false, 5000000);
  EXPECT_EQ(*std::max_element(paths.begin(), paths.end()), 5000000u);
  EXPECT_EQ(paths[37 * 300], uint64_t(std::ceil(ring(37) * 5000000.0)));
}

TEST(PathAllocation, NothingToTradeWhereEveryBinIsAlike) {
  // Incidence bins of equal projected solid angle (the whole cells of a disk grid; the cells the
  // rim cuts are exit bins only): every slice gains alike from the fold, so every slice keeps
  // paths_per_slice. And a handful of paths never rounds to none.
  const DirectionGrid disk(DiskGrid{8, 8});
  double full = 0;
  for (int b : upperBins(disk)) full = std::max(full, disk.projectedSolidAngle(b));
  std::vector<int> lit;
  for (int b : upperBins(disk))
    if (disk.projectedSolidAngle(b) > full * (1 - 1e-12)) lit.push_back(b);
  ASSERT_GT(lit.size(), 16u);
  for (double s : equalErrorPathShares(disk, lit, false)) EXPECT_NEAR(s, 1.0, 1e-9);
  const DirectionGrid grid(ThetaPhiGrid{6, 12});
  for (uint64_t n : equalErrorSlicePaths(grid, upperBins(grid), false, 2)) EXPECT_GE(n, 1u);
}

}  // namespace
}  // namespace mbsdf
