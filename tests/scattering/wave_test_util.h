// Helpers for the wave-optics tests: one wave tile on a geometry, hemispherical integrals.
#pragma once
#include <cmath>
#include <memory>
#include <string>

#include "geometry/generators.h"
#include "optics/fresnel.h"
#include "scattering/wave_estimator.h"
#include "scattering_test_util.h"

namespace mbsdf::test {

struct WaveScenario {
  Microgeometry geometry;
  Material mat;
  DirectionGrid grid;
  std::vector<double> lambda_um;
  std::unique_ptr<PeriodicScene> scene;
  std::unique_ptr<WaveEstimator> estimator;
  WaveScenario(Microgeometry g, Material m, DirectionGrid::Layout layout, std::vector<double> lambdas,
               double coherenceLength_um, WaveSettings s)
      : geometry(std::move(g)), mat(std::move(m)), grid(layout), lambda_um(std::move(lambdas)) {
    scene = std::make_unique<PeriodicScene>(geometry);
    estimator = makeWaveEstimator(WaveContext{
        geometry, *scene, mat, lambda_um, grid,
        CoherenceWindow::fromCoherenceLength(coherenceLength_um, geometry.sizeX, geometry.sizeY, geometry.periodic),
        s});
  }
  WaveTileResult run(double theta_deg, double phi_deg, bool exact, int tile = 0) const {
    Vec3 w = sphericalDirection(radians(theta_deg), radians(phi_deg));
    return estimator->run(tile, grid.binOf(w), exact ? std::optional<Vec3>(w) : std::nullopt);
  }
  // Σ f Ω⊥ over a hemisphere (upper = true) and its standard error (root-sum-square).
  std::pair<double, double> integral(const std::vector<double>& f, const std::vector<double>& e, int l,
                                     bool upper) const {
    double s = 0, v = 0;
    for (int b = 0; b < grid.binCount(); ++b)
      if (grid.isUpper(b) == upper) {
        double op = grid.projectedSolidAngle(b);
        s += f[size_t(l) * grid.binCount() + b] * op;
        v += std::pow(e[size_t(l) * grid.binCount() + b] * op, 2);
      }
    return {s, std::sqrt(v)};
  }
};

// Energy of the upper-hemisphere bins whose centre lies within `radius` of direction w in the
// projected (x, y) plane of directions.
inline double energyAround(const DirectionGrid& g, const std::vector<double>& f, int l, const Vec3& w, double radius) {
  double e = 0;
  for (int b = 0; b < g.binsPerHemisphere(); ++b) {
    Vec3 c = g.centre(b);
    if (std::hypot(c.x - w.x, c.y - w.y) <= radius) e += f[size_t(l) * g.binCount() + b] * g.projectedSolidAngle(b);
  }
  return e;
}

// Flat interfaces under a collimated beam through a deterministic estimator (orders regime, δc =
// 50 µm on a 4 µm patch): Σ f Ω⊥ = Fresnel within 0.1 % for gold at 0°, 30°, 60°, 70° and glass
// (reflection and transmission) at 40°.
inline void expectFlatInterfacesGiveFresnel(const std::string& estimator) {
  WaveSettings ws;
  ws.estimator = waveEstimatorKind(estimator);
  for (double theta : {0.0, 30.0, 60.0, 70.0}) {
    WaveScenario sc(makeFlat(4, 4, 1.0), material("Au"), ThetaPhiGrid{30, 60}, {0.55}, 50.0, ws);
    WaveTileResult r = sc.run(theta, 10.0, true);
    auto [R, se] = sc.integral(r.fws, r.fwsErr, 0, true);
    const double ref = fresnelReflectance(std::cos(radians(theta)), 1.0, sc.mat.ior(0.55));
    EXPECT_NEAR(R / ref, 1.0, 1e-3) << estimator << " " << theta;
    EXPECT_EQ(se, 0.0);
  }
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  WaveScenario sc(makeFlat(4, 4, 1.0), glass, ThetaPhiGrid{30, 60}, {0.55}, 50.0, ws);
  WaveTileResult r = sc.run(40.0, 0.0, true);
  const double R = fresnelReflectance(std::cos(radians(40.0)), 1.0, Complex(1.5, 0));
  EXPECT_NEAR(sc.integral(r.fws, r.fwsErr, 0, true).first / R, 1.0, 1e-3) << estimator;
  EXPECT_NEAR(sc.integral(r.fws, r.fwsErr, 0, false).first / (1 - R), 1.0, 1e-3) << estimator;
}

}  // namespace mbsdf::test
