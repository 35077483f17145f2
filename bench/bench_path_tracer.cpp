// Path-tracer speed against raw Embree on the same scene, measured in the same run
// (non-negotiable 4). Scene: the `hemispheres` patch (20 x 20 µm, radius 2 µm, spacing 5 µm,
// perfect-mirror facets), incidence 30°, all cores.
//   ours: rays/s of PathTracer::run (periodic wrapping, Fresnel, tallies, deterministic merging)
//   raw:  rays/s of bare rtcIntersect1 calls on the same Embree scene, with rays drawn like our
//         primary rays (uniform footprint, cosine directions), parallelised the same way (TBB)
// The ratio ours/raw is printed at the end (target >= 0.6).
#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cstdio>

#include "core/rng.h"
#include "geometry/embree_scene.h"
#include "geometry/generators.h"
#include "optics/material.h"
#include "scattering/path_tracer.h"

using namespace mbsdf;

namespace {

struct Fixture {
  Microgeometry geometry = makeDomeLattice(20, 20, 5, 5, 2, 2, 2, 2.0 / 16);
  PeriodicScene scene{geometry};
  Material mirror;
  DirectionGrid grid{ThetaPhiGrid{75, 300}};
  Fixture() { builtinMaterial("mirror", &mirror); }
};
Fixture& fixture() {
  static Fixture f;
  return f;
}

double gOurs = 0, gRaw = 0;

void BM_PathTracerRays(benchmark::State& state) {
  Fixture& f = fixture();
  PathTracerSettings s;
  s.paths = uint64_t(state.range(0));
  PathTracer tracer(f.scene, f.mirror, {0.55}, f.grid, s);
  int bin = f.grid.binOfAngles(30, 0);
  uint64_t rays = 0;
  double seconds = 0;
  int tile = 0;
  for (auto _ : state) {
    TileResult r = tracer.run(tile, 0, bin);
    rays += r.rays;
    seconds += r.seconds;
    ++tile;
  }
  state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
  state.counters["rays_per_path"] = double(rays) / double(s.paths * state.iterations());
  gOurs = double(rays) / seconds;
}

void BM_RawEmbreeRays(benchmark::State& state) {
  Fixture& f = fixture();
  const uint64_t n = uint64_t(state.range(0));
  int bin = f.grid.binOfAngles(30, 0);
  std::atomic<uint64_t> hits{0};
  uint64_t rays = 0;
  double seconds = 0;
  int tile = 0;
  for (auto _ : state) {
    auto t0 = std::chrono::steady_clock::now();
    tbb::parallel_for(uint64_t(0), (n + 1023) / 1024, [&](uint64_t c) {
      uint64_t local = 0;
      for (uint64_t j = c * 1024; j < std::min(n, (c + 1) * 1024); ++j) {
        Sampler s(7, uint32_t(tile), j);
        DirectionSample wi = f.grid.sampleCosine(bin, s.get1D(), s.get1D());
        Vec3 o{(s.get1D() - 0.5) * 20, (s.get1D() - 0.5) * 20, f.scene.zTop()};
        double t;
        local += f.scene.intersectRaw(o, -wi.w, 1e30, &t);
      }
      hits += local;
    });
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rays += n;
    ++tile;
  }
  state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
  gRaw = double(rays) / seconds;
  benchmark::DoNotOptimize(hits.load());
}

BENCHMARK(BM_PathTracerRays)->Arg(1 << 20)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RawEmbreeRays)->Arg(1 << 21)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  if (gOurs > 0 && gRaw > 0)
    std::printf("\npath tracer: %.3g rays/s   raw rtcIntersect1: %.3g rays/s   ratio: %.2f (target >= 0.6)\n", gOurs,
                gRaw, gOurs / gRaw);
  return 0;
}
