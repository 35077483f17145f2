// The microflake random walk (microflake/microflake_walk.h) on the four cases measured side by side
// with NVIDIA's facet-forge random walk (Heitz et al. 2016): GGX α 0.3 conductor at 30°, GGX α 2
// mirror, Beckmann α 0.1 conductor at 30°, Beckmann α 1 at 60°, plus the vMF family at κ = 0 and
// near it. Per case: walk paths per second per thread, and the walk's cost taken apart against the
// raw cost of its parts measured in the same run (one thread, the same distribution and
// directions): random numbers, free paths, visible-normal samples, the exit bin and the Fresnel
// factor, times how often a path needs each (its mean number of collisions, from replayed paths).
#include <benchmark/benchmark.h>
#include <tbb/info.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "core/rng.h"
#include "microflake/microflake_walk.h"
#include "optics/fresnel_table.h"
#include "optics/material.h"

using namespace mbsdf;

namespace {

struct WalkCase {
  std::string name;
  Ndf ndf;
  std::string material;  // "Al" (a conductor) or "mirror"
  double theta_deg;
};

const std::vector<WalkCase>& walkCases() {
  static const std::vector<WalkCase> cases = {{"GGX a=0.3 Al 30deg", GgxNdf{0.3, 0.3}, "Al", 30},
                                              {"GGX a=2 mirror 30deg", GgxNdf{2, 2}, "mirror", 30},
                                              {"Beckmann a=0.1 Al 30deg", BeckmannNdf{0.1, 0.1}, "Al", 30},
                                              {"Beckmann a=1 Al 60deg", BeckmannNdf{1, 1}, "Al", 60},
                                              {"vMF kappa=0 mirror 30deg", VonMisesFisherNdf{0}, "mirror", 30},
                                              {"vMF kappa=0.05 mirror 30deg", VonMisesFisherNdf{0.05}, "mirror", 30}};
  return cases;
}

struct WalkFigures {
  double pathsPerSecondPerThread = 0, collisionsPerPath = 0;
  double nsRandom = 0, nsFreePath = 0, nsVisible = 0, nsBin = 0, nsFresnel = 0;
};
std::vector<WalkFigures> gWalk(walkCases().size());

template <typename F>
double nanosecondsPerCall(int n, F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < n; ++i) f(i);
  return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() / n;
}

void BM_WalkCase(benchmark::State& state) {
  const size_t c = size_t(state.range(0));
  const WalkCase& wc = walkCases()[c];
  const MicroflakeDistribution dist(wc.ndf);
  Material material;
  builtinMaterial(wc.material, &material);
  const DirectionGrid grid(ThetaPhiGrid{75, 300});
  MicroflakeSettings s;
  s.paths = 1 << 19;
  const MicroflakeWalk walk(dist, material, {0.55}, grid, s);
  const Vec3 wi = sphericalDirection(radians(wc.theta_deg), 0);
  const int bin = grid.binOf(wi);
  double seconds = 0;
  int tile = 0;
  // One tile first, untimed: the process's first walk pays for the tallies' storage and the
  // threads' start (a case run first measured up to a third slower than in steady state).
  walk.run(tile++, 0, bin, wi);
  for (auto _ : state) seconds += walk.run(tile++, 0, bin, wi).seconds;
  WalkFigures& f = gWalk[c];
  f.pathsPerSecondPerThread = double(s.paths) * state.iterations() / seconds / tbb::info::default_concurrency();
  state.counters["paths_per_s_per_thread"] = f.pathsPerSecondPerThread;

  // The parts, on one thread. Directions: the walk's own first collisions' (v = wi).
  double depth = 0;
  const int nReplay = 20000;
  for (int p = 0; p < nReplay; ++p) depth += walk.replay(0, bin, uint64_t(p), 0, wi).depth;
  f.collisionsPerPath = depth / nReplay;
  const int n = 1 << 18;
  Sampler rng(3, 0, 0);
  double sink = 0;
  f.nsRandom = nanosecondsPerCall(n, [&](int) { sink += rng.get1D(); });
  f.nsFreePath = nanosecondsPerCall(n, [&](int i) { sink += dist.freePath(-wi, (i + 0.5) / n); });
  f.nsVisible = nanosecondsPerCall(n, [&](int) {
    const auto m = dist.sampleVisible(wi, rng);
    sink += m ? m->z : 0.0;
  });
  // Exit directions spread over the upper hemisphere, made beforehand so that only binOf is timed.
  std::vector<Vec3> exits(4096);
  for (Vec3& w : exits) {
    const double z = rng.get1D(), phi = 2 * kPi * rng.get1D(), r = safeSqrt(1 - z * z);
    w = Vec3{r * std::cos(phi), r * std::sin(phi), z};
  }
  f.nsBin = nanosecondsPerCall(n, [&](int i) { sink += grid.binOf(exits[size_t(i) & 4095]); });
  if (!material.isPerfectConductor()) {
    // The walk's tabulated reflectance, at scattered cosines as a walk meets them.
    const ConductorFresnelTable fresnel(material.outsideIor, material.ior(0.55));
    f.nsFresnel = nanosecondsPerCall(n, [&](int i) { sink += fresnel(double((i * 2654435761u) % n) / n); });
  }
  benchmark::DoNotOptimize(sink);
}
BENCHMARK(BM_WalkCase)->DenseRange(0, 5)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

}  // namespace

namespace mbsdf {
// Printed by main (bench_path_tracer.cpp) after the benchmarks.
void printWalkSummary() {
  bool any = false;
  for (const WalkFigures& f : gWalk) any = any || f.pathsPerSecondPerThread > 0;
  if (!any) return;
  std::printf(
      "\nmicroflake walk, per thread (parts measured on one thread in the same run, each with its own random "
      "numbers; parts/path = collisions x (free path + visible normal + Fresnel) + exit flight + exit bin)\n");
  std::printf("%-28s %12s %10s %9s %9s %9s %9s %9s %12s\n", "case", "paths/s/thr", "coll/path", "rng ns", "flight ns",
              "vndf ns", "bin ns", "fres ns", "parts/path");
  for (size_t c = 0; c < gWalk.size(); ++c) {
    const WalkFigures& f = gWalk[c];
    if (f.pathsPerSecondPerThread <= 0) continue;
    const double perCollision = f.nsFreePath + f.nsVisible + f.nsFresnel;
    const double partsNs = f.collisionsPerPath * perCollision + f.nsFreePath + f.nsBin;
    std::printf("%-28s %12.3g %10.2f %9.1f %9.1f %9.1f %9.1f %9.1f %9.0f ns (walk %.0f ns)\n",
                walkCases()[c].name.c_str(), f.pathsPerSecondPerThread, f.collisionsPerPath, f.nsRandom, f.nsFreePath,
                f.nsVisible, f.nsBin, f.nsFresnel, partsNs, 1e9 / f.pathsPerSecondPerThread);
  }
}
}  // namespace mbsdf
