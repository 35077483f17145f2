// Scalar diffraction against references: grating efficiencies, the geometric
// limit, unbiasedness and convergence of the estimators, energy closure with the lost component,
// and finiteness at grazing angles.
#include <gtest/gtest.h>

#include <cmath>

#include "core/rng.h"
#include "geometry/generators.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

// Shallow sinusoidal reflective grating, perfect conductor, period 5 µm, amplitude 0.05 µm,
// λ = 0.5 µm, normal incidence: orders at sin θm = mλ/Λ with efficiencies J_m²(2 k0 h) (thin
// grating) within 0.01 absolute for |m| <= 3.
TEST(WaveGrating, SineGratingOrdersMatchBessel) {
  const double period = 5.0, h = 0.05, lambda = 0.5;
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Orders;
  ws.samplesPerBin = 4096;
  WaveScenario sc(makeSineGrating(period, 1.0, period, h, 64, 0), material("mirror"), ThetaPhiGrid{90, 72}, {lambda},
                  50.0, ws);
  WaveTileResult r = sc.run(0.0, 0.0, true);
  const double k0 = 2 * kPi / lambda;
  double total = 0;
  for (int m = -3; m <= 3; ++m) {
    // Order m leaves along ωo_x = −mλ/Λ; its lobe (σ = 8.3 µm: 0.007 wide) is summed over the bins
    // within 0.04 of it (orders are 0.1 apart).
    double sx = -m * lambda / period;
    double eta = energyAround(sc.grid, r.fws, 0, Vec3{sx, 0, std::sqrt(1 - sx * sx)}, 0.04);
    double expected = std::pow(std::cyl_bessel_j(double(std::abs(m)), 2 * k0 * h), 2);
    EXPECT_NEAR(eta, expected, 0.01) << "order " << m;
    RecordProperty("eta_" + std::to_string(m), std::to_string(eta));
    total += eta;
  }
  EXPECT_NEAR(total, 1.0, 0.01);
}

// Geometric limit: a smooth surface with features much larger than λ — WS and GS agree:
// Σ |f_ws − f_gs| Ω⊥ <= 0.05. Surface: a sine grating of period 40 µm and amplitude 2 µm (slopes up
// to 0.31, reflections up to 35°) at λ = 0.4 µm, under a coherence window of δc = 600 µm
// (σ = 100 µm: 15 standard deviations between neighbouring order lobes); the patch is
// 0.3 µm deep in y (below λ: no orders in y, the profile is y-invariant). Bins: an 11 x 11 disk
// grid, odd so that the plane of incidence runs through the middle of a pixel row rather than along
// bin edges, where ray-traced and diffracted light would be split differently between two bins;
// each pixel holds about 18 diffraction orders.
TEST(WaveGeometricLimit, SmoothSurfaceMatchesGeometricOptics) {
  const double lambda = 0.4;
  Microgeometry g = makeSineGrating(40.0, 0.3, 40.0, 2.0, 512, 0);
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Orders;
  ws.samplesPerBin = 4096;
  DirectionGrid::Layout layout = DiskGrid{11, 11};
  WaveScenario wave(g, material("mirror"), layout, {lambda}, 600.0, ws);
  WaveTileResult w = wave.run(0.0, 0.0, true);
  PathTracerSettings ps;
  ps.paths = 400000;
  Scenario geo(g, material("mirror"), layout, {lambda}, ps);
  TileResult t = geo.run(0.0, 0.0, true);
  double l1 = 0, ws_ = 0, gs = 0;
  for (int b = 0; b < wave.grid.binCount(); ++b) {
    double op = wave.grid.projectedSolidAngle(b);
    l1 += std::abs(w.fws[b] - t.at(Component::Coherent, 0, b)) * op;
    ws_ += w.fws[b] * op;
    gs += t.at(Component::Coherent, 0, b) * op;
  }
  RecordProperty("L1", std::to_string(l1));
  EXPECT_LE(l1, 0.05) << "WS " << ws_ << " GS " << gs;
}

