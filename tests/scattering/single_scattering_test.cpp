// The deterministic facet sum of geometric single scattering (src/scattering/single_scattering.h)
// against closed forms (Fresnel on a flat interface, the 90° V-groove's one-bounce share tan θ),
// against the path tracer's depth-1 tally within its standard errors, and on hard cases (grazing
// incidence, total internal reflection, degenerate triangles, thread counts).
#include "scattering/single_scattering.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>

#include "geometry/generators.h"
#include "optics/fresnel.h"
#include "scattering_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

struct Facets {
  Scenario sc;
  FacetSingleScattering sum;
  Facets(Microgeometry g, Material m, DirectionGrid::Layout layout, std::vector<double> lambdas, uint64_t paths = 1000)
      : sc(std::move(g), std::move(m), layout, std::move(lambdas),
           [&] {
             PathTracerSettings s;
             s.paths = paths;
             s.seed = 7;
             return s;
           }()),
        sum(sc.geometry, *sc.scene, sc.mat, sc.lambda_um, sc.grid) {}
  TileResult run(double theta_deg, double phi_deg, bool exact) const {
    const int bin = sc.grid.binOfAngles(theta_deg, phi_deg);
    std::optional<Vec3> dir;
    if (exact) dir = sphericalDirection(radians(theta_deg), radians(phi_deg));
    return sum.run(0, 0, bin, dir);
  }
};

// Σ_b err_b Ω⊥ over a hemisphere: the facet sum's error bound on an energy.
double errorSum(const TileResult& r, const DirectionGrid& g, int l, bool upper) {
  double e = 0;
  for (int b = 0; b < r.nBins; ++b)
    if (g.isUpper(b) == upper)
      e += r.stdError[int(Component::Coherent)][size_t(l) * r.nBins + b] * g.projectedSolidAngle(b);
  return e;
}

}  // namespace

TEST(SingleScattering, FlatConductorIsFresnelInTheMirrorBin) {
  Facets f(makeFlat(10, 10, 0), material("Al"), ThetaPhiGrid{8, 16}, {0.45, 0.65});
  ASSERT_TRUE(f.sum.maxSlope());
  EXPECT_EQ(*f.sum.maxSlope(), 0.0);
  for (double theta : {0.0, 40.0, 70.0, 89.0}) {
    const TileResult r = f.run(theta, 30.0, true);
    expectFinite(r);
    EXPECT_EQ(r.rays, 0u) << "a flat patch needs no visibility ray";
    const int mirror = f.sc.grid.binOf(reflect(sphericalDirection(radians(theta), radians(30.0)), Vec3{0, 0, 1}));
    for (int l = 0; l < 2; ++l) {
      const double F = fresnelReflectance(std::cos(radians(theta)), 1.0, f.sc.mat.ior(f.sc.lambda_um[size_t(l)]));
      EXPECT_NEAR(r.at(Component::Coherent, l, mirror) * f.sc.grid.projectedSolidAngle(mirror), F, 1e-6) << theta;
      EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, l, true), F, 1e-6) << theta;
      EXPECT_EQ(energy(r, f.sc.grid, Component::Coherent, l, false), 0.0);
    }
  }
  // Over an incidence bin: the cosine-weighted mean of F over the bin (a 400 x 400 midpoint rule),
  // all of it in the mirrored bin (a theta-phi grid with even n_phi maps bins onto bins).
  const int bin = f.sc.grid.binOfAngles(50.0, 30.0);
  const TileResult r = f.sum.run(0, 0, bin, std::nullopt);
  double mean = 0;
  const int n = 400;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const DirectionSample d = f.sc.grid.sampleCosine(bin, (i + 0.5) / n, (j + 0.5) / n);
      mean += d.weight * fresnelReflectance(d.w.z, 1.0, f.sc.mat.ior(0.45)) / (double(n) * n);
    }
  EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, true), mean, 2e-5);
  EXPECT_LT(errorSum(r, f.sc.grid, 0, true), 1e-4);
}

