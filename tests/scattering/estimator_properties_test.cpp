// One set of properties checked over every estimator, as pbrt runs one χ² test over every BxDF:
// the geometric ones (path tracer, the facet sum of single scattering, the microflake walk) and the
// wave ones (`area`, `paper`, `orders`, `exact`, `fft`), each on a conductor and a dielectric lit
// from above and from inside, on a grid of bin-averaged incidences including grazing ones:
//  - no NaN or Inf in any value or standard error;
//  - the geometric estimators conserve energy: the energy leaving (every component, truncated
//    paths included) is within 4 standard errors of 1 for the lossless dielectric and at most that
//    for the conductor; the wave ones stay within the scalar model's bound (no bin above the
//    incident power, the hemispheres' energy at most 1 + 5 % + 4 standard errors: the model's own
//    excess, docs/physics.md §5);
//  - determinism: the same tile computed with one thread and with all of them is bit-identical.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <functional>
#include <string>

#include "microflake/microflake_walk.h"
#include "microflake/ndf.h"
#include "scattering/single_scattering.h"
#include "scattering/tile_result.h"
#include "scattering_test_util.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

Material glassOf(double n) {
  Material m;
  m.model = Dielectric{ConstantIndex{n, 0}};
  return m;
}

// Values and errors, all finite.
void expectFinite(const std::vector<double>& v, const std::string& what) {
  for (size_t i = 0; i < v.size(); ++i) ASSERT_TRUE(std::isfinite(v[i])) << what << " entry " << i;
}

// Runs `compute` with one thread and with every thread; the results must be bit-identical.
template <class R>
R deterministic(const std::function<R()>& compute, const std::function<std::vector<double>(const R&)>& flat,
                const std::string& what) {
  R one;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = compute();
  }
  R all = compute();
  const std::vector<double> a = flat(one), b = flat(all);
  EXPECT_EQ(a.size(), b.size()) << what;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (!(a[i] == b[i] || (std::isnan(a[i]) && std::isnan(b[i])))) {
      ADD_FAILURE() << what << ": entry " << i << " differs between 1 thread and all: " << a[i] << " vs " << b[i];
      break;
    }
  return all;
}

std::vector<double> flatTile(const TileResult& r) {
  std::vector<double> v;
  for (int c = 0; c < kComponentCount; ++c) {
    v.insert(v.end(), r.value[c].begin(), r.value[c].end());
    v.insert(v.end(), r.stdError[c].begin(), r.stdError[c].end());
  }
  for (const auto* x : {&r.truncated, &r.leaked, &r.missed}) v.insert(v.end(), x->begin(), x->end());
  return v;
}

std::vector<double> flatWave(const WaveTileResult& r) {
  std::vector<double> v = r.fws;
  v.insert(v.end(), r.fwsErr.begin(), r.fwsErr.end());
  return v;
}

// Energy leaving a geometric tile (energyBalance + 1: every traced component, both hemispheres,
// plus truncated, leaked and missed) and its standard error from the per-path moments.
std::pair<double, double> geometricEnergy(const TileResult& r, const DirectionGrid& grid, int l) {
  std::vector<Component> present, traced;
  for (Component c : {Component::Coherent, Component::Multiple}) {
    if (!r.has(c)) continue;
    present.push_back(c);
    if (!r.pathMoments[int(c)].empty()) traced.push_back(c);
  }
  const double e = energyBalance(r, grid, present, true)[size_t(l)] + 1;
  const std::vector<double> se = traced.empty() ? std::vector<double>{} : r.pathEnergyStdError(traced, -1);
  return {e, se.empty() ? 0.0 : se[size_t(l)]};
}

const std::vector<double> kThetas = {0.0, 35.0, 75.0, 89.0, 120.0, 170.0};  // > 90: from inside

}  // namespace

