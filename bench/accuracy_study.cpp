// What accuracy costs in time (issue "accuracy vs time"): every estimator at increasing budgets on
// cases with known answers, writing one CSV row per (case, estimator, budget, seed):
//   case,estimator,budget,seed,seconds,error
// `error` is the relative error against the closed form:
//  - flat_al_40: ∫f_ws over the hemisphere vs the Fresnel reflectance of Al at 40°, 550 nm
//    (window δc = 50 µm, 2 µm periodic patch, 30 x 60 bins, collimated incidence);
//  - sine_grating: Σ_m |η_m − J_m²(2 k0 h)| over |m| <= 3 / Σ_m J_m² (perfect conductor,
//    Λ = 5 µm, h = 0.05 µm, λ = 0.5 µm, normal incidence, 90 x 72 bins);
//  - vgroove_20: the one-bounce fraction of a 90° mirror V-groove at 20° vs tan 20° (path tracer);
//  - glass_reflectance: the reflectance of flat BK7 at 60° vs Fresnel (path tracer, Russian
//    roulette);
//  - chandrasekhar_albedo / chandrasekhar_lobe: the microflake walk in Chandrasekhar's isotropic
//    medium (constant NDF, mirror flakes of albedo 0.9, θi = 30°): albedo vs 1 − H(μi)√(1 − a), and
//    the table's relative L1 distance Σ|f − f_ref|Ω⊥ / Σ f_ref Ω⊥ vs seed Eq. 30;
//  - hemisphere_cell_ws: one 5 µm cell of HEMISPHERES (Al, θi = 50°, δc = 60 µm, 15 x 30 bins) in
//    the grating-order regime: relative L1 distance of the WS table of `orders` and `area` to the
//    deterministic `exact` table (`exact`'s own row: its distance to `orders` at 2^18 samples, the
//    noise of that table); flat_al_40 and sine_grating also run `exact`;
//  - hemispheres_paper_ws: the paper's HEMISPHERES at the paper's resolution (75 x 300 bins, δc =
//    50 µm): the WS table of `area` against `exact`'s (the patch repeats a 5 µm cell whose order
//    lobes stay apart under this window);
//  - hemispheres_gm (and its coherent / multiple components) / hemispheres_ws: the paper's HEMISPHERES (Al, 550 nm, θi
//  = 30°, 30 x 60 bins):
//    relative L1 distance of the GM table (path tracer) to a reference at 16x the largest budget
//    (so the curves flatten at the reference's own noise), and of the WS table (area estimator,
//    δc = 50 µm) to `exact`'s.
// Lines "#cost,<aspect>,<setting>,<seconds>" give the cost of each model (GS/GM/WS/WM, + lost), of
// the angular resolution and of the number of wavelengths at a fixed budget.
// scripts/accuracy-vs-time runs it and turns the CSV into a table and a log-log plot.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <tuple>
#include <string>
#include <vector>

#include "geometry/generators.h"
#include "microflake/chandrasekhar.h"
#include "microflake/microflake_walk.h"
#include "scattering/path_tracer.h"
#include "scattering/wave_estimator.h"

using namespace mbsdf;

namespace {

Material named(const char* n) {
  Material m;
  builtinMaterial(n, &m);
  return m;
}

double hemisphere(const DirectionGrid& g, const std::vector<double>& f, bool upper) {
  double s = 0;
  for (int b = 0; b < g.binCount(); ++b)
    if (g.isUpper(b) == upper) s += f[b] * g.projectedSolidAngle(b);
  return s;
}

struct Timer {
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }
};

