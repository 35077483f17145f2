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
//    roulette).
// scripts/accuracy-vs-time runs it and turns the CSV into a table and a log-log plot.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "geometry/generators.h"
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

void row(const char* c, const std::string& est, long budget, int seed, double sec, double err) {
  std::printf("%s,%s,%ld,%d,%.6g,%.6g\n", c, est.c_str(), budget, seed, sec, err);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const int seeds = argc > 1 ? std::atoi(argv[1]) : 3;
  std::printf("case,estimator,budget,seed,seconds,error\n");

  // Flat aluminium at 40° through the wave estimators.
  {
    Microgeometry g = makeFlat(2, 2, 0);
    PeriodicScene scene(g);
    Material al = named("Al");
    DirectionGrid grid(ThetaPhiGrid{30, 60});
    Vec3 wi = sphericalDirection(radians(40), radians(17));
    const double F = fresnelReflectance(std::cos(radians(40)), 1.0, al.ior(0.55));
    for (const std::string est : {"orders", "area", "paper"})
      for (long budget : {64L, 256L, 1024L, 4096L, 16384L}) {
        if (est != "orders" && budget > 4096) continue;
        for (int s = 0; s < seeds; ++s) {
          WaveSettings ws;
          ws.estimator = est;
          ws.samplesPerBin = int(budget);
          ws.pointsPerDirection = 16;
          ws.seed = uint64_t(s + 1);
          auto e = makeWaveEstimator(WaveContext{g, scene, al, {0.55}, grid,
                                                 CoherenceWindow::fromCoherenceLength(50, 2, 2, true), ws});
          Timer t;
          WaveTileResult r = e->run(s, grid.binOf(wi), wi);
          row("flat_al_40", est, budget, s, t.seconds(), std::abs(hemisphere(grid, r.fws, true) - F) / F);
        }
      }
  }
  // Sine grating orders.
  {
    Microgeometry g = makeSineGrating(5, 1, 5, 0.05, 64, 0);
    PeriodicScene scene(g);
    Material mirror = named("mirror");
    DirectionGrid grid(ThetaPhiGrid{90, 72});
    const double k0 = 2 * kPi / 0.5;
    for (const std::string est : {"orders", "area", "paper"})
      for (long budget : {64L, 256L, 1024L, 4096L, 16384L}) {
        if (est != "orders" && budget > 1024) continue;
        for (int s = 0; s < seeds; ++s) {
          WaveSettings ws;
          ws.estimator = est;
          ws.samplesPerBin = int(budget);
          ws.pointsPerDirection = 16;
          ws.seed = uint64_t(s + 1);
          auto e = makeWaveEstimator(WaveContext{g, scene, mirror, {0.5}, grid,
                                                 CoherenceWindow::fromCoherenceLength(50, 5, 1, true), ws});
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
  {
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
  return 0;
}