TEST(SingleScattering, FlatGlassSplitsFresnelAndReflectsTotallyBeyondTheCriticalAngle) {
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  Facets f(makeFlat(10, 10, 0), glass, ThetaPhiGrid{8, 16}, {0.55});
  for (double theta : {0.0, 35.0, 80.0}) {
    const TileResult r = f.run(theta, 0.0, true);
    expectFinite(r);
    const double F = fresnelReflectance(std::cos(radians(theta)), 1.0, Complex(1.5, 0));
    EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, true), F, 1e-12);
    EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, false), 1 - F, 1e-12);
  }
  // From inside: below the critical angle (41.8°) split by Fresnel, beyond it all reflected.
  const double below = 180 - 30.0, beyond = 180 - 50.0;
  TileResult r = f.run(below, 0.0, true);
  const double F = fresnelReflectance(std::cos(radians(30.0)), 1.5, Complex(1.0, 0));
  EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, false), F, 1e-12);
  EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, true), 1 - F, 1e-12);
  r = f.run(beyond, 0.0, true);
  expectFinite(r);
  EXPECT_NEAR(energy(r, f.sc.grid, Component::Coherent, 0, false), 1.0, 1e-12);
  EXPECT_EQ(energy(r, f.sc.grid, Component::Coherent, 0, true), 0.0);
}

// The 90° V-groove of path_tracer_vgroove_test.cpp: with wi at θ in the plane across the grooves,
// one bounce carries tan θ of the power into polar angle 90° − θ (the rest is retro-reflected after
// two). Its walls are steeper than any exit direction, so every pair casts rays: the facets' points
// decide, and the reported error must cover the difference.
TEST(SingleScattering, VGrooveOneBounceShareIsTanTheta) {
  Facets f(makeRidged(10, 10, 2.0, 90.0, 0), material("mirror"), ThetaPhiGrid{180, 72}, {0.55});
  for (double theta : {10.0, 20.0, 30.0}) {
    const TileResult r = f.run(theta, 0.0, true);
    expectFinite(r);
    EXPECT_GT(r.rays, 0u);
    const double single = energy(r, f.sc.grid, Component::Coherent, 0, true);
    const double err = errorSum(r, f.sc.grid, 0, true);
    EXPECT_NEAR(single, std::tan(radians(theta)), err) << theta;
    EXPECT_LT(err, 0.1) << theta;
    // All of it at polar angle 90° − θ, in the plane of incidence.
    const int out = f.sc.grid.binOf(Vec3{std::cos(radians(theta)), 0, std::sin(radians(theta))});
    EXPECT_NEAR(r.at(Component::Coherent, 0, out) * f.sc.grid.projectedSolidAngle(out), single, 1e-12) << theta;
    std::printf("V-groove at %.0f deg: one bounce %.5f (tan theta %.5f, bound %.5f, %llu rays)\n", theta, single,
                std::tan(radians(theta)), err, (unsigned long long)r.rays);
  }
}

