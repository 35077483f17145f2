// The `fft` wave estimator (fft_estimator.h, heightfield_spectrum.h): Ĥ_G of every order of a
// heightfield from FFTs. References: Fresnel for flat interfaces, the `exact` facet sums in the
// orders regime (1 % in Σ|Δf|Ω⊥ / Σ f Ω⊥), energy conservation and the
// `area` Monte Carlo estimator in the speckle regime (windows narrower than the patch).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "geometry/generators.h"
#include "optics/fresnel.h"
#include "scattering/fft_estimator.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

// Σ|f_a − f_b| Ω⊥ / Σ f_b Ω⊥ over both hemispheres, wavelength 0.
double relativeL1(const DirectionGrid& grid, const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0, s = 0;
  for (int bin = 0; bin < grid.binCount(); ++bin) {
    d += std::abs(a[size_t(bin)] - b[size_t(bin)]) * grid.projectedSolidAngle(bin);
    s += b[size_t(bin)] * grid.projectedSolidAngle(bin);
  }
  return d / s;
}

}  // namespace

TEST(HeightGrid, RecognisesHeightfieldMeshesOnly) {
  std::vector<double> h(12);
  for (size_t i = 0; i < h.size(); ++i) h[i] = 0.1 * std::sin(double(i));
  const Microgeometry g = heightfieldMesh(h, 4, 3, 2.0, 1.5);
  const auto hg = heightGridOf(g);
  ASSERT_TRUE(hg);
  EXPECT_EQ(hg->nx, 4);
  EXPECT_EQ(hg->ny, 3);
  EXPECT_EQ(hg->h, h);
  EXPECT_TRUE(heightGridOf(makeFlat(4, 4, 1.0)));
  EXPECT_TRUE(heightGridOf(makeGaussian(4, 4, 0.1, 1.0, 16, 16, 3)));
  EXPECT_FALSE(heightGridOf(
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.5})));
  Microgeometry swapped = g;
  std::swap(swapped.triangles[0], swapped.triangles[2]);
  EXPECT_FALSE(heightGridOf(swapped));
  Microgeometry seam = g;
  seam.vertices[4].z += 0.01;  // the seam column no longer repeats the first one
  EXPECT_FALSE(heightGridOf(seam));
}

// Flat interfaces (orders regime; the 1 µm texels are split 16 x 16 for the one-point rule).
TEST(WaveFft, FlatInterfacesGiveFresnel) {
  expectFlatInterfacesGiveFresnel("fft");
}

// Orders regime: `fft` against `exact` on rough heightfields, within 1 % of the scattered power
// (Σ|Δf|Ω⊥ / Σ f Ω⊥), at normal incidence and at 60° (where the masking correction is at work),
// for gold and for glass (reflection and transmission).
TEST(WaveFft, MatchesExactOnHeightfields) {
  struct Case {
    Microgeometry g;
    std::string material;
    double theta;
  };
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  const Microgeometry gauss = makeGaussian(5, 5, 0.12, 1.0, 40, 40, 11);
  const Microgeometry noise = makeNoise({.size_um = {5, 5},
                                         .rms_um = 0.15,
                                         .feature_radius_um = 0.8,
                                         .density_per_um2 = 2.0,
                                         .texels = {48, 48},
                                         .seed = 7});
  for (const auto& [g, mat, theta] :
       {Case{gauss, "Au", 0.0}, Case{gauss, "Au", 60.0}, Case{noise, "Au", 30.0}, Case{gauss, "glass", 35.0}}) {
    WaveSettings fs, es;
    fs.estimator = WaveEstimatorKind::Fft;
    es.estimator = WaveEstimatorKind::Exact;
    const Material m = mat == "glass" ? glass : material(mat);
    WaveScenario f(g, m, ThetaPhiGrid{12, 24}, {0.6}, 60.0, fs), e(g, m, ThetaPhiGrid{12, 24}, {0.6}, 60.0, es);
    const WaveTileResult rf = f.run(theta, 20.0, true), re = e.run(theta, 20.0, true);
    for (double v : rf.fws) ASSERT_TRUE(std::isfinite(v));
    const double l1 = relativeL1(f.grid, rf.fws, re.fws);
    EXPECT_LT(l1, 0.01) << g.description << " " << mat << " at " << theta << "°";
    RecordProperty("l1_" + mat + "_" + std::to_string(int(theta)), std::to_string(l1));
    RecordProperty("seconds_" + mat + "_" + std::to_string(int(theta)),
                   std::to_string(rf.seconds) + " fft, " + std::to_string(re.seconds) + " exact");
  }
}

// Speckle regime (δc = 12 µm on an 8 µm patch: 2πσ/L = 1.6, the lobes overlap): a flat gold
// mirror still reflects exactly R(θ) (the lobe is spread over several bins), on a disk grid (tensor
// nodes per pixel) and on a theta-phi grid (nodes per bin in its own parametrisation).
TEST(WaveFft, SpeckleRegimeFlatMirrorGivesFresnel) {
  WaveSettings ws;
  ws.estimator = WaveEstimatorKind::Fft;
  for (const DirectionGrid::Layout& layout :
       {DirectionGrid::Layout{DiskGrid{64, 64}}, DirectionGrid::Layout{ThetaPhiGrid{30, 60}}})
    for (double theta : {0.0, 40.0}) {
      WaveScenario sc(makeFlat(8, 8, 1.0), material("Au"), layout, {0.55}, 12.0, ws);
      WaveTileResult r = sc.run(theta, 0.0, true);
      const double ref = fresnelReflectance(std::cos(radians(theta)), 1.0, sc.mat.ior(0.55));
      auto [R, se] = sc.integral(r.fws, r.fwsErr, 0, true);
      EXPECT_NEAR(R / ref, 1.0, 2e-3) << sc.grid.kind() << " " << theta << " (reported error " << se << ")";
      RecordProperty("R_over_fresnel_" + sc.grid.kind() + "_" + std::to_string(int(theta)), std::to_string(R / ref));
    }
}