// Relative L1 distance of two tables over the upper hemisphere.
double relativeL1(const DirectionGrid& g, const std::vector<double>& f, const std::vector<double>& ref) {
  double d = 0, n = 0;
  for (int b = 0; b < g.binsPerHemisphere(); ++b) {
    d += std::abs(f[b] - ref[b]) * g.projectedSolidAngle(b);
    n += std::abs(ref[b]) * g.projectedSolidAngle(b);
  }
  return d / n;
}
std::vector<double> sum(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> s(a);
  for (size_t i = 0; i < s.size(); ++i) s[i] += b[i];
  return s;
}
// Wave-estimator settings of the study: 16 points per direction, seed = seedIndex + 1.
WaveSettings waveSettings(const std::string& estimator, long samplesPerBin, int seedIndex, bool masked = false) {
  WaveSettings ws;
  ws.estimator = waveEstimatorKind(estimator);
  ws.samplesPerBin = int(samplesPerBin);
  ws.pointsPerDirection = 16;
  ws.seed = uint64_t(seedIndex + 1);
  ws.computeMasked = masked;
  return ws;
}
// One WS table of a collimated beam wi (550 nm, Al) and its wall time.
struct WaveCase {
  const Microgeometry& g;
  const PeriodicScene& scene;
  const Material& material;
  const DirectionGrid& grid;
  double coherenceLength_um;
  Vec3 wi;
  std::pair<std::vector<double>, double> table(const std::string& est, long samples, int seed) const {
    auto e =
        makeWaveEstimator(WaveContext{g,
                                      scene,
                                      material,
                                      {0.55},
                                      grid,
                                      CoherenceWindow::fromCoherenceLength(coherenceLength_um, g.sizeX, g.sizeY, true),
                                      waveSettings(est, samples, seed)});
    Timer t;
    WaveTileResult r = e->run(seed, grid.binOf(wi), wi);
    return std::pair{r.fws, t.seconds()};
  }
};

void cost(const char* aspect, const std::string& setting, double seconds) {
  std::printf("#cost,%s,%s,%.6g\n", aspect, setting.c_str(), seconds);
  std::fflush(stdout);
}