// The area estimator is unbiased: its mean over 20 seeds at a small budget equals a large-budget
// reference within 3 standard errors in the diffuse bins; the paper's |mean|² is biased upward
// by about Var/P there (its reported error), which the test measures.
TEST(WaveUnbiased, AreaEstimatorMeanMatchesReference) {
  Microgeometry g = makeGaussian(2, 2, 0.15, 0.5, 32, 32, 4);
  DirectionGrid::Layout layout = ThetaPhiGrid{5, 10};
  auto make = [&](const std::string& est, int samples, int points) {
    WaveSettings ws;
    ws.estimator = waveEstimatorKind(est);
    ws.samplesPerBin = samples;
    ws.pointsPerDirection = points;
    return std::make_unique<WaveScenario>(g, material("Al"), layout, std::vector<double>{0.5}, 0.0, ws);
  };
  auto ref = make("area", 1 << 16, 64);
  WaveTileResult R = ref->run(30.0, 0.0, true, 1000);
  const DirectionGrid& grid = ref->grid;
  int spec = grid.binOf(sphericalDirection(radians(30.0), kPi));
  const int seeds = 20;
  auto small = make("area", 64, 16);
  auto paper = make("paper", 64, 16);
  std::vector<double> mean(grid.binCount(), 0.0), m2(grid.binCount(), 0.0), pmean(grid.binCount(), 0.0),
      pbias(grid.binCount(), 0.0);
  for (int s = 0; s < seeds; ++s) {
    WaveTileResult a = small->run(30.0, 0.0, true, s);
    WaveTileResult p = paper->run(30.0, 0.0, true, s);
    for (int b = 0; b < grid.binCount(); ++b) {
      mean[b] += a.fws[b] / seeds;
      m2[b] += a.fws[b] * a.fws[b] / seeds;
      pmean[b] += p.fws[b] / seeds;
      pbias[b] += p.fwsErr[b] / seeds;
    }
  }
  int tested = 0, beyond3 = 0;
  double z2 = 0, paperExcess = 0, paperBias = 0, refSum = 0;
  for (int b = 0; b < grid.binsPerHemisphere(); ++b) {
    if (b == spec) continue;  // diffuse bins only
    double var = std::max(0.0, m2[b] - mean[b] * mean[b]) * seeds / (seeds - 1);
    double se = std::sqrt(var / seeds + R.fwsErr[b] * R.fwsErr[b]);
    double z = (mean[b] - R.fws[b]) / se;
    z2 += z * z;
    if (std::abs(z) > 3) ++beyond3;
    ++tested;
    double op = grid.projectedSolidAngle(b);
    paperExcess += (pmean[b] - R.fws[b]) * op;
    paperBias += pbias[b] * op;
    refSum += R.fws[b] * op;
  }
  EXPECT_GE(tested, 40);
  EXPECT_LE(beyond3, 1) << "bins beyond 3 standard errors";
  EXPECT_LT(z2 / tested, 2.0) << "mean z² of the bins";
  RecordProperty("area_mean_z2", std::to_string(z2 / tested));
  // The biased form shows a diffuse floor: its excess over the reference is positive and of the
  // size of its own Var/P estimate.
  EXPECT_GT(paperExcess, 0.5 * paperBias)
      << "excess " << paperExcess << " bias estimate " << paperBias << " ref " << refSum;
  RecordProperty("paper_excess", std::to_string(paperExcess));
  RecordProperty("paper_var_over_P", std::to_string(paperBias));
}

// Convergence on `hemispheres` at θi = 55°: the variance of the area estimator falls as
// budget^(−1 ± 0.15); the paper estimator's measured rate is recorded beside it.
TEST(WaveConvergence, AreaVarianceFallsAsOneOverBudget) {
  Microgeometry g =
      makeDomeLattice({.size_um = {2, 2}, .spacing_um = {2, 2}, .radii_um = {0.8, 0.8, 0.8}, .resolution_um = 0.1});
  DirectionGrid::Layout layout = ThetaPhiGrid{4, 8};
  auto variance = [&](const std::string& est, int samples) {
    WaveSettings ws;
    ws.estimator = waveEstimatorKind(est);
    ws.samplesPerBin = samples;
    ws.pointsPerDirection = 16;
    WaveScenario sc(g, material("Al"), layout, {0.5}, 0.0, ws);
    const int seeds = 40;
    // Variance of the reflected energy Σ f Ω⊥ over seeds.
    double m1 = 0, m2 = 0;
    for (int s = 0; s < seeds; ++s) {
      WaveTileResult r = sc.run(55.0, 0.0, true, s);
      double e = sc.integral(r.fws, r.fwsErr, 0, true).first;
      m1 += e / seeds;
      m2 += e * e / seeds;
    }
    return (m2 - m1 * m1) * seeds / (seeds - 1);
  };
  std::vector<int> budgets{32, 128, 512, 2048};
  auto slope = [&](const std::string& est) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (int n : budgets) {
      double x = std::log(double(n)), y = std::log(variance(est, n));
      sx += x;
      sy += y;
      sxx += x * x;
      sxy += x * y;
    }
    double k = double(budgets.size());
    return (k * sxy - sx * sy) / (k * sxx - sx * sx);
  };
  double area = slope("area");
  double paper = slope("paper");
  RecordProperty("area_rate", std::to_string(area));
  RecordProperty("paper_rate", std::to_string(paper));
  std::printf("variance ~ budget^%.3f (area), budget^%.3f (paper)\n", area, paper);
  EXPECT_NEAR(area, -1.0, 0.15);
}