// Speckle regime on a rough heightfield: `fft` against the `area` Monte Carlo estimator (which
// makes no assumption on the window) within 4 of the latter's standard errors per resolved bin,
// and the same total, at 20°, on both grid layouts.
TEST(WaveFft, SpeckleRegimeMatchesAreaMonteCarlo) {
  const Microgeometry g = makeGaussian(6, 6, 0.1, 1.0, 48, 48, 5);
  WaveSettings fs, as;
  fs.estimator = WaveEstimatorKind::Fft;
  as.estimator = WaveEstimatorKind::Area;
  as.samplesPerBin = 1 << 14;
  for (const DirectionGrid::Layout& layout :
       {DirectionGrid::Layout{DiskGrid{20, 20}}, DirectionGrid::Layout{ThetaPhiGrid{10, 20}}}) {
    WaveScenario f(g, material("Au"), layout, {0.6}, 9.0, fs), a(g, material("Au"), layout, {0.6}, 9.0, as);
    const WaveTileResult rf = f.run(20.0, 0.0, true), ra = a.run(20.0, 0.0, true);
    int tested = 0;
    double z2 = 0;
    for (int bin = 0; bin < f.grid.binsPerHemisphere(); ++bin) {
      if (ra.fwsErr[size_t(bin)] <= 0 || ra.fws[size_t(bin)] < 3 * ra.fwsErr[size_t(bin)]) continue;
      const double z = (rf.fws[size_t(bin)] - ra.fws[size_t(bin)]) / ra.fwsErr[size_t(bin)];
      EXPECT_LT(std::abs(z), 4.0) << f.grid.kind() << " bin " << bin << ": fft " << rf.fws[size_t(bin)] << " area "
                                  << ra.fws[size_t(bin)];
      z2 += z * z;
      ++tested;
    }
    EXPECT_GE(tested, 20) << f.grid.kind();
    auto [ef, sf] = f.integral(rf.fws, rf.fwsErr, 0, true);
    auto [ea, sa] = a.integral(ra.fws, ra.fwsErr, 0, true);
    EXPECT_LT(std::abs(ef - ea), 4 * sa) << f.grid.kind() << ": " << ef << " vs " << ea << " +- " << sa;
    const std::string k = f.grid.kind();
    RecordProperty("bins_" + k, tested);
    RecordProperty("mean_z2_" + k, std::to_string(z2 / std::max(1, tested)));
    RecordProperty("energy_" + k, std::to_string(ef) + " fft (" + std::to_string(rf.seconds) + " s), " +
                                      std::to_string(ea) + " area (" + std::to_string(ra.seconds) + " s)");
  }
}

// Light from inside glass in the speckle regime: the reflected bins are the FFT's, the transmitted
// ones the `area` estimator's (the reverse-path integrand of transmission from the denser medium is
// no field the FFT can share, fft_estimator.cpp). The transmitted bins equal a standalone `area`
// run with the same settings and tile, and the reflected ones agree with it within 4 of its
// standard errors.
TEST(WaveFft, SpeckleRegimeFromInsideGlassTransmitsByArea) {
  const Microgeometry g = makeGaussian(6, 6, 0.1, 1.0, 48, 48, 5);
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  WaveSettings fs, as;
  fs.estimator = WaveEstimatorKind::Fft;
  as.estimator = WaveEstimatorKind::Area;
  fs.samplesPerBin = as.samplesPerBin = 1 << 15;
  WaveScenario f(g, glass, ThetaPhiGrid{10, 20}, {0.6}, 9.0, fs), a(g, glass, ThetaPhiGrid{10, 20}, {0.6}, 9.0, as);
  const WaveTileResult rf = f.run(160.0, 0.0, true, 3), ra = a.run(160.0, 0.0, true, 3);
  int transmitted = 0, reflected = 0;
  for (int bin = 0; bin < f.grid.binCount(); ++bin) {
    ASSERT_TRUE(std::isfinite(rf.fws[size_t(bin)]));
    if (f.grid.isUpper(bin)) {  // transmitted into the air
      EXPECT_EQ(rf.fws[size_t(bin)], ra.fws[size_t(bin)]) << bin;
      EXPECT_EQ(rf.fwsErr[size_t(bin)], ra.fwsErr[size_t(bin)]) << bin;
      transmitted += rf.fws[size_t(bin)] > 0;
    } else if (ra.fwsErr[size_t(bin)] > 0 && ra.fws[size_t(bin)] > 3 * ra.fwsErr[size_t(bin)]) {
      EXPECT_LT(std::abs(rf.fws[size_t(bin)] - ra.fws[size_t(bin)]),
                4 * ra.fwsErr[size_t(bin)] + 1e-3 * ra.fws[size_t(bin)])
          << "bin " << bin << ": fft " << rf.fws[size_t(bin)] << " area " << ra.fws[size_t(bin)];
      ++reflected;
    }
  }
  EXPECT_GE(transmitted, 20);
  EXPECT_GE(reflected, 5);
}