// One measurement. `bound`: the error is a deterministic estimator's distance to a Monte Carlo table
// of the same case, i.e. that table's noise, an upper bound of the estimator's own error, not the
// error itself (the plot and the table say so).
void row(const char* c, const std::string& est, long budget, int seed, double sec, double err, bool bound = false) {
  std::printf("%s,%s,%ld,%d,%.6g,%.6g,%d\n", c, est.c_str(), budget, seed, sec, err, bound ? 1 : 0);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const int seeds = argc > 1 ? std::atoi(argv[1]) : 3;
  // Optional second argument: run only the cases whose name contains it.
  const std::string only = argc > 2 ? argv[2] : "";
  auto want = [&](const char* name) { return only.empty() || std::string(name).find(only) != std::string::npos; };
  std::printf("case,estimator,budget,seed,seconds,error,upper_bound\n");

  // Flat aluminium at 40° through the wave estimators.
  if (want("flat_al_40")) {
    Microgeometry g = makeFlat(2, 2, 0);
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(ThetaPhiGrid{30, 60});
    Vec3 wi = sphericalDirection(radians(40), radians(17));
    const double F = fresnelReflectance(std::cos(radians(40)), 1.0, al.ior(0.55));
    for (const std::string est : {"orders", "area", "paper", "exact"})
      for (long budget : {64L, 256L, 1024L, 4096L, 16384L}) {
        if (est != "orders" && budget > 4096) continue;
        if (est == "exact" && budget != 64) continue;  // deterministic: no budget
        for (int s = 0; s < (est == "exact" ? 1 : seeds); ++s) {
          const WaveSettings ws = waveSettings(est, budget, s);
          auto e = makeWaveEstimator(
              WaveContext{g, scene, al, {0.55}, grid, CoherenceWindow::fromCoherenceLength(50, 2, 2, true), ws});
          Timer t;
          WaveTileResult r = e->run(s, grid.binOf(wi), wi);
          row("flat_al_40", est, budget, s, t.seconds(), std::abs(hemisphere(grid, r.fws, true) - F) / F);
        }
      }
  }
  // Sine grating orders.
  if (want("sine_grating")) {
    Microgeometry g = makeSineGrating(5, 1, 5, 0.05, 64, 0);
    PeriodicScene scene(g);
    Material mirror = named("mirror");
    DirectionGrid grid(ThetaPhiGrid{90, 72});
    const double k0 = 2 * kPi / 0.5;
    for (const std::string est : {"orders", "area", "paper", "exact"})
      for (long budget : {64L, 256L, 1024L, 4096L, 16384L}) {
        if (est != "orders" && budget > 1024) continue;
        if (est == "exact" && budget != 64) continue;  // deterministic: no budget
        for (int s = 0; s < (est == "exact" ? 1 : seeds); ++s) {
          const WaveSettings ws = waveSettings(est, budget, s);
          auto e = makeWaveEstimator(
              WaveContext{g, scene, mirror, {0.5}, grid, CoherenceWindow::fromCoherenceLength(50, 5, 1, true), ws});
          Timer t;
          Vec3 wi{0, 0, 1};
          WaveTileResult r = e->run(s, grid.binOf(wi), wi);
          double err = 0, norm = 0;
          for (int m = -3; m <= 3; ++m) {
            double sx = -m * 0.1, eta = 0;
            for (int b = 0; b < grid.binsPerHemisphere(); ++b) {
              Vec3 c = grid.centre(b);
              if (std::hypot(c.x - sx, c.y) <= 0.04) eta += r.fws[b] * grid.projectedSolidAngle(b);
            }
            double ref = std::pow(std::cyl_bessel_j(double(std::abs(m)), 2 * k0 * 0.05), 2);
            err += std::abs(eta - ref);
            norm += ref;
          }
          row("sine_grating", est, budget, s, t.seconds(), err / norm);
        }
      }
  }
  // Path tracer: V-groove one-bounce fraction and glass reflectance.
  if (want("vgroove_20") || want("glass_reflectance")) {
    Microgeometry v = makeRidged(10, 10, 2, 90, 0);
    PeriodicScene sv(v);
    Microgeometry flat = makeFlat(10, 10, 0);
    PeriodicScene sf(flat);
    Material mirror = named("mirror");
    Material glass;
    glass.model = Dielectric{ConstantIndex{1.5, 0}};
    DirectionGrid grid(ThetaPhiGrid{30, 60});
    const double t20 = std::tan(radians(20));
    const double R60 = fresnelReflectance(std::cos(radians(60)), 1.0, Complex(1.5, 0));
    for (long budget : {1000L, 10000L, 100000L, 1000000L})
      for (int s = 0; s < seeds; ++s) {
        PathTracerSettings ps;
        ps.paths = uint64_t(budget);
        ps.seed = uint64_t(s + 1);
        {
          PathTracer tr(sv, mirror, {0.55}, grid, ps);
          Vec3 wi = sphericalDirection(radians(20), 0);
          Timer t;
          TileResult r = tr.run(s, 0, grid.binOf(wi), wi);
          row("vgroove_20", "path", budget, s, t.seconds(),
              std::abs(hemisphere(grid, r.value[int(Component::Coherent)], true) - t20) / t20);
        }
        {
          PathTracer tr(sf, glass, {0.55}, grid, ps);
          Vec3 wi = sphericalDirection(radians(60), 0);
          Timer t;
          TileResult r = tr.run(s, 0, grid.binOf(wi), wi);
          row("glass_reflectance", "path", budget, s, t.seconds(),
              std::abs(hemisphere(grid, r.value[int(Component::Coherent)], true) - R60) / R60);
        }
      }
  }
  // Chandrasekhar's medium through the microflake walk.
  if (want("chandrasekhar")) {
    const double a = 0.9;
    MicroflakeDistribution sphere(VonMisesFisherNdf{0.0});
    Material mirror = named("mirror");
    DirectionGrid grid(ThetaPhiGrid{15, 30});
    const Vec3 wi = sphericalDirection(radians(30), 0);
    const double Hi = chandrasekharH(wi.z, a), albedoRef = 1 - Hi * std::sqrt(1 - a);
    std::vector<double> ref(grid.binCount(), 0.0);
    for (int b = 0; b < grid.binsPerHemisphere(); ++b) {
      const int n = 16;
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const Vec3 wo = grid.sampleCosine(b, (i + 0.5) / n, (j + 0.5) / n).w;
          ref[b] += isotropicMediumBRDF(wi.z, wo.z, a) / (n * n);
        }
    }
    for (long budget : {1000L, 10000L, 100000L, 1000000L, 4000000L})
      for (int s = 0; s < seeds; ++s) {
        MicroflakeSettings ms;
        ms.paths = uint64_t(budget);
        ms.seed = uint64_t(s + 1);
        ms.maxDepth = 100000;
        ms.flakeAlbedo = a;
        MicroflakeWalk walk(sphere, mirror, {0.55}, grid, ms);
        Timer t;
        TileResult r = walk.run(s, 0, grid.binOf(wi), wi);
        const double sec = t.seconds();
        std::vector<double> f = sum(r.value[int(Component::Coherent)], r.value[int(Component::Multiple)]);
        row("chandrasekhar_albedo", "walk", budget, s, sec,
            std::abs(hemisphere(grid, f, true) - albedoRef) / albedoRef);
        row("chandrasekhar_lobe", "walk", budget, s, sec, relativeL1(grid, f, ref));
      }
  }
  // One cell of HEMISPHERES (5 µm, r = 2 µm, Al, 550 nm, θi = 50°: mutual shadowing) under a window
  // much wider than the cell (δc = 60 µm: the grating-order regime, where `exact` applies): the WS
  // table of the Monte Carlo estimators against `exact`'s.
  if (want("hemisphere_cell_ws")) {
    Microgeometry g =
        makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25});
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(ThetaPhiGrid{15, 30});
    const WaveCase c{g, scene, al, grid, 60.0, sphericalDirection(radians(50), radians(20))};
    // `exact` (deterministic; checked against `orders` bin by bin in tests/scattering/
    // wave_exact_test.cpp) is the reference; its own row is its distance to `orders` at 2^18
    // samples, the noise of that Monte Carlo table.
    const auto [ref, refSec] = c.table("exact", 64, 0);
    for (const std::string est : {"orders", "area"})
      for (long budget : {64L, 256L, 1024L, 4096L, 16384L, 65536L}) {
        if (est == "area" && budget > 4096) continue;
        for (int s = 0; s < seeds; ++s) {
          auto [f, sec] = c.table(est, budget, s);
          row("hemisphere_cell_ws", est, budget, s, sec, relativeL1(grid, f, ref));
        }
      }
    row("hemisphere_cell_ws", "exact", 64, 0, refSec, relativeL1(grid, c.table("orders", 1 << 18, 1000).first, ref),
        true);
  }
  // A rough Gaussian heightfield (10 µm, rms 0.1 µm, correlation 1 µm, Al, 550 nm, θi = 30°) under
  // a window narrower than the patch (δc = 15 µm: overlapping order lobes, speckle) on a 32 x 32
  // disk grid: the WS table of `area` against `fft` (deterministic; checked against `area` bin by
  // bin and against `exact` in tests/scattering/wave_fft_test.cpp); fft's own row is its distance
  // to `area` at 2^15 samples per bin, the noise of that Monte Carlo table.
  if (want("gaussian_speckle_ws")) {
    Microgeometry g = makeGaussian(10, 10, 0.1, 1.0, 128, 128, 3);
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(DiskGrid{32, 32});
    const WaveCase c{g, scene, al, grid, 15.0, sphericalDirection(radians(30), radians(10))};
    const auto [ref, refSec] = c.table("fft", 64, 0);
    for (long budget : {64L, 256L, 1024L, 4096L})
      for (int s = 0; s < seeds; ++s) {
        auto [f, sec] = c.table("area", budget, s);
        row("gaussian_speckle_ws", "area", budget, s, sec, relativeL1(grid, f, ref));
      }
    row("gaussian_speckle_ws", "fft", 64, 0, refSec, relativeL1(grid, c.table("area", 1 << 15, 1000).first, ref), true);
  }
  // The paper's HEMISPHERES at the paper's resolution (20 µm patch of 4 x 4 domes, r = 2 µm at
  // r/16, Al, 550 nm, θi = 30°, δc = 50 µm, 75 x 300 bins): the window (σ = 8.3 µm) is narrower than
  // the patch, but the patch repeats a 5 µm cell (geometry/lattice_cell.h), whose order lobes stay
  // apart (2πσ/L_cell = 10.5), so `exact` applies and is the reference; the WS table of `area`
  // against it. exact's own row: its distance to `orders` at 2^20 points (the noise of that table,
  // an upper bound of exact's error).
  if (want("hemispheres_paper_ws")) {
    Microgeometry g =
        makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 16});
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(ThetaPhiGrid{75, 300});
    const WaveCase c{g, scene, al, grid, 50.0, sphericalDirection(radians(30), radians(10))};
    const auto [ref, refSec] = c.table("exact", 64, 0);
    for (long budget : {16L, 64L, 256L})
      for (int s = 0; s < seeds; ++s) {
        auto [f, sec] = c.table("area", budget, s);
        row("hemispheres_paper_ws", "area", budget, s, sec, relativeL1(grid, f, ref));
      }
    // `orders` (Monte Carlo over the same lobes: its budget is points, not samples per bin)
    // converging on `exact` as 1/√N shows that the distance is its noise, not a bias of either.
    for (long budget : {1L << 14, 1L << 16, 1L << 18})
      for (int s = 0; s < seeds; ++s) {
        auto [f, sec] = c.table("orders", budget, s);
        row("hemispheres_paper_ws", "orders", budget, s, sec, relativeL1(grid, f, ref));
      }
    row("hemispheres_paper_ws", "exact", 64, 0, refSec, relativeL1(grid, c.table("orders", 1 << 20, 1000).first, ref),
        true);
  }
  // HEMISPHERES (the paper's surface) against high-budget references.
  if (want("hemispheres_gm") || want("hemispheres_ws")) {
    Microgeometry g =
        makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 16});
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(ThetaPhiGrid{30, 60});
    const Vec3 wi = sphericalDirection(radians(30), radians(10));
    const int bin = grid.binOf(wi);
    auto gm = [&](long paths, int seed) {
      PathTracerSettings ps;
      ps.paths = uint64_t(paths);
      ps.seed = uint64_t(seed + 1);
      PathTracer tr(scene, al, {0.55}, grid, ps);
      Timer t;
      TileResult r = tr.run(seed, 0, bin, wi);
      return std::tuple{sum(r.value[int(Component::Coherent)], r.value[int(Component::Multiple)]), t.seconds(),
                        r.value[int(Component::Coherent)], r.value[int(Component::Multiple)]};
    };
    auto ws = [&](long samples, int seed, bool masked = false) {
      const WaveSettings w = waveSettings("area", samples, seed, masked);
      auto e = makeWaveEstimator(
          WaveContext{g, scene, al, {0.55}, grid, CoherenceWindow::fromCoherenceLength(50, 20, 20, true), w});
      Timer t;
      WaveTileResult r = e->run(seed, bin, wi);
      return std::pair{r.fws, t.seconds()};
    };
    const auto [refGm, refSec, refCoh, refMul] = gm(16000000, 1000);
    // The WS reference: `exact` (the patch repeats a 5 µm cell whose order lobes stay apart under
    // this window; see hemispheres_paper_ws), deterministic, instead of `area` at 16x the budget.
    const std::vector<double> refWs = WaveCase{g, scene, al, grid, 50.0, wi}.table("exact", 64, 0).first;
    for (long budget : {1000L, 10000L, 100000L, 1000000L})
      for (int s = 0; s < seeds; ++s) {
        auto [f, sec, coh, mul] = gm(budget, s);
        row("hemispheres_gm", "path", budget, s, sec, relativeL1(grid, f, refGm));
        row("hemispheres_coherent", "path", budget, s, sec, relativeL1(grid, coh, refCoh));
        row("hemispheres_multiple", "path", budget, s, sec, relativeL1(grid, mul, refMul));
      }
    for (long budget : {64L, 256L, 1024L, 4096L})
      for (int s = 0; s < seeds; ++s) {
        auto [f, sec] = ws(budget, s);
        row("hemispheres_ws", "area", budget, s, sec, relativeL1(grid, f, refWs));
      }

    // Cost at a fixed budget (1e6 paths, 256 wave samples per bin): models, resolution, wavelengths.
    const double tGm = std::get<1>(gm(1000000, 7)), tWs = ws(256, 7).second, tLost = ws(256, 7, true).second;
    cost("model", "GS (path tracer; depth 1 needs the same paths)", tGm);
    cost("model", "GM", tGm);
    cost("model", "WS (GS paths + area estimator)", tGm + tWs);
    cost("model", "WM", tGm + tWs);
    cost("model", "WM + lost", tGm + tLost);
    for (auto [nt, np] : {std::pair{15, 30}, std::pair{30, 60}, std::pair{75, 300}}) {
      DirectionGrid gr(ThetaPhiGrid{nt, np});
      PathTracerSettings ps;
      ps.paths = 1000000;
      PathTracer tr(scene, al, {0.55}, gr, ps);
      Timer t;
      tr.run(0, 0, gr.binOf(wi), wi);
      const double tp = t.seconds();
      const WaveSettings w = waveSettings("area", 256, 0);
      auto e = makeWaveEstimator(
          WaveContext{g, scene, al, {0.55}, gr, CoherenceWindow::fromCoherenceLength(50, 20, 20, true), w});
      Timer t2;
      e->run(0, gr.binOf(wi), wi);
      cost("resolution", std::to_string(nt) + " x " + std::to_string(np) + " GM", tp);
      cost("resolution", std::to_string(nt) + " x " + std::to_string(np) + " WS (256 samples/bin)", t2.seconds());
    }
    Material bk7 = named("BK7");
    for (int nl : {1, 8, 32}) {
      std::vector<double> lambdas;
      for (int i = 0; i < nl; ++i) lambdas.push_back(0.4 + (i + 0.5) * 0.3 / nl);
      PathTracerSettings ps;
      ps.paths = 1000000;
      {
        PathTracer tr(scene, al, lambdas, grid, ps);
        Timer t;
        tr.run(0, 0, bin, wi);
        cost("wavelengths", std::to_string(nl) + " λ, Al GM (one path, per-λ Fresnel weights)", t.seconds());
      }
      if (nl <= 8) {
        PathTracer tr(scene, bk7, lambdas, grid, ps);
        Timer t;
        tr.run(0, 0, bin, wi);
        cost("wavelengths", std::to_string(nl) + " λ, BK7 GM (dispersion: paths per λ)", t.seconds());
      }
      const WaveSettings w = waveSettings("area", 256, 0);
      auto e = makeWaveEstimator(
          WaveContext{g, scene, al, lambdas, grid, CoherenceWindow::fromCoherenceLength(50, 20, 20, true), w});
      Timer t;
      e->run(0, bin, wi);
      cost("wavelengths", std::to_string(nl) + " λ, Al WS (shared rays, per-λ phases)", t.seconds());
    }
  }
  return 0;
}
