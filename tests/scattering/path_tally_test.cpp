// The deterministic Monte Carlo tallies: over several batches (whose merge overlaps the next
// batch's paths), with any number of threads, the sums are those of one serial loop over the paths
// in order; progress reaches every path; a progress callback that throws abandons the tile; chunks
// kept from an earlier run start empty.
#include "scattering/path_tally.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <atomic>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "core/rng.h"

namespace mbsdf {
namespace {

// A synthetic path: an exit bin and per-wavelength weights from the path's own numbers.
struct SyntheticPath {
  int bin;
  Component component;
  double w[2];
};
SyntheticPath syntheticPath(uint64_t path, int group, int nBins) {
  Sampler s(3, 0, path, uint32_t(group));
  SyntheticPath p;
  p.bin = std::min(nBins - 1, int(s.get1D() * nBins));
  p.component = s.get1D() < 0.7 ? Component::Coherent : Component::Multiple;
  p.w[0] = std::exp(-3 * s.get1D());
  p.w[1] = s.get1D() * s.get1D();
  return p;
}

PathTallyPlan planOf(const DirectionGrid& grid, int nLambda, uint64_t paths) {
  PathTallyPlan plan;
  plan.grid = &grid;
  plan.nLambda = nLambda;
  plan.groups = wavelengthGroups(nLambda, true);
  plan.paths = paths;
  plan.components = {Component::Coherent};
  return plan;
}

TEST(PathTally, BatchedParallelSumsEqualASerialLoopInPathOrder) {
  const DirectionGrid grid(ThetaPhiGrid{6, 12});
  PathTallyPlan plan = planOf(grid, 2, 3 * 256 * 1024 + 777);  // three full batches and part of a fourth
  plan.firstPath = 5;
  plan.components = {Component::Coherent, Component::Multiple};
  const int nB = grid.binCount();
  auto trace = [&](uint64_t path, int group, PathChunk& out) {
    const SyntheticPath p = syntheticPath(path, group, nB);
    out.tally(p.bin, p.component, group, p.w, 2);
    ++out.rays;
  };
  // The reference: every path in order, summed as the tallies define the estimate.
  std::vector<double> sum(size_t(2) * nB * 2, 0.0);
  for (uint64_t i = 0; i < plan.paths; ++i) {
    const SyntheticPath p = syntheticPath(plan.firstPath + i, 0, nB);
    for (int l = 0; l < 2; ++l) sum[(size_t(p.component == Component::Multiple) * 2 + l) * nB + p.bin] += p.w[l];
  }
  for (int threads : {1, 2, 4}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    uint64_t lastDone = 0, calls = 0;
    const TileResult r = runPaths(plan, trace, [&](uint64_t done) {
      EXPECT_GT(done, lastDone);
      lastDone = done;
      ++calls;
    });
    EXPECT_EQ(lastDone, plan.paths);
    EXPECT_EQ(calls, 4u);
    EXPECT_EQ(r.rays, plan.paths);
    for (int c = 0; c < 2; ++c)
      for (int l = 0; l < 2; ++l)
        for (int b = 0; b < nB; ++b) {
          const Component comp = c == 0 ? Component::Coherent : Component::Multiple;
          ASSERT_EQ(r.at(comp, l, b),
                    sum[(size_t(c) * 2 + l) * nB + b] / (double(plan.paths) * grid.projectedSolidAngle(b)))
              << threads << " threads, bin " << b;
        }
  }
}

// runPaths keeps its chunks' storage from run to run: a run after one with more wavelengths, more
// chunks and other tallies starts from empty chunks of its own size.
TEST(PathTally, ChunksKeptFromRunToRunStartEmpty) {
  const DirectionGrid grid(ThetaPhiGrid{4, 8});
  const int nB = grid.binCount();
  size_t nLambda = 0;
  std::atomic<int> wrongSize{0};
  auto traceTruncating = [&](uint64_t path, int group, PathChunk& out) {
    if (out.truncated.size() != nLambda || out.missed.size() != nLambda) ++wrongSize;
    const SyntheticPath p = syntheticPath(path, group, nB);
    out.tally(p.bin, p.component, group, p.w, out.truncated.size());
    for (size_t l = 0; l < out.truncated.size(); ++l) out.truncated[l] += p.w[l];
    ++out.rays;
  };
  PathTallyPlan small = planOf(grid, 1, 1000);
  small.components = {Component::Coherent, Component::Multiple};
  // The reference: the small plan's paths in order.
  std::vector<double> sum(size_t(2) * nB, 0.0);
  double truncated = 0;
  for (uint64_t i = 0; i < small.paths; ++i) {
    const SyntheticPath p = syntheticPath(i, 0, nB);
    sum[size_t(p.component == Component::Multiple) * nB + p.bin] += p.w[0];
    truncated += p.w[0];
  }
  PathTallyPlan large = planOf(grid, 2, 2 * 256 * 1024);
  large.components = {Component::Coherent, Component::Multiple};
  for (int pass = 0; pass < 2; ++pass) {
    nLambda = 2;
    runPaths(large, traceTruncating, {});
    nLambda = 1;
    const TileResult r = runPaths(small, traceTruncating, {});
    EXPECT_EQ(wrongSize.load(), 0);
    EXPECT_EQ(r.rays, small.paths);
    ASSERT_EQ(r.truncated.size(), 1u);
    EXPECT_EQ(r.truncated[0], truncated / double(small.paths));
    for (int c = 0; c < 2; ++c)
      for (int b = 0; b < nB; ++b)
        ASSERT_EQ(r.at(c == 0 ? Component::Coherent : Component::Multiple, 0, b),
                  sum[size_t(c) * nB + b] / (double(small.paths) * grid.projectedSolidAngle(b)))
            << "pass " << pass << ", bin " << b;
  }
}

TEST(PathTally, AThrowingProgressAbandonsTheTile) {
  const DirectionGrid grid(ThetaPhiGrid{2, 4});
  const PathTallyPlan plan = planOf(grid, 1, 4 * 256 * 1024);
  uint64_t traced = 0;
  auto trace = [&](uint64_t, int group, PathChunk& out) {
    const double w = 1;
    out.tally(0, Component::Coherent, group, &w, 1);
  };
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  EXPECT_THROW(runPaths(plan, trace,
                        [&](uint64_t done) {
                          traced = done;
                          throw std::runtime_error("abandon");
                        }),
               std::runtime_error);
  EXPECT_EQ(traced, 256u * 1024u);  // the first batch's progress, then nothing more
}

}  // namespace
}  // namespace mbsdf
