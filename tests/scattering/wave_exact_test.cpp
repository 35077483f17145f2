// The `exact` wave estimator (orders_estimator.h): order amplitudes summed over facets with the
// phase integrated in closed form. References: Fresnel for flat interfaces, J_m²(2 k0 h) for a thin
// sinusoidal grating, the Monte Carlo `orders` and `area` estimators within their error bars on
// shadowing surfaces (hemispheres, overhang) and a rough random heightfield (noise).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "geometry/generators.h"
#include "optics/fresnel.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

// Flat interfaces under a collimated beam: Σ f Ω⊥ = Fresnel reflectance within 0.1 % (gold at
// 0°, 30°, 60°, 70°; glass reflection and transmission from outside at 40°), with no sampling error.
// (At 80° the order's Gaussian lobe, sd 0.0074 in direction cosines for δc = 50 µm, reaches past
// the horizon and 1/128 of it is dropped as evanescent: a limit of the lobe model, not of the sum.)
TEST(WaveExact, FlatInterfacesGiveFresnel) {
  expectFlatInterfacesGiveFresnel("exact");
}

// A shallow sinusoidal perfect-conductor grating (period 5 µm, amplitude 0.05 µm, λ = 0.5 µm,
// normal incidence): order efficiencies J_m²(2 k0 h) within 0.005 for |m| <= 3.
TEST(WaveExact, SineGratingOrdersMatchBessel) {
  const double period = 5.0, h = 0.05, lambda = 0.5;
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Exact;
  WaveScenario sc(makeSineGrating(period, 1.0, period, h, 64, 0), material("mirror"), ThetaPhiGrid{90, 72}, {lambda},
                  50.0, ws);
  WaveTileResult r = sc.run(0.0, 0.0, true);
  const double k0 = 2 * kPi / lambda;
  for (int m = -3; m <= 3; ++m) {
    const double sx = -m * lambda / period;
    const double eta = energyAround(sc.grid, r.fws, 0, Vec3{sx, 0, std::sqrt(1 - sx * sx)}, 0.04);
    const double expected = std::pow(std::cyl_bessel_j(double(std::abs(m)), 2 * k0 * h), 2);
    EXPECT_NEAR(eta, expected, 0.005) << "order " << m;
    RecordProperty("eta_" + std::to_string(m), std::to_string(eta));
  }
}

// Shadowing and masking: mirror hemispheres (r = 2 µm on a 5 µm lattice) at 50° incidence, where
// the domes shadow and mask each other. The exact facet sums (visibility split down to 4^3 pieces
// per facet) against the Monte Carlo orders estimator with 2^17 points: per bin within 4 standard
// errors of the latter, and the same total.
namespace {

// `exact` against a Monte Carlo estimator with many samples on the same patch and collimated beam:
// every bin the reference resolves (f > 3 SE) within 4 SE, and the hemisphere's energy within 4 SE.
void expectExactMatchesMonteCarlo(const Microgeometry& g, const std::string& reference, int samples, double theta_deg,
                                  double phi_deg, double coherenceLength_um = 60.0, double maxTheta_deg = 90.0) {
  WaveSettings ex, mc;
  ex.estimator = WaveEstimatorKind::Exact;
  mc.estimator = waveEstimatorKind(reference);
  mc.samplesPerBin = samples;
  WaveScenario a(g, material("mirror"), ThetaPhiGrid{12, 24}, {0.6}, coherenceLength_um, ex);
  WaveScenario b(g, material("mirror"), ThetaPhiGrid{12, 24}, {0.6}, coherenceLength_um, mc);
  WaveTileResult ra = a.run(theta_deg, phi_deg, true), rb = b.run(theta_deg, phi_deg, true);
  int tested = 0;
  double z2 = 0;
  for (int bin = 0; bin < a.grid.binsPerHemisphere(); ++bin) {
    ASSERT_TRUE(std::isfinite(ra.fws[size_t(bin)])) << bin;
    if (rb.fwsErr[size_t(bin)] <= 0 || rb.fws[size_t(bin)] < 3 * rb.fwsErr[size_t(bin)]) continue;
    if (a.grid.centre(bin).z < std::cos(radians(maxTheta_deg))) continue;
    const double z = (ra.fws[size_t(bin)] - rb.fws[size_t(bin)]) / rb.fwsErr[size_t(bin)];
    EXPECT_LT(std::abs(z), 4.0) << "bin " << bin << ": exact " << ra.fws[size_t(bin)] << " " << reference << " "
                                << rb.fws[size_t(bin)];
    z2 += z * z;
    ++tested;
  }
  EXPECT_GE(tested, 10);
  auto [ea, sa] = a.integral(ra.fws, ra.fwsErr, 0, true);
  auto [eb, sb] = b.integral(rb.fws, rb.fwsErr, 0, true);
  EXPECT_LT(std::abs(ea - eb), 4 * sb) << ea << " vs " << eb << " +- " << sb;
  ::testing::Test::RecordProperty("bins", tested);
  ::testing::Test::RecordProperty("mean_z2", std::to_string(z2 / std::max(1, tested)));
  ::testing::Test::RecordProperty("energy_exact", std::to_string(ea));
  ::testing::Test::RecordProperty("energy_" + reference, std::to_string(eb));
}

}  // namespace