// Against the path tracer's depth-1 tally (an independent estimator of the same quantity): per
// hemisphere the energies within 4 combined standard errors, and the L1 distance of the tables
// within what the two errors explain (√(2/π) Σ sd + 4 √Σ sd², as integration.effects_auto judges).
TEST(SingleScattering, MatchesThePathTracersDepthOneTally) {
  struct Case {
    const char* name;
    Microgeometry g;
    Material m;
    double theta, phi;
    bool rays;  // whether visibility rays are expected
    bool collimated = false;
  };
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  std::vector<Case> cases;
  cases.push_back({"Al sine grating, 2 um period, 30 nm", makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), material("Al"),
                   40, 20, false});
  cases.push_back({"Al sine grating at grazing incidence", makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), material("Al"),
                   84, 0, true});
  cases.push_back(
      {"glass sine grating, 2 um period, 0.3 um", makeSineGrating(2.0, 0.3, 2.0, 0.3, 64, 0), glass, 50, 0, true});
  cases.push_back(
      {"rough Au Gaussian heightfield", makeGaussian(10, 10, 0.3, 2.0, 24, 24, 3), material("Au"), 30, 45, true});
  // A mesh (not a heightfield): every pair by rays, so a collimated beam (a bin's 1280 directions
  // would take 27 s here; the transport leaves such tiles to the path tracer).
  cases.push_back(
      {"mirror hemispheres (collimated; a mesh: every pair by rays)",
       makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.5}),
       material("mirror"), 20, 10, true, true});
  for (Case& c : cases) {
    const uint64_t paths = 400000;
    Facets f(std::move(c.g), c.m, ThetaPhiGrid{8, 16}, {0.5}, paths);
    const int bin = f.sc.grid.binOfAngles(c.theta, c.phi);
    std::optional<Vec3> beam;
    if (c.collimated) beam = sphericalDirection(radians(c.theta), radians(c.phi));
    const TileResult a = f.sum.run(0, 0, bin, beam);
    const TileResult b = f.sc.tracer->run(0, 0, bin, beam);
    expectFinite(a);
    EXPECT_EQ(a.rays > 0, c.rays) << c.name;
    for (bool up : {true, false}) {
      const double ea = energy(a, f.sc.grid, Component::Coherent, 0, up);
      const double eb = energy(b, f.sc.grid, Component::Coherent, 0, up);
      const double se = energyStdError(b, f.sc.grid, Component::Coherent, 0, up);
      EXPECT_NEAR(ea, eb, 4 * se + errorSum(a, f.sc.grid, 0, up)) << c.name << (up ? " reflected" : " transmitted");
    }
    double l1 = 0, sdSum = 0, sd2 = 0;
    for (int k = 0; k < a.nBins; ++k) {
      const double op = f.sc.grid.projectedSolidAngle(k);
      const double sd = std::hypot(a.stdError[0][size_t(k)], b.stdError[0][size_t(k)]) * op;
      l1 += std::abs(a.at(Component::Coherent, 0, k) - b.at(Component::Coherent, 0, k)) * op;
      sdSum += sd;
      sd2 += sd * sd;
    }
    EXPECT_LT(l1, std::sqrt(2 / kPi) * sdSum + 4 * std::sqrt(sd2)) << c.name;
    std::printf(
        "%-60s facet sum %.4f (error bound %.4f, %llu rays, %.3f s) vs paths %.4f +- %.4f (%.3f s); L1 %.4f\n", c.name,
        energy(a, f.sc.grid, Component::Coherent, 0, true) + energy(a, f.sc.grid, Component::Coherent, 0, false),
        errorSum(a, f.sc.grid, 0, true) + errorSum(a, f.sc.grid, 0, false), (unsigned long long)a.rays, a.seconds,
        energy(b, f.sc.grid, Component::Coherent, 0, true) + energy(b, f.sc.grid, Component::Coherent, 0, false),
        std::hypot(energyStdError(b, f.sc.grid, Component::Coherent, 0, true),
                   energyStdError(b, f.sc.grid, Component::Coherent, 0, false)),
        b.seconds, l1);
  }
}

TEST(SingleScattering, SameBytesForAnyThreadCountAndNoNaNAtTheHorizon) {
  Microgeometry g = makeSineGrating(2.0, 0.3, 2.0, 0.3, 64, 0);
  // A degenerate (zero-area) triangle: ignored, not a NaN normal.
  g.triangles.push_back({g.triangles[0][0], g.triangles[0][0], g.triangles[0][1]});
  Facets f(std::move(g), material("Au"), ThetaPhiGrid{8, 16}, {0.5, 0.6});
  const int bin = f.sc.grid.binOfAngles(80.0, 0.0);
  TileResult one;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = f.sum.run(0, 0, bin, std::nullopt);
  }
  const TileResult many = f.sum.run(0, 0, bin, std::nullopt);
  EXPECT_EQ(one.value[0], many.value[0]);
  EXPECT_EQ(one.stdError[0], many.stdError[0]);
  for (double theta : {89.0, 89.99, 90.0 - 1e-9}) {
    const TileResult r = f.run(theta, 0.0, true);
    expectFinite(r);
    for (int l = 0; l < 2; ++l)
      EXPECT_LE(energy(r, f.sc.grid, Component::Coherent, l, true), 1.0 + errorSum(r, f.sc.grid, l, true) + 1e-12);
  }
}
