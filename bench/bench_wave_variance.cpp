// The `area` wave estimator's variance per sample with the mean plane's control variate
// (scattering/mean_plane_control.h) against the same estimator without it, measured in the same run
// on the same seeds: a flat mirror and flat glass (from above and below), shallow sine gratings of
// two depths and a rough Gaussian heightfield, 8 x 16 bins, 550 nm, δc = 50 µm, collimated at 30°.
// Per case: Var(E) × samples per bin over 16 seeds of the hemispherical energy E (Σ f Ω⊥), with and
// without, their ratio, and the seconds per tile of each.
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "geometry/embree_scene.h"
#include "geometry/generators.h"
#include "optics/material.h"
#include "scattering/wave_estimator.h"

using namespace mbsdf;

namespace {

struct VarianceCase {
  std::string name;
  Microgeometry geometry;
  Material material;
  double theta_deg;
};

Material builtin(const std::string& name) {
  Material m;
  builtinMaterial(name, &m);
  return m;
}

Material glass15() {
  Material m;
  m.model = Dielectric{ConstantIndex{1.5, 0}};
  return m;
}

const std::vector<VarianceCase>& varianceCases() {
  static const std::vector<VarianceCase> cases = {
      {"flat mirror", makeFlat(4, 4, 1.0), builtin("mirror"), 30},
      {"flat glass from air", makeFlat(4, 4, 1.0), glass15(), 30},
      {"flat glass from n=1.5", makeFlat(4, 4, 1.0), glass15(), 150},
      {"sine grating h=0.02um Al", makeSineGrating(4, 4, 4, 0.02, 32, 0), builtin("Al"), 30},
      {"sine grating h=0.1um Al", makeSineGrating(4, 4, 4, 0.1, 32, 0), builtin("Al"), 30},
      {"gaussian rms 0.2um Al", makeGaussian(4, 4, 0.2, 1.0, 32, 32, 3), builtin("Al"), 30}};
  return cases;
}

struct VarianceFigures {
  double varPerSample[2] = {0, 0}, seconds[2] = {0, 0}, energy[2] = {0, 0};
};
// Sized on first use: the cases' materials come from tables that static initialisation of this file
// must not read before they exist.
std::vector<VarianceFigures>& figures() {
  static std::vector<VarianceFigures> f(varianceCases().size());
  return f;
}
constexpr int kSamplesPerBin = 256, kSeeds = 16;

void BM_AreaVariance(benchmark::State& state) {
  const VarianceCase& c = varianceCases()[size_t(state.range(0))];
  VarianceFigures& f = figures()[size_t(state.range(0))];
  const DirectionGrid grid(ThetaPhiGrid{8, 16});
  const PeriodicScene scene(c.geometry);
  const Vec3 wi = sphericalDirection(radians(c.theta_deg), radians(10.0));
  for (auto _ : state)
    for (int mode = 0; mode < 2; ++mode) {
      WaveSettings ws;
      ws.estimator = WaveEstimatorKind::Area;
      ws.samplesPerBin = kSamplesPerBin;
      ws.controlVariate = mode == 0 ? WaveControlVariate::MeanPlane : WaveControlVariate::None;
      const WaveContext ctx{
          c.geometry, scene, c.material,
          {0.55},     grid,  CoherenceWindow::fromCoherenceLength(50.0, c.geometry.sizeX, c.geometry.sizeY, true),
          ws};
      const std::unique_ptr<WaveEstimator> est = makeWaveEstimator(ctx);
      double m1 = 0, m2 = 0;
      const auto t0 = std::chrono::steady_clock::now();
      for (int seed = 0; seed < kSeeds; ++seed) {
        const WaveTileResult r = est->run(seed, grid.binOf(wi), wi);
        double e = 0;
        for (int b = 0; b < grid.binCount(); ++b) e += r.fws[size_t(b)] * grid.projectedSolidAngle(b);
        m1 += e / kSeeds;
        m2 += e * e / kSeeds;
      }
      f.seconds[mode] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / kSeeds;
      f.varPerSample[mode] = std::max(0.0, m2 - m1 * m1) * kSeeds / (kSeeds - 1) * kSamplesPerBin;
      f.energy[mode] = m1;
    }
  state.counters["variance_ratio"] =
      f.varPerSample[1] > 0 ? f.varPerSample[1] / std::max(f.varPerSample[0], 1e-300) : 0;
}
BENCHMARK(BM_AreaVariance)->DenseRange(0, 5)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

}  // namespace

namespace mbsdf {
// Printed by main (bench_path_tracer.cpp) after the benchmarks.
void printWaveVarianceSummary() {
  bool any = false;
  for (const VarianceFigures& f : figures()) any = any || f.seconds[0] > 0;
  if (!any) return;
  std::printf(
      "\narea wave estimator, variance per sample of the hemispherical energy (Var(E) x %d samples per bin, "
      "%d seeds), with the mean-plane control variate and without it (the same estimator otherwise)\n",
      kSamplesPerBin, kSeeds);
  std::printf("%-26s %12s %12s %10s %9s %9s %10s %10s\n", "case", "var/sample", "without", "ratio", "E", "E without",
              "s/tile", "without");
  for (size_t c = 0; c < figures().size(); ++c) {
    const VarianceFigures& f = figures()[c];
    if (f.seconds[0] <= 0) continue;
    std::printf("%-26s %12.3g %12.3g %10.3g %9.4f %9.4f %10.3f %10.3f\n", varianceCases()[c].name.c_str(),
                f.varPerSample[0], f.varPerSample[1], f.varPerSample[1] / std::max(f.varPerSample[0], 1e-300),
                f.energy[0], f.energy[1], f.seconds[0], f.seconds[1]);
  }
}
}  // namespace mbsdf