// Energy closure on `hemispheres` (radius 2 µm, spacing 5 µm) with perfect-mirror facets at
// λ = 0.25 µm, θi from 0° to 80°: a mirror reflects everything (GM = 1 exactly), and the paper's
// Eq. 20 means WM + lost to close the balance too. The gap 1 − (WM + lost) is the part of the
// scalar model that neither term holds: the lost diagnostic counts the Kirchhoff field of
// front-facing but masked points; at larger θi more of the light is shadowed and masked near the
// horizon, where the far-field lobes are cut, and diffraction at the shadow boundaries belongs to
// neither: it grows with λ against the features (at 0.5 µm it is 0.05 at 0°, 0.11 at 30°). Measured
// at 0.25 µm: 0.022, 0.019, 0.024 at 0°, 10°, 20°, then 0.05–0.08 to 80°. Asserted within 5 % to
// 20°, and within 0.25 beyond.
TEST(WaveClosure, GmMatchesWmPlusLost) {
  Microgeometry g =
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 16});
  DirectionGrid::Layout layout = ThetaPhiGrid{9, 18};
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Exact;
  ws.computeMasked = true;
  WaveScenario wave(g, material("mirror"), layout, {0.25}, 50.0, ws);
  PathTracerSettings ps;
  ps.paths = 50000;
  ps.tallyGeoMasked = true;
  Scenario geo(g, material("mirror"), layout, {0.25}, ps);
  for (double theta = 0; theta <= 80; theta += 10) {
    TileResult t = geo.run(theta, 0.0, true);
    WaveTileResult w = wave.run(theta, 0.0, true);
    addWaveComponents(t, w, true, true);
    auto integ = [&](Component c) {  // over the whole sphere
      return wave.integral(t.value[int(c)], t.stdError[int(c)], 0, true).first +
             wave.integral(t.value[int(c)], t.stdError[int(c)], 0, false).first;
    };
    double gm = integ(Component::Coherent) + integ(Component::Multiple);
    double wm = integ(Component::Coherent) + integ(Component::Incoherent) + integ(Component::Multiple);
    double lost = integ(Component::Lost);
    EXPECT_NEAR(gm, 1.0, 1e-9) << "a mirror reflects everything";
    RecordProperty("theta" + std::to_string(int(theta)) + "_WM_plus_lost", std::to_string(wm + lost));
    std::printf("theta %.0f: GM %.4f, WM %.4f + lost %.4f = %.4f, gap %+.4f\n", theta, gm, wm, lost, wm + lost,
                gm - wm - lost);
    EXPECT_NEAR(wm + lost, gm, theta <= 20.0 ? 0.05 : 0.25) << "theta " << theta << ": WM " << wm << " lost " << lost;
  }
}

// No NaN or Inf at grazing incidence, with total internal reflection and grazing facets.
TEST(WaveHardCases, FiniteEverywhere) {
  auto check = [](const WaveTileResult& r) {
    for (const auto* v : {&r.fws, &r.fwsErr, &r.pmsk, &r.pmskErr})
      for (double x : *v) ASSERT_TRUE(std::isfinite(x));
  };
  for (const char* est : {"area", "paper"}) {
    WaveSettings ws;
    ws.estimator = waveEstimatorKind(est);
    ws.samplesPerBin = 64;
    ws.pointsPerDirection = 16;
    ws.computeMasked = true;
    WaveScenario hemi(
        makeDomeLattice({.size_um = {2, 2}, .spacing_um = {2, 2}, .radii_um = {0.8, 0.8, 0.8}, .resolution_um = 0.1}),
        material("Au"), DiskGrid{9, 9}, {0.45, 0.65}, 0.0, ws);
    for (double theta : {85.0, 89.5}) {
      check(hemi.run(theta, 10.0, true));
      check(hemi.run(theta, 10.0, false));
    }
    Material glass;
    glass.model = Dielectric{ConstantIndex{1.5, 0}};
    WaveScenario ridged(makeRidged(2, 1, 1.0, 60.0, 0), glass, ThetaPhiGrid{6, 12}, {0.5}, 0.0, ws);
    for (double theta : {89.5, 180 - 41.8, 180 - 60.0, 180 - 89.5}) check(ridged.run(theta, 30.0, true));
  }
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Orders;
  ws.samplesPerBin = 64;
  ws.computeMasked = true;
  for (DirectionGrid::Layout layout :
       {DirectionGrid::Layout(ThetaPhiGrid{6, 12}), DirectionGrid::Layout(DiskGrid{9, 9})}) {
    WaveScenario orders(
        makeDomeLattice({.size_um = {2, 2}, .spacing_um = {2, 2}, .radii_um = {0.8, 0.8, 0.8}, .resolution_um = 0.1}),
        material("Au"), layout, {0.45}, 50.0, ws);
    for (double theta : {0.0, 89.5}) {
      check(orders.run(theta, 10.0, true));
      check(orders.run(theta, 10.0, false));
    }
  }
}
