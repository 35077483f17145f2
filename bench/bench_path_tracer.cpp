// Path-tracer speed against raw Embree on the same scene, measured in the same run
// (speed is a ratio against a baseline of the same run). Scene: the `hemispheres` patch (20 x 20 µm, radius 2 µm,
// spacing 5 µm, perfect-mirror facets), incidence 30°, all cores.
//   ours: rays/s of PathTracer::run (periodic wrapping, Fresnel, tallies, deterministic merging)
//   raw:  rays/s of bare rtcIntersect1 calls on the same Embree scene, with rays drawn like our
//         primary rays (uniform footprint, cosine directions), parallelised the same way (TBB)
// The ratio ours/raw is printed at the end (targets: >= 1.0 with the tracer's rays as packets, >= 0.9
// with them all one by one), and the ratio against raw Embree on the tracer's own rays, secondaries
// included, in their paths' order and in origin order as the tracer traces them (BM_TracerRaysAgain). Also: Kirchhoff
// samples per second per core, the time of one paper-resolution slice per wave estimator, and the microflake random
// walk's paths/s beside the explicit path tracer's on the matching Gaussian heightfield (Beckmann α = 0.5, Al at 550
// nm, incidence 30°; ratio printed).
#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "core/rng.h"
#include "geometry/embree_scene.h"
#include "geometry/generators.h"
#include "geometry/ray_order.h"
#include "optics/material.h"
#include "scattering/path_tracer.h"
#include "scattering/single_scattering.h"
#include "microflake/microflake_walk.h"
#include "scattering/wave_estimator.h"

#include <tbb/info.h>

using namespace mbsdf;

namespace {

struct Fixture {
  Microgeometry geometry =
      makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 16});
  PeriodicScene scene{geometry};
  Material mirror;
  DirectionGrid grid{ThetaPhiGrid{75, 300}};
  Fixture() { builtinMaterial("mirror", &mirror); }
};
Fixture& fixture() {
  static Fixture f;
  return f;
}

// The path tracer (rays as packets, then all one by one) and raw rtcIntersect1 alternate in
// rounds, so that all see the same state of the machine; the ratios printed are the medians of the
// rounds'.
double gOurs = 0, gOursSingle = 0, gRaw = 0, gRatio = 0, gRatioLo = 0, gRatioHi = 0, gRatioSingle = 0;

double rawPrimaryRaysPerSecond(Fixture& f, uint64_t n, int round) {
  const int bin = f.grid.binOfAngles(30, 0);
  std::atomic<uint64_t> hits{0};
  const auto t0 = std::chrono::steady_clock::now();
  tbb::parallel_for(uint64_t(0), (n + 1023) / 1024, [&](uint64_t c) {
    uint64_t local = 0;
    for (uint64_t j = c * 1024; j < std::min(n, (c + 1) * 1024); ++j) {
      Sampler s(7, uint32_t(round), j);
      DirectionSample wi = f.grid.sampleCosine(bin, s);
      Vec3 o{(s.get1D() - 0.5) * 20, (s.get1D() - 0.5) * 20, f.scene.zTop()};
      double t;
      local += f.scene.intersectRaw(o, -wi.w, 1e30, &t);
    }
    hits += local;
  });
  benchmark::DoNotOptimize(hits.load());
  return double(n) / std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : (v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]));
}

