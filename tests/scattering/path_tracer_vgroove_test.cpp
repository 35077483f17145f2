// 90° V-groove grating with perfect-mirror facets, light in the plane across the grooves
// against closed-form geometry, derived here:
// Profile: valley at x = 0, ridge at x = Λ/2 (height Λ/2), facets A (z = x, normal (−1,0,1)/√2) and
// B (z = Λ − x, normal (1,0,1)/√2). Light from wi = (sin θ, 0, cos θ), 0 <= θ < 45°: both facets are
// fully lit; the power on A is (1 − tan θ)/2 and on B (1 + tan θ)/2 of the total.
//  - From A the mirror direction is (−cos θ, 0, −sin θ): down into the neighbouring facet, which
//    sends it back along wi (two bounces, retro-reflection).
//  - From B the mirror direction is (cos θ, 0, sin θ) (polar angle 90° − θ). A point on B at
//    fractional distance u from the ridge reaches the next facet iff u >= 2t/(1+t), t = tan θ; the
//    second bounce again returns along wi. So one bounce (coherent) carries
//    (1+t)/2 · 2t/(1+t) = tan θ of the power, into polar angle 90° − θ, and two bounces (multiple)
//    carry 1 − tan θ, retro-reflected into the incidence direction.
#include <gtest/gtest.h>

#include <cmath>

#include "geometry/generators.h"
#include "scattering_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {
Scenario vgroove(uint64_t paths) {
  PathTracerSettings s;
  s.paths = paths;
  return Scenario(makeRidged(10, 10, 2.0, 90.0, 0), material("mirror"), ThetaPhiGrid{180, 72}, {0.55}, s);
}
// Energy of a component in the bins whose polar angle range contains theta_deg and whose azimuth
// is within one bin of phi = 0 (the plane of incidence).
double energyNear(const Scenario& sc, const TileResult& r, Component c, double theta_deg, bool anyPhi = false) {
  double e = 0;
  for (int b = 0; b < r.nBins; ++b) {
    if (!sc.grid.isUpper(b)) continue;
    Vec3 w = sc.grid.centre(b);
    double th = degrees(sphericalTheta(w)), ph = degrees(sphericalPhi(w));
    bool inPlane = anyPhi || ph < 5.01 || ph > 354.99;
    if (inPlane && std::abs(th - theta_deg) <= 0.25 + 1e-9) e += r.at(c, 0, b) * sc.grid.projectedSolidAngle(b);
  }
  return e;
}
}  // namespace

TEST(VGroove, NormalIncidenceIsPureRetroreflectionWithTwoBounces) {
  Scenario sc = vgroove(20000);
  Vec3 wi{0, 0, 1};
  int bin = sc.grid.binOf(wi);
  for (uint64_t p = 0; p < 2000; ++p) {
    auto rec = sc.tracer->replay(0, bin, p, 0, wi);
    ASSERT_EQ(rec.depth, 2) << "path " << p;
    EXPECT_NEAR(dot(rec.wo, wi), 1.0, 1e-9) << "path " << p;
  }
  TileResult r = sc.tracer->run(0, 0, bin, wi);
  EXPECT_EQ(energy(r, sc.grid, Component::Coherent, 0, true), 0.0);
  EXPECT_NEAR(energy(r, sc.grid, Component::Multiple, 0, true), 1.0, 1e-12);
  // The retro-reflection bin of a theta-phi grid at the pole is the polar cap (row 0, all phi).
  EXPECT_NEAR(energyNear(sc, r, Component::Multiple, 0.0, /*anyPhi=*/true), 1.0, 1e-12);
}

class VGrooveOblique : public ::testing::TestWithParam<double> {};

TEST_P(VGrooveOblique, SplitBetweenOneAndTwoBouncesMatchesGeometry) {
  const double theta = GetParam();
  const uint64_t N = 200000;
  Scenario sc = vgroove(N);
  Vec3 wi = sphericalDirection(radians(theta), 0.0);
  TileResult r = sc.tracer->run(0, 0, sc.grid.binOf(wi), wi);
  const double t = std::tan(radians(theta));
  // Binomial standard error of a proportion estimated from N paths.
  const double se = std::sqrt(t * (1 - t) / double(N));
  double single = energy(r, sc.grid, Component::Coherent, 0, true);
  double dbl = energy(r, sc.grid, Component::Multiple, 0, true);
  EXPECT_NEAR(single, t, 4 * se);
  EXPECT_NEAR(dbl, 1 - t, 4 * se);
  EXPECT_NEAR(single + dbl, 1.0, 1e-12);
  // Exit bins: one bounce at polar angle 90° − θ, two bounces back along wi.
  EXPECT_NEAR(energyNear(sc, r, Component::Coherent, 90 - theta), single, 1e-12);
  EXPECT_NEAR(energyNear(sc, r, Component::Multiple, theta), dbl, 1e-12);
}

INSTANTIATE_TEST_SUITE_P(Angles, VGrooveOblique, ::testing::Values(20.0, 40.0));