TEST(EstimatorProperties, GeometricEstimators) {
  const Microgeometry g = makeGaussian(6, 6, 0.3, 1.5, 12, 12, 21);
  const DirectionGrid::Layout layout = ThetaPhiGrid{9, 18};
  int checked = 0;
  for (const bool conductor : {true, false}) {
    const Material mat = conductor ? material("Al") : glassOf(1.5);
    PathTracerSettings ps;
    ps.paths = 20000;
    Scenario sc(g, mat, layout, {0.5, 0.7}, ps);
    FacetSingleScattering facets(g, *sc.scene, mat, {0.5, 0.7}, sc.grid);
    MicroflakeSettings ms;
    ms.paths = 20000;
    const MicroflakeDistribution flakes(GgxNdf{0.4, 0.4});
    const MicroflakeWalk walk(flakes, mat, {0.5, 0.7}, sc.grid, ms);
    for (double theta : kThetas) {
      if (conductor && theta > 90) continue;
      const int bin = sc.grid.binOfAngles(theta, 10.0);
      const std::string where = std::string(conductor ? "Al" : "glass") + " θ " + std::to_string(int(theta));
      // Every geometric estimator through the one interface the run uses.
      const std::vector<std::pair<std::string, const GeometricEstimator*>> estimators = {
          {"path tracer", sc.tracer.get()}, {"facet sum", &facets}, {"microflake walk", &walk}};
      for (const auto& [name, estimator] : estimators) {
        const std::string what = name + ", " + where;
        // The facet sum's visibility rays make grazing bins its costly case (seconds each): one
        // conductor at 75° stands for them.
        if (estimator->deterministic() && (theta == 89.0 || (theta == 75.0 && !conductor))) continue;
        const TileRequest request{3, 0, bin, std::nullopt};
        const TileResult r = deterministic<TileResult>([&] { return estimator->run(request, {}); }, flatTile, what);
        expectFinite(flatTile(r), what);
        for (int l = 0; l < r.nLambda; ++l) {
          const auto [e, se] = geometricEnergy(r, sc.grid, l);
          if (estimator->deterministic()) {
            EXPECT_LE(e, 1 + 1e-6) << what;  // single scattering only: at most what arrives
          } else if (conductor) {
            EXPECT_LE(e, 1 + 4 * se + 1e-12) << what;
          } else {
            EXPECT_NEAR(e, 1.0, 4 * se + 1e-9) << what << " λ " << l;
          }
        }
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 3 * (4 + 6) - 3);
}

TEST(EstimatorProperties, WaveEstimators) {
  const Microgeometry g = makeGaussian(2, 2, 0.05, 0.5, 24, 24, 9);
  int checked = 0;
  for (const char* est : {"area", "paper", "orders", "exact", "fft"}) {
    for (const bool conductor : {true, false}) {
      WaveSettings ws;
      ws.estimator = waveEstimatorKind(est);
      ws.samplesPerBin = std::string(est) == "paper" ? 16 : 256;
      ws.pointsPerDirection = 16;
      const Material mat = conductor ? material("Al") : glassOf(1.5);
      WaveScenario sc(g, mat, ThetaPhiGrid{9, 18}, {0.5, 0.7}, 20.0, ws);
      for (double theta : kThetas) {
        if (conductor && theta > 90) continue;
        const std::string what =
            std::string(est) + ", " + (conductor ? "Al" : "glass") + " θ " + std::to_string(int(theta));
        const int bin = sc.grid.binOfAngles(theta, 10.0);
        const WaveTileResult r =
            deterministic<WaveTileResult>([&] { return sc.estimator->run(5, bin, std::nullopt); }, flatWave, what);
        expectFinite(flatWave(r), what);
        if (std::string(est) == "paper") {  // its Var/P bias puts energies above 1 (kept for comparison)
          ++checked;
          continue;
        }
        for (int l = 0; l < r.nLambda; ++l) {
          double total = 0, var = 0;
          for (int b = 0; b < sc.grid.binCount(); ++b) {
            const size_t i = size_t(l) * size_t(sc.grid.binCount()) + size_t(b);
            const double op = sc.grid.projectedSolidAngle(b);
            EXPECT_LE(std::abs(r.fws[i]) * op, 1.0 + 6 * r.fwsErr[i] * op) << what << " bin " << b;
            total += r.fws[i] * op;
            var += std::pow(r.fwsErr[i] * op, 2);
          }
          EXPECT_LE(total, 1.05 + 4 * std::sqrt(var)) << what << " λ " << l;
        }
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 5 * (4 + 6));
}