// Mirror hemispheres at 50°: mutual shadowing and masking split facets (visibility at the centroid
// and inset points disagree), compared with the `orders` Monte Carlo estimator at 2^17 samples and
// with the `area` estimator (no order model at all) at 2^15, the latter for exits up to 65°. Beyond
// 65°, near the specular azimuth, `area` and `exact` disagree beyond their errors while `orders`
// agrees with `exact` (bin at θo 86°: area 0.18 ± 0.01 over 8 seeds, exact 0.089, orders 0.0891 ±
// 0.0005; at 79°: area 0.28 ± 0.07, exact 0.53; the grazing region's energy 0.078 against 0.069):
// a difference of the two models at grazing exit that is not resolved yet.
TEST(WaveExact, ShadowingHemispheresMatchMonteCarlo) {
  const Microgeometry g =
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25});
  expectExactMatchesMonteCarlo(g, "orders", 1 << 17, 50.0, 20.0);
  expectExactMatchesMonteCarlo(g, "area", 1 << 15, 50.0, 20.0, 60.0, 65.0);
}

// OVERHANG (mushrooms whose caps overhang their stems: not a heightfield) at 40°: the caps' flat
// undersides face away and the stems sit in the caps' shadow; against the `orders` estimator at
// 2^17 samples (251 bins, mean z² 1.42, energy 0.7171 vs 0.7183) and the `area` estimator at 2^15
// (the 18 bins it resolves; energy 0.757: its heavy tail near the specular order, see below).
TEST(WaveExact, OverhangMatchesMonteCarlo) {
  const Microgeometry g = makeOverhang({.size_um = {5, 5},
                                        .spacing_um = 5,
                                        .stem_radius_um = 0.6,
                                        .stem_height_um = 1.0,
                                        .cap_radius_um = 1.8,
                                        .cap_height_um = 0.6,
                                        .resolution_um = 0.25});
  expectExactMatchesMonteCarlo(g, "orders", 1 << 17, 40.0, 10.0);
  expectExactMatchesMonteCarlo(g, "area", 1 << 15, 40.0, 10.0);
}

// A sparse-convolution noise heightfield (rms 0.15 µm, feature radius 0.8 µm) at 30°: a rough,
// random patch whose light spreads over many bins; against the `orders` estimator. (The `area`
// estimator is not a fair reference here: its estimate of the bin holding the specular order's
// narrow lobe is heavy-tailed — 1.34 ± 0.32 against 2.71 at 2^15 samples, z = 4.2, while the other
// 58 bins agree with mean z² 1.25.)
TEST(WaveExact, NoiseHeightfieldMatchesMonteCarlo) {
  expectExactMatchesMonteCarlo(makeNoise({.size_um = {5, 5},
                                          .rms_um = 0.15,
                                          .feature_radius_um = 0.8,
                                          .density_per_um2 = 2.0,
                                          .texels = {48, 48},
                                          .seed = 7}),
                               "orders", 1 << 17, 30.0, 0.0);
}

// A patch of nx x ny copies of a cell (geometry/lattice_cell.h) has order amplitudes only on the
// cell's lattice, nx ny times the cell's: `exact` on 2 x 2 hemisphere cells gives the single cell's
// table (same window) from one cell's facets, to 1e-7 (measured 3e-9: the window's normalisation W2
// sums the copies within ±4σ, which fall slightly differently for a 5 and a 10 µm patch).
TEST(WaveExact, LatticeOfCellsGivesTheCellsTable) {
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Exact;
  const WaveScenario one(
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}),
      material("Al"), ThetaPhiGrid{12, 24}, {0.6}, 60.0, ws);
  const WaveScenario four(
      makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}),
      material("Al"), ThetaPhiGrid{12, 24}, {0.6}, 60.0, ws);
  const WaveTileResult a = one.run(50.0, 20.0, true), b = four.run(50.0, 20.0, true);
  const double ea = one.integral(a.fws, a.fwsErr, 0, true).first, eb = four.integral(b.fws, b.fwsErr, 0, true).first;
  EXPECT_NEAR(eb, ea, 1e-7 * ea);
  for (size_t i = 0; i < a.fws.size(); ++i) EXPECT_NEAR(b.fws[i], a.fws[i], 1e-7 * (1 + std::abs(a.fws[i]))) << i;
  EXPECT_EQ(b.samples, a.samples);  // facets x orders: one cell's of each
  EXPECT_NE(four.estimator->notes().find("one cell"), std::string::npos) << four.estimator->notes();
}