void BM_PathTracerVsRaw(benchmark::State& state) {
  Fixture& f = fixture();
  PathTracerSettings s;
  s.paths = uint64_t(state.range(0));
  PathTracer tracer(f.scene, f.mirror, {0.55}, f.grid, s);
  s.packets = false;
  PathTracer singleTracer(f.scene, f.mirror, {0.55}, f.grid, s);
  const int bin = f.grid.binOfAngles(30, 0);
  std::vector<double> ours, oursSingle, raw, ratio, ratioSingle;
  int round = 0;
  for (auto _ : state) {
    const TileResult r = tracer.run(round, 0, bin);
    ours.push_back(double(r.rays) / r.seconds);
    const TileResult q = singleTracer.run(round, 0, bin);
    oursSingle.push_back(double(q.rays) / q.seconds);
    raw.push_back(rawPrimaryRaysPerSecond(f, 1 << 20, round));
    ratio.push_back(ours.back() / raw.back());
    ratioSingle.push_back(oursSingle.back() / raw.back());
    ++round;
  }
  gOurs = median(ours);
  gOursSingle = median(oursSingle);
  gRaw = median(raw);
  gRatio = median(ratio);
  gRatioSingle = median(ratioSingle);
  gRatioLo = *std::min_element(ratio.begin(), ratio.end());
  gRatioHi = *std::max_element(ratio.begin(), ratio.end());
  state.counters["rays_per_s"] = gOurs;
  state.counters["single_rays_per_s"] = gOursSingle;
  state.counters["raw_rays_per_s"] = gRaw;
  state.counters["ratio"] = gRatio;
  state.counters["ratio_single"] = gRatioSingle;
}

