// Flat interfaces against Fresnel: conductors put all energy in the specular
// bin with albedo = unpolarised Fresnel reflectance; dielectrics conserve energy, refract into the
// Snell bin and show total internal reflection without NaN.
#include <gtest/gtest.h>

#include <cmath>

#include "geometry/generators.h"
#include "scattering/path_tracer.h"
#include "scattering_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

// Cosine-weighted average of the Fresnel reflectance over the theta range of an incidence bin
// (midpoint rule in sin²θ, which is uniform for cosine-weighted directions): the exact expectation
// of the estimator, computed without Monte Carlo.
double binAveragedFresnel(const DirectionGrid& g, int bin, double n1, Complex n2, bool perfect) {
  if (perfect) return 1.0;
  Vec3 c = g.centre(bin);
  const auto& tp = std::get<ThetaPhiGrid>(g.layout());
  int t = int(sphericalTheta(c) / (0.5 * kPi) * tp.nTheta);
  double s0 = std::sin(t * 0.5 * kPi / tp.nTheta), s1 = std::sin((t + 1) * 0.5 * kPi / tp.nTheta);
  const int n = 4000;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    double sin2 = s0 * s0 + (s1 * s1 - s0 * s0) * (i + 0.5) / n;
    sum += fresnelReflectance(std::sqrt(1 - sin2), n1, n2);
  }
  return sum / n;
}

}  // namespace

class FlatConductor : public ::testing::TestWithParam<std::tuple<std::string, double>> {};

TEST_P(FlatConductor, AllEnergyInSpecularBinWithFresnelAlbedo) {
  auto [name, theta] = GetParam();
  PathTracerSettings s;
  s.paths = 20000;
  Scenario setup(makeFlat(10, 10, 0), material(name), ThetaPhiGrid{90, 360}, {0.45, 0.55, 0.65}, s);
  TileResult r = setup.run(theta, 10.0);
  TileResult exactRun = setup.run(theta, 10.0, /*exact=*/true);
  int inc = setup.grid.binOfAngles(theta, 10.0);
  Vec3 ci = setup.grid.centre(inc);
  int spec = setup.grid.binOf({-ci.x, -ci.y, ci.z});
  for (int l = 0; l < 3; ++l) {
    double total = energy(r, setup.grid, Component::Coherent, l, true);
    double inSpec = r.at(Component::Coherent, l, spec) * setup.grid.projectedSolidAngle(spec);
    EXPECT_GE(inSpec, 0.999 * total) << name << " theta " << theta;
    EXPECT_EQ(energy(r, setup.grid, Component::Multiple, l, true), 0.0);
    Complex n2 = setup.mat.isPerfectConductor() ? Complex(0, 0) : setup.mat.ior(setup.lambda_um[l]);
    double expected = binAveragedFresnel(setup.grid, inc, 1.0, n2, setup.mat.isPerfectConductor());
    EXPECT_NEAR(total, expected, 0.005 * expected) << name << " theta " << theta << " lambda " << setup.lambda_um[l];
    // A collimated beam at exactly theta against the point value of Fresnel.
    double point = setup.mat.isPerfectConductor() ? 1.0 : fresnelReflectance(std::cos(radians(theta)), 1.0, n2);
    double exact = energy(exactRun, setup.grid, Component::Coherent, l, true);
    EXPECT_NEAR(exact, point, 0.005 * point) << name << " theta " << theta;
    EXPECT_EQ(r.truncated[l], 0.0);
    EXPECT_EQ(r.leaked[l], 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Materials, FlatConductor,
                         ::testing::Combine(::testing::Values("Al", "Au", "mirror"),
                                            ::testing::Values(0.5, 30.0, 60.0, 85.0)));

class FlatDielectric : public ::testing::TestWithParam<double> {};

// theta > 90: light from inside the glass.
TEST_P(FlatDielectric, EnergyConservedSnellBinAndTir) {
  double theta = GetParam();
  PathTracerSettings s;
  s.paths = 100000;
  Scenario setup(makeFlat(10, 10, 0), material("BK7"), ThetaPhiGrid{90, 360}, {0.45, 0.65}, s);
  TileResult r = setup.run(theta, 20.5, /*exact=*/true);  // 20.5: off the 1° bin edges
  const bool inside = theta > 90;
  const double cosI = std::abs(std::cos(radians(theta)));
  for (int l = 0; l < 2; ++l) {
    double n = setup.mat.ior(setup.lambda_um[l]).real();
    double n1 = inside ? n : 1.0, n2 = inside ? 1.0 : n;
    double Rexp = fresnelReflectance(cosI, n1, Complex(n2, 0));
    double R = energy(r, setup.grid, Component::Coherent, l, !inside);
    double T = energy(r, setup.grid, Component::Coherent, l, inside);
    EXPECT_NEAR(R + T, 1.0, 0.005);
    // Russian roulette with probability F: R is a binomial proportion.
    double se = std::sqrt(std::max(Rexp * (1 - Rexp), 1e-12) / double(s.paths));
    EXPECT_NEAR(R, Rexp, 4 * se + 1e-12) << "theta " << theta;
    double sinT = n1 / n2 * std::sin(radians(theta));
    if (sinT >= 1) {
      EXPECT_EQ(T, 0.0) << "total internal reflection";
    } else {
      // Snell direction (pointing away from the surface on the far side).
      double thetaT = std::asin(sinT);
      Vec3 wt = sphericalDirection(thetaT, radians(20.5 + 180.0));
      if (!inside) wt.z = -wt.z;
      int snell = setup.grid.binOf(wt);
      double inSnell = r.at(Component::Coherent, l, snell) * setup.grid.projectedSolidAngle(snell);
      EXPECT_NEAR(inSnell, T, 1e-12 + 1e-9 * T);
    }
    for (int b = 0; b < r.nBins; ++b) {
      ASSERT_TRUE(std::isfinite(r.at(Component::Coherent, l, b)));
      ASSERT_TRUE(std::isfinite(r.stdError[int(Component::Coherent)][size_t(l) * r.nBins + b]));
    }
  }
}

// Outside: 0°, 30°, 60°, 85°. Inside (180° − θ): 30° below the critical angle (~41°),
// 41.3° just beyond it, 60° beyond.
INSTANTIATE_TEST_SUITE_P(Angles, FlatDielectric, ::testing::Values(0.0, 30.0, 60.0, 85.0, 150.0, 138.7, 120.0));

TEST(FlatDielectric, BinAveragedIncidenceConservesEnergy) {
  PathTracerSettings s;
  s.paths = 50000;
  Scenario setup(makeFlat(10, 10, 0), material("BK7"), ThetaPhiGrid{30, 60}, {0.55}, s);
  for (double theta : {10.0, 70.0, 160.0, 100.0}) {
    TileResult r = setup.run(theta, 0.0);
    double R = energy(r, setup.grid, Component::Coherent, 0, true);
    double T = energy(r, setup.grid, Component::Coherent, 0, false);
    EXPECT_NEAR(R + T, 1.0, 1e-9) << theta;
  }
}