// The window narrower than the patch but wide against its cell (2 x 2 hemisphere cells, 10 µm,
// δc = 30 µm: 2πσ/L = 3.1 for the patch, 6.3 for the cell): the speckle of the patch's orders is
// absent because only the cell's orders carry power, so `exact`'s separate lobes hold; against
// `area` (the windowed integral by Monte Carlo, no order model) at 2^18 within 4 SE (2^17 resolves
// 8 bins on this patch, 2^15 only 5).
TEST(WaveExact, CellLobesUnderAWindowNarrowerThanThePatchMatchArea) {
  expectExactMatchesMonteCarlo(
      makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}),
      "area", 1 << 18, 40.0, 20.0, 30.0);
}

// exact over an incidence bin (the job's tabulated BSDF): the order powers from the 2 × 2 (and 1 × 1)
// Gauss–Legendre nodes, interpolated to 32 × 32 sub-directions and binned there, against the mean of
// 24 × 24 collimated exact tables at stratified cosine-weighted directions of the same bin (each
// binned by its own lobe pattern: an independent route). An Al-like mirror grating, Λ = 2 µm = 4 λ,
// h = 30 nm, on 8 × 16 bins at three incidence bins: the L1 distance per slice is within the
// reported error (on the safe side) and below 0.04. Binning the nodes' own exit directions instead
// (the plain 2 × 2 rule, before) was 0.13–0.18 from its own 8 × 8 rule on this grating: the exit
// direction's bin jumps across the incidence bin.
TEST(WaveExact, IncidenceBinAverageMatchesDenseCollimatedMean) {
  const double lambda = 0.5;
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Exact;
  WaveScenario sc(makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), material("mirror"), ThetaPhiGrid{8, 16}, {lambda}, 50.0,
                  ws);
  const int nB = sc.grid.binCount();
  for (auto [theta, phi] : {std::pair{5.0, 10.0}, std::pair{39.4, 10.0}, std::pair{65.0, 100.0}}) {
    const int bin = sc.grid.binOf(sphericalDirection(radians(theta), radians(phi)));
    const WaveTileResult avg = sc.estimator->run(0, bin, std::nullopt);
    constexpr int M = 24;
    std::vector<double> ref(size_t(nB), 0.0);
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < M; ++j) {
        const Vec3 wi = sc.grid.sampleCosine(bin, (i + 0.5) / M, (j + 0.5) / M).w;
        const WaveTileResult one = sc.estimator->run(0, bin, wi);
        for (int b = 0; b < nB; ++b) ref[size_t(b)] += one.fws[size_t(b)] / (M * M);
      }
    double l1 = 0, reported = 0, energy = 0;
    for (int b = 0; b < nB; ++b) {
      const double op = sc.grid.projectedSolidAngle(b);
      ASSERT_TRUE(std::isfinite(avg.fws[size_t(b)]) && std::isfinite(avg.fwsErr[size_t(b)]));
      l1 += std::abs(avg.fws[size_t(b)] - ref[size_t(b)]) * op;
      reported += avg.fwsErr[size_t(b)] * op;
      energy += ref[size_t(b)] * op;
    }
    EXPECT_LT(l1, reported) << "theta " << theta;
    EXPECT_LT(l1, 0.04) << "theta " << theta;
    EXPECT_GT(energy, 0.9) << "theta " << theta;
    std::printf("theta %.1f: L1 to the collimated mean %.4f, reported %.4f, energy %.4f\n", theta, l1, reported,
                energy);
  }
}