// First rays alone (the rays of rawPrimaryRaysPerSecond, in chunks of 1024 like the tracer's):
// in the order drawn, traced one by one by PeriodicScene::trace; in origin order (OriginOrder, as
// the tracer orders them), one by one and as packets of 16 (PeriodicScene::traceMany), in the same
// run.
double gFirstSingle = 0, gFirstOrderedSingle = 0, gFirstPackets = 0;
void BM_FirstRays(benchmark::State& state) {
  Fixture& f = fixture();
  const uint64_t n = uint64_t(state.range(0)), nChunks = (n + 1023) / 1024;
  const int bin = f.grid.binOfAngles(30, 0);
  std::vector<Vec3> o(n), d(n), oo(n), od(n);
  std::vector<uint32_t> cells(n);
  OriginOrder order;
  order.prepare(n, f.scene.sizeX(), f.scene.sizeY());
  for (uint64_t j = 0; j < n; ++j) {
    Sampler s(7, 0, j);
    d[j] = -f.grid.sampleCosine(bin, s).w;
    o[j] = {(s.get1D() - 0.5) * 20, (s.get1D() - 0.5) * 20, f.scene.zTop()};
    cells[j] = order.cellOf(o[j]);
  }
  const std::span<const uint32_t> places = order.places(cells);
  for (uint64_t j = 0; j < n; ++j) {
    oo[places[j]] = o[j];
    od[places[j]] = d[j];
  }
  std::vector<TraceResult> out(n);
  double single = 0, orderedSingle = 0, packets = 0;
  auto seconds = [&](auto&& chunk) {
    const auto t0 = std::chrono::steady_clock::now();
    tbb::parallel_for(uint64_t(0), nChunks,
                      [&](uint64_t c) { chunk(c * 1024, std::min(n, (c + 1) * 1024) - c * 1024); });
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  for (auto _ : state) {
    single += seconds([&](uint64_t j0, uint64_t m) {
      for (uint64_t j = j0; j < j0 + m; ++j) out[j] = f.scene.trace(o[j], d[j]);
    });
    orderedSingle += seconds([&](uint64_t j0, uint64_t m) {
      for (uint64_t j = j0; j < j0 + m; ++j) out[j] = f.scene.trace(oo[j], od[j]);
    });
    packets += seconds([&](uint64_t j0, uint64_t m) {
      f.scene.traceMany({oo.data() + j0, m}, {od.data() + j0, m}, {}, TraceMode::Packets, {out.data() + j0, m});
    });
  }
  const double rays = double(n) * double(state.iterations());
  gFirstSingle = rays / single;
  gFirstOrderedSingle = rays / orderedSingle;
  gFirstPackets = rays / packets;
  state.counters["single_rays_per_s"] = gFirstSingle;
  state.counters["ordered_single_rays_per_s"] = gFirstOrderedSingle;
  state.counters["ordered_packet_rays_per_s"] = gFirstPackets;
}
BENCHMARK(BM_FirstRays)->Arg(1 << 20)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// The path tracer's own rays (primaries and secondaries, recorded by replaying its paths), traced
// again outside it: by raw rtcIntersect1 in the base copy (no wrapping, unbounded), and by
// PeriodicScene::trace (wrapping, double-precision hit records). Secondaries start on the surface
// and cost Embree more than primaries from above it, so this is the baseline that separates
// Embree's own cost from the tracer's.
double gRawSameRays = 0, gSceneSameRays = 0, gManySameRays = 0, gRawOrderedRays = 0;
void BM_TracerRaysAgain(benchmark::State& state) {
  Fixture& f = fixture();
  PathTracerSettings s;
  PathTracer tracer(f.scene, f.mirror, {0.55}, f.grid, s);
  const int bin = f.grid.binOfAngles(30, 0);
  std::vector<PathTracer::PathRecord::Ray> rays;
  for (uint64_t p = 0; p < uint64_t(state.range(0)); ++p) {
    const auto rec = tracer.replay(0, bin, p);
    rays.insert(rays.end(), rec.rays.begin(), rec.rays.end());
  }
  const uint64_t n = rays.size(), nChunks = (n + 1023) / 1024;
  // The same rays in origin order (all of them in one order: the tracer orders each round's).
  std::vector<PathTracer::PathRecord::Ray> ordered(n);
  {
    OriginOrder order;
    order.prepare(n, f.scene.sizeX(), f.scene.sizeY());
    std::vector<uint32_t> cells(n);
    for (uint64_t j = 0; j < n; ++j) cells[j] = order.cellOf(rays[j].o);
    const std::span<const uint32_t> places = order.places(cells);
    for (uint64_t j = 0; j < n; ++j) ordered[places[j]] = rays[j];
  }
  double rawSeconds = 0, sceneSeconds = 0, manySeconds = 0, orderedSeconds = 0;
  std::atomic<uint64_t> sink{0};
  // Raw rtcIntersect1 on the rays `of`, in chunks of 1024 on TBB threads.
  auto rawQueries = [&](const std::vector<PathTracer::PathRecord::Ray>& of) {
    tbb::parallel_for(uint64_t(0), nChunks, [&](uint64_t c) {
      uint64_t local = 0;
      for (uint64_t j = c * 1024; j < std::min(n, (c + 1) * 1024); ++j) {
        double t;
        local += f.scene.intersectRaw(of[j].o, of[j].d, 1e30, &t);
      }
      sink += local;
    });
  };
  for (auto _ : state) {
    auto t0 = std::chrono::steady_clock::now();
    rawQueries(rays);
    auto t1 = std::chrono::steady_clock::now();
    tbb::parallel_for(uint64_t(0), nChunks, [&](uint64_t c) {
      uint64_t local = 0;
      for (uint64_t j = c * 1024; j < std::min(n, (c + 1) * 1024); ++j)
        local += f.scene.trace(rays[j].o, rays[j].d, rays[j].ignorePrim).kind == TraceResult::Kind::Hit;
      sink += local;
    });
    auto t2 = std::chrono::steady_clock::now();
    tbb::parallel_for(uint64_t(0), nChunks, [&](uint64_t c) {
      const uint64_t j0 = c * 1024, m = std::min(n, j0 + 1024) - j0;
      std::vector<Vec3> o(m), d(m);
      std::vector<int> leaving(m);
      std::vector<TraceResult> out(m);
      for (uint64_t j = 0; j < m; ++j) {
        o[j] = rays[j0 + j].o;
        d[j] = rays[j0 + j].d;
        leaving[j] = rays[j0 + j].ignorePrim;
      }
      f.scene.traceMany(o, d, leaving, TraceMode::Single, out);
      uint64_t local = 0;
      for (const TraceResult& r : out) local += r.kind == TraceResult::Kind::Hit;
      sink += local;
    });
    auto t3 = std::chrono::steady_clock::now();
    rawQueries(ordered);
    auto t4 = std::chrono::steady_clock::now();
    orderedSeconds += std::chrono::duration<double>(t4 - t3).count();
    rawSeconds += std::chrono::duration<double>(t1 - t0).count();
    sceneSeconds += std::chrono::duration<double>(t2 - t1).count();
    manySeconds += std::chrono::duration<double>(t3 - t2).count();
  }
  gManySameRays = double(n) * double(state.iterations()) / manySeconds;
  gRawOrderedRays = double(n) * double(state.iterations()) / orderedSeconds;
  state.counters["raw_ordered_rays_per_s"] = gRawOrderedRays;
  state.counters["trace_many_rays_per_s"] = gManySameRays;
  gRawSameRays = double(n) * double(state.iterations()) / rawSeconds;
  gSceneSameRays = double(n) * double(state.iterations()) / sceneSeconds;
  state.counters["raw_rays_per_s"] = gRawSameRays;
  state.counters["trace_rays_per_s"] = gSceneSameRays;
  benchmark::DoNotOptimize(sink.load());
}

// Kirchhoff samples (point x exit direction, with shadow and masking rays, 8 wavelengths) per
// second, with the `area` estimator on the same hemispheres scene, 30 x 60 bins per hemisphere.
double gKirchhoffPerCore = 0;
const std::vector<double> kEightLambdas = {0.41875, 0.45625, 0.49375, 0.53125, 0.56875, 0.60625, 0.64375, 0.68125};

void BM_KirchhoffSamples(benchmark::State& state) {
  Fixture& f = fixture();
  Material al;
  builtinMaterial("Al", &al);
  DirectionGrid grid(ThetaPhiGrid{30, 60});
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Area;
  ws.samplesPerBin = int(state.range(0));
  WaveContext ctx{f.geometry, f.scene, al, kEightLambdas, grid, CoherenceWindow(0, 20, 20, true), ws};
  auto est = makeWaveEstimator(ctx);
  Vec3 wi = sphericalDirection(radians(30), 0);
  uint64_t samples = 0;
  double seconds = 0;
  int tile = 0;
  for (auto _ : state) {
    WaveTileResult r = est->run(tile++, grid.binOf(wi), wi);
    samples += r.samples;
    seconds += r.seconds;
  }
  state.counters["samples_per_s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
  gKirchhoffPerCore = double(samples) / seconds / tbb::info::default_concurrency();
  state.counters["samples_per_s_per_core"] = gKirchhoffPerCore;
}

// One slice at the paper's resolution (75 x 300 exit bins per hemisphere, 8 wavelengths,
// 5 million Kirchhoff samples per slice = 222 per bin) on hemispheres, θi = 55°, per estimator.
std::map<std::string, double> gSliceSeconds;
void BM_PaperResolutionSlice(benchmark::State& state, std::string estimator) {
  Fixture& f = fixture();
  Material al;
  builtinMaterial("Al", &al);
  WaveSettings ws;
  ws.estimator = waveEstimatorKind(estimator);
  ws.samplesPerBin = 5000000 / f.grid.binsPerHemisphere();
  WaveContext ctx{
      f.geometry,
      f.scene,
      al,
      kEightLambdas,
      f.grid,
      CoherenceWindow::fromCoherenceLength(estimator == "orders" || estimator == "exact" ? 50.0 : 0.0, 20, 20, true),
      ws};
  auto est = makeWaveEstimator(ctx);
  Vec3 wi = sphericalDirection(radians(55), 0);
  for (auto _ : state) {
    WaveTileResult r = est->run(0, f.grid.binOf(wi), wi);
    gSliceSeconds[estimator] = r.seconds;
    state.counters["samples"] = double(r.samples);
    state.counters["rays"] = double(r.rays);
  }
}

BENCHMARK(BM_KirchhoffSamples)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);
BENCHMARK_CAPTURE(BM_PaperResolutionSlice, paper, std::string("paper"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
BENCHMARK_CAPTURE(BM_PaperResolutionSlice, area, std::string("area"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
BENCHMARK_CAPTURE(BM_PaperResolutionSlice, orders, std::string("orders"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
// exact under the same window as orders: the 20 µm patch repeats a 5 µm cell (lattice_cell.h).
BENCHMARK_CAPTURE(BM_PaperResolutionSlice, exact, std::string("exact"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
BENCHMARK(BM_PathTracerVsRaw)->Arg(1 << 19)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(7);
BENCHMARK(BM_TracerRaysAgain)->Arg(1 << 18)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// Statistical vs explicit: the same surface statistics, the same tallies and grid.
double gWalkPaths = 0, gExplicitPaths = 0;
struct SmithFixture {
  double alpha = 0.5;
  Microgeometry geometry;
  std::unique_ptr<PeriodicScene> scene;
  Material al;
  DirectionGrid grid{ThetaPhiGrid{75, 300}};
  MicroflakeDistribution dist{BeckmannNdf{0.5, 0.5}};
  SmithFixture() {
    builtinMaterial("Al", &al);
    // Gaussian correlation exp(−r²/ℓ²), ℓ = 1 µm: per-axis slope variance 2h²/ℓ² = α²/2.
    geometry = makeGaussian(32, 32, alpha / 2, 1.0, 256, 256, 1);
    scene = std::make_unique<PeriodicScene>(geometry);
  }
};
SmithFixture& smithFixture() {
  static SmithFixture f;
  return f;
}

// Paths per second of a geometric estimator (PathTracer or MicroflakeWalk) at θi = 30°.
template <typename Estimator>
double pathsPerSecond(benchmark::State& state, const Estimator& est, uint64_t paths, const DirectionGrid& grid) {
  const Vec3 wi = sphericalDirection(radians(30.0), 0);
  double seconds = 0;
  int tile = 0;
  for (auto _ : state) seconds += est.run(tile++, 0, grid.binOf(wi), wi).seconds;
  const double rate = double(paths) * state.iterations() / seconds;
  state.counters["paths_per_s"] = rate;
  return rate;
}

void BM_MicroflakeWalkPaths(benchmark::State& state) {
  SmithFixture& f = smithFixture();
  MicroflakeSettings s;
  s.paths = uint64_t(state.range(0));
  MicroflakeWalk walk(f.dist, f.al, {0.55}, f.grid, s);
  gWalkPaths = pathsPerSecond(state, walk, s.paths, f.grid);
}
BENCHMARK(BM_MicroflakeWalkPaths)->Arg(1 << 20)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ExplicitHeightfieldPaths(benchmark::State& state) {
  SmithFixture& f = smithFixture();
  PathTracerSettings s;
  s.paths = uint64_t(state.range(0));
  PathTracer tracer(*f.scene, f.al, {0.55}, f.grid, s);
  gExplicitPaths = pathsPerSecond(state, tracer, s.paths, f.grid);
}
BENCHMARK(BM_ExplicitHeightfieldPaths)->Arg(1 << 20)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(4);

// The fft estimator's benchmark: one slice of a 512² periodic Gaussian heightfield (texel 0.05 µm, rms
// 0.08 µm, correlation 1 µm), σ = 4 µm window (δc = 24 µm), λ = 500 nm, normal incidence, 128 x 128
// disk grid, no masking (none at normal incidence below the steepest slope), with `fft`; beside it
// `exact` (facet sums x orders) on a 128² crop of the same statistics, scaled by facets x orders.
double gFftSeconds = 0, gExactCropSeconds = 0, gExactScale = 0;
void BM_FftHeightfieldSlice(benchmark::State& state, std::string estimator) {
  const int n = estimator == "fft" ? 512 : 128;
  const double L = 0.05 * n;
  const Microgeometry g = makeGaussian(L, L, 0.08, 1.0, n, n, 42);
  PeriodicScene scene(g);
  Material al;
  builtinMaterial("Al", &al);
  DirectionGrid grid(DiskGrid{128, 128});
  WaveSettings ws;
  ws.estimator = waveEstimatorKind(estimator);
  WaveContext ctx{g, scene, al, {0.5}, grid, CoherenceWindow(4.0, L, L, true), ws};
  auto est = makeWaveEstimator(ctx);
  const Vec3 wi{0, 0, 1};
  for (auto _ : state) {
    WaveTileResult r = est->run(0, grid.binOf(wi), wi);
    (estimator == "fft" ? gFftSeconds : gExactCropSeconds) = r.seconds;
    double energy = 0;  // Σ f Ω⊥ over the upper hemisphere (Al at 500 nm reflects 0.92)
    for (int b = 0; b < grid.binsPerHemisphere(); ++b) energy += r.fws[size_t(b)] * grid.projectedSolidAngle(b);
    state.counters["reflected"] = energy;
  }
  // exact's cost is facets x propagating orders: (512/128)² facets and (512/128)² orders.
  if (estimator == "exact") gExactScale = std::pow(512.0 / 128.0, 4);
}
BENCHMARK_CAPTURE(BM_FftHeightfieldSlice, fft, std::string("fft"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);
BENCHMARK_CAPTURE(BM_FftHeightfieldSlice, exact_crop, std::string("exact"))
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// The facet sum of single scattering (scattering/single_scattering.h) against the path tracer on the
// same tile: the Al sine grating of integration.effects_auto (2 x 0.3 µm, 128 facets in 64
// orientations, 2 wavelengths, 8 x 16 theta-phi bins), incidence bin at 20° (above the steepest
// slope: no ray) and the job's 50 000 paths. Prints the facet sum's pairs per second against the
// path tracer's rays per second — the exchange rate FacetSingleScattering::kPairsPerRay assumes — and
// the tile's speed-up.
struct GratingFixture {
  Microgeometry geometry = makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0);
  PeriodicScene scene{geometry};
  Material al;
  DirectionGrid grid{ThetaPhiGrid{8, 16}};
  GratingFixture() { builtinMaterial("Al", &al); }
};
double gFacetPairsPerSecond = 0, gFacetTileSeconds = 0, gGratingRaysPerSecond = 0, gGratingPathTileSeconds = 0;

void BM_FacetSumTile(benchmark::State& state) {
  static GratingFixture f;
  FacetSingleScattering sum(f.geometry, f.scene, f.al, {0.5, 0.6}, f.grid);
  const int bin = f.grid.binOfAngles(20, 0);
  const double pairs = sum.cost(bin, std::nullopt).pairs;
  double seconds = 0;
  int n = 0;
  for (auto _ : state) {
    seconds += sum.run(n, 0, bin, std::nullopt).seconds;
    ++n;
  }
  gFacetPairsPerSecond = pairs * n / seconds;
  gFacetTileSeconds = seconds / n;
  state.counters["pairs_per_s"] = gFacetPairsPerSecond;
}
BENCHMARK(BM_FacetSumTile)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(20);

void BM_GratingPathTile(benchmark::State& state) {
  static GratingFixture f;
  PathTracerSettings s;
  s.paths = 50000;
  PathTracer tracer(f.scene, f.al, {0.5, 0.6}, f.grid, s);
  const int bin = f.grid.binOfAngles(20, 0);
  double seconds = 0, rays = 0;
  int n = 0;
  for (auto _ : state) {
    const TileResult r = tracer.run(n, 0, bin);
    seconds += r.seconds;
    rays += double(r.rays);
    ++n;
  }
  gGratingRaysPerSecond = rays / seconds;
  gGratingPathTileSeconds = seconds / n;
  state.counters["rays_per_s"] = gGratingRaysPerSecond;
}
BENCHMARK(BM_GratingPathTile)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(20);

}  // namespace

namespace mbsdf {
void printWriterSummary();        // bench_writer.cpp
void printReadSummary();          // bench_writer.cpp
void printWalkSummary();          // bench_walk.cpp
void printWaveVarianceSummary();  // bench_wave_variance.cpp
}  // namespace mbsdf

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  mbsdf::printWriterSummary();
  mbsdf::printReadSummary();
  mbsdf::printWalkSummary();
  mbsdf::printWaveVarianceSummary();
  if (gOurs > 0 && gRaw > 0)
    std::printf(
        "\npath tracer: %.3g rays/s   raw rtcIntersect1: %.3g rays/s   ratio: %.2f (median of 7 alternating rounds, "
        "%.2f-%.2f; target >= 1.0)\n"
        "path tracer with all its rays one by one: %.3g rays/s, ratio %.2f (target >= 0.9)\n",
        gOurs, gRaw, gRatio, gRatioLo, gRatioHi, gOursSingle, gRatioSingle);
  if (gOurs > 0 && gRawSameRays > 0)
    std::printf(
        "the tracer's own rays again: raw rtcIntersect1 %.3g rays/s, PeriodicScene::trace %.3g rays/s, "
        "PeriodicScene::traceMany %.3g rays/s; path tracer / raw on the same rays: %.2f; raw on them in origin "
        "order %.3g rays/s, path tracer / that: %.2f\n",
        gRawSameRays, gSceneSameRays, gManySameRays, gOurs / gRawSameRays, gRawOrderedRays, gOurs / gRawOrderedRays);
  if (gFirstSingle > 0)
    std::printf(
        "first rays: one by one (PeriodicScene::trace) %.3g rays/s; in origin order %.3g rays/s (%.2fx), as packets "
        "(traceMany) %.3g rays/s (%.2fx)\n",
        gFirstSingle, gFirstOrderedSingle, gFirstOrderedSingle / gFirstSingle, gFirstPackets,
        gFirstPackets / gFirstSingle);
  if (gKirchhoffPerCore > 0)
    std::printf("Kirchhoff samples (shadow + masking rays, 8 wavelengths): %.3g per second per core\n",
                gKirchhoffPerCore);
  for (auto& [name, sec] : gSliceSeconds)
    std::printf("paper-resolution slice (75x300 bins, 8 wavelengths, 5M samples) on hemispheres, %s: %.2f s\n",
                name.c_str(), sec);
  if (gWalkPaths > 0 && gExplicitPaths > 0)
    std::printf(
        "Beckmann 0.5, Al: microflake walk %.3g paths/s, explicit Gaussian heightfield (131k triangles) %.3g "
        "paths/s, ratio %.2f\n",
        gWalkPaths, gExplicitPaths, gWalkPaths / gExplicitPaths);
  if (gFftSeconds > 0)
    std::printf(
        "512^2 Gaussian heightfield slice (128x128 disk grid, sigma 4 um, 500 nm, normal incidence): fft %.2f s "
        "(target <= 2 s)\n",
        gFftSeconds);
  if (gExactCropSeconds > 0)
    std::printf(
        "exact on a 128^2 crop: %.2f s, scaled to 512^2 (facets x orders, x%.0f): %.0f s; fft is %.0fx faster\n",
        gExactCropSeconds, gExactScale, gExactCropSeconds * gExactScale,
        gFftSeconds > 0 ? gExactCropSeconds * gExactScale / gFftSeconds : 0.0);
  if (gFacetPairsPerSecond > 0 && gGratingRaysPerSecond > 0)
    std::printf(
        "Al sine grating tile at 20 deg: facet sum %.3g pairs/s, path tracer %.3g rays/s: %.2f pairs per ray "
        "(FacetSingleScattering::kPairsPerRay = %.0f); tile %.2f ms vs %.2f ms at 50000 paths: %.1fx\n",
        gFacetPairsPerSecond, gGratingRaysPerSecond, gFacetPairsPerSecond / gGratingRaysPerSecond,
        FacetSingleScattering::kPairsPerRay, 1e3 * gFacetTileSeconds, 1e3 * gGratingPathTileSeconds,
        gGratingPathTileSeconds / gFacetTileSeconds);
  return 0;
}