// [sampling] wave_subdirections: the binning of an incidence bin's orders through M × M
// sub-directions, each spreading the order's lobe over the bins by its integrated shares, converges
// fast on a grid whose bins are as fine as the incidence bin's image (the same grating on 30 × 120
// bins, at 5°, 39.4° and 65°): against M = 128, M = 16 within 1 % (L1 per slice) and M = 32 at
// least a third closer and within 0.2 % (sampling the lobe at one point per sub-direction instead
// left 6–8 % at M = 32 on the paper's HEMISPHERES, orders_estimator.cpp); the error each M
// reports, summed over the bins, never below its distance from M = 128; the energy the same
// whatever M (the binning moves power between bins only); M = 512 within 0.1 % of M = 128.
TEST(WaveExact, IncidenceBinAverageConvergesWithSubdirections) {
  const double lambda = 0.5;
  auto tableAt = [&](int M, double theta, double phi) {
    WaveSettings ws;
    ws.estimator = WaveEstimatorKind::Exact;
    ws.subdirections = M;
    WaveScenario sc(makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), material("mirror"), ThetaPhiGrid{30, 120}, {lambda},
                    50.0, ws);
    const int bin = sc.grid.binOf(sphericalDirection(radians(theta), radians(phi)));
    return std::pair{sc.estimator->run(0, bin, std::nullopt), DirectionGrid(ThetaPhiGrid{30, 120})};
  };
  for (auto [theta, phi] : {std::pair{5.0, 10.0}, std::pair{39.4, 10.0}, std::pair{65.0, 100.0}}) {
    constexpr int kReference = 128;
    const auto [ref, grid] = tableAt(kReference, theta, phi);
    double previous = 0, refEnergy = 0;
    for (int b = 0; b < grid.binCount(); ++b) refEnergy += ref.fws[size_t(b)] * grid.projectedSolidAngle(b);
    for (int M = kMinSubdirections; M <= kReference / 4; M *= 2) {  // 4x coarser than the reference at least
      const WaveTileResult t = tableAt(M, theta, phi).first;
      double l1 = 0, reported = 0, energy = 0;
      for (int b = 0; b < grid.binCount(); ++b) {
        const double op = grid.projectedSolidAngle(b);
        l1 += std::abs(t.fws[size_t(b)] - ref.fws[size_t(b)]) * op;
        reported += t.fwsErr[size_t(b)] * op;
        energy += t.fws[size_t(b)] * op;
      }
      l1 /= refEnergy;
      reported /= refEnergy;
      std::printf("theta %.1f, M = %3d: L1 to M = %d %.4f, reported %.4f, energy %.6f (M = %d: %.6f)\n", theta, M,
                  kReference, l1, reported, energy, kReference, refEnergy);
      EXPECT_LT(l1, reported) << "theta " << theta << ", M " << M;
      EXPECT_LT(l1, M == kMinSubdirections ? 0.01 : 0.002) << "theta " << theta << ", M " << M;
      if (M > kMinSubdirections) {
        EXPECT_LT(l1, 0.67 * previous) << "theta " << theta << ", M " << M;
      }
      EXPECT_NEAR(energy, refEnergy, 1e-3 * refEnergy) << "theta " << theta << ", M " << M;
      previous = l1;
    }
    if (theta == 39.4) {  // the finest setting, whose lobe patterns run to 512 points, agrees too
      const WaveTileResult finest = tableAt(kMaxSubdirections, theta, phi).first;
      double l1 = 0;
      for (int b = 0; b < grid.binCount(); ++b)
        l1 += std::abs(finest.fws[size_t(b)] - ref.fws[size_t(b)]) * grid.projectedSolidAngle(b);
      EXPECT_LT(l1 / refEnergy, 1e-3) << "M " << kMaxSubdirections;
    }
  }
}

// [sampling] wave_incidence_directions_pole_horizon: the bins that reach normal incidence or the
// horizon take their own rule, the others the job's. With 4 directions (n = 2) elsewhere and 16
// (n = 4) there, a pole and a horizon bin give the table of 16 directions everywhere, bit for bit,
// and a middle bin that of 4 everywhere; for `exact` and for `fft` (a sine grating, a heightfield).
TEST(WaveExact, PoleAndHorizonBinsTakeTheirOwnRule) {
  for (WaveEstimatorKind kind : {WaveEstimatorKind::Exact, WaveEstimatorKind::Fft}) {
    auto tableAt = [&](int directions, int poleHorizon, double theta) {
      WaveSettings ws;
      ws.estimator = kind;
      ws.incidenceDirections = directions;
      ws.poleHorizonIncidenceDirections = poleHorizon;
      WaveScenario sc(makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), material("mirror"), ThetaPhiGrid{8, 16}, {0.5}, 50.0,
                      ws);
      const int bin = sc.grid.binOf(sphericalDirection(radians(theta), radians(10.0)));
      return std::pair{sc.estimator->run(0, bin, std::nullopt), sc.grid.atPoleOrHorizon(bin)};
    };
    for (double theta : {5.0, 39.4, 85.0}) {
      const auto [mixed, edge] = tableAt(4, 16, theta);
      EXPECT_EQ(edge, theta != 39.4);
      const WaveTileResult same = tableAt(edge ? 16 : 4, 0, theta).first;
      const WaveTileResult other = tableAt(edge ? 4 : 16, 0, theta).first;
      EXPECT_EQ(mixed.fws, same.fws) << "theta " << theta;
      EXPECT_EQ(mixed.fwsErr, same.fwsErr) << "theta " << theta;
      EXPECT_NE(mixed.fws, other.fws) << "theta " << theta;
    }
  }
}
