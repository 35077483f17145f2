// Scalar diffraction on flat interfaces: the hemispherical integral of f_ws
// equals the Fresnel reflectance (and transmittance, from outside and from inside) within 1 %,
// `incoherent` integrates to ~0 and `lost` is ~0.
//  - With a coherence window (δc = 50 µm, σ = 8.3 µm) on a small periodic patch the field is the
//    plane wave's: the reference is Fresnel itself (orders estimator, which integrates the lobes).
//  - Without a window the integral covers one copy of the patch: a square aperture of side L
//    diffracts part of the power into evanescent directions. The reference is then Fresnel times
//    the aperture's propagating fraction, computed here by quadrature of the closed-form far field
//    I = g(ωo) L² sinc(q_x L/2) sinc(q_y L/2) over the hemisphere (area estimator).
#include <gtest/gtest.h>

#include <cmath>

#include "geometry/generators.h"
#include "scattering/kirchhoff.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

double sinc(double u) {
  return std::abs(u) < 1e-8 ? 1.0 - u * u / 6 : std::sin(u) / u;
}

// ∫ p dω over the reflection or transmission hemisphere for a flat square aperture of side L.
double apertureReference(double L, double lambda, double n1, Complex n2, Vec3 wi, bool transmission) {
  const bool fromAbove = wi.z > 0;
  const double nI = fromAbove ? n1 : n2.real(), nO = transmission ? (fromAbove ? n2.real() : n1) : nI;
  const Complex nOther = fromAbove ? n2 : Complex(n1, 0);
  const double k0 = 2 * kPi / lambda, cosI = std::abs(wi.z);
  Vec3 m{0, 0, fromAbove ? 1.0 : -1.0};
  FresnelAmplitudes F = fresnelAmplitudes(cosI, nI, nOther);
  const int nt = 1200, np = 1200;
  double sum = 0;
  for (int i = 0; i < nt; ++i) {
    double th = (i + 0.5) * 0.5 * kPi / nt;
    for (int j = 0; j < np; ++j) {
      double ph = (j + 0.5) * 2 * kPi / np;
      Vec3 wo = sphericalDirection(th, ph);
      if (transmission == fromAbove) wo.z = -wo.z;
      // Transmission from the denser medium: the reverse path's integrand, as the estimators
      // evaluate it (wave::integrandAt).
      const bool reverse = transmission && nI > nO;
      KirchhoffValue kv = reverse ? kirchhoffIntegrand({0, 0, 0}, -m, wo, wi, k0, nO, nI,
                                                       fresnelAmplitudes(std::abs(wo.z), nO, Complex(nI, 0)), true)
                                  : kirchhoffIntegrand({0, 0, 0}, m, wi, wo, k0, nI, nO, F, transmission);
      double a = L * L * sinc(kv.qx * L / 2) * sinc(kv.qy * L / 2);
      double p = 0.5 * (std::norm(kv.s) + std::norm(kv.p)) * a * a * kirchhoffPowerScale(L * L, cosI, nI, nO);
      sum += p * std::sin(th) * (0.5 * kPi / nt) * (2 * kPi / np);
    }
  }
  return sum;
}

}  // namespace

// Outside the anonymous namespace: the test classes TEST_P derives from the fixture have external
// linkage.
struct FlatCase {
  std::string material;  // "Al" or "BK7"
  double theta;          // > 90: from inside the glass
  bool window;
};

class WaveFlat : public ::testing::TestWithParam<FlatCase> {};

TEST_P(WaveFlat, HemisphericalIntegralMatchesFresnel) {
  const FlatCase c = GetParam();
  const double phi = 17.0;
  WaveSettings ws;
  ws.seed = 3;
  ws.computeMasked = true;
  double L, coherence;
  DirectionGrid::Layout layout;
  if (c.window) {
    ws.estimator = WaveEstimatorKind::Orders;
    ws.samplesPerBin = 8192;  // points per order
    L = 2.0;
    coherence = 50.0;
    layout = ThetaPhiGrid{30, 60};
  } else {
    ws.estimator = WaveEstimatorKind::Area;
    ws.samplesPerBin = 4096;
    ws.pointsPerDirection = 64;
    L = 1.0;
    coherence = 0.0;
    layout = ThetaPhiGrid{15, 30};
  }
  const std::vector<double> lambdas{0.45, 0.65};
  WaveScenario sc(makeFlat(L, L, 0), material(c.material), layout, lambdas, coherence, ws);
  WaveTileResult r = sc.run(c.theta, phi, /*exact=*/true);
  PathTracerSettings ps;
  ps.paths = 20000;
  ps.tallyGeoMasked = true;
  Scenario geo(makeFlat(L, L, 0), material(c.material), layout, lambdas, ps);
  TileResult t = geo.run(c.theta, phi, /*exact=*/true);
  addWaveComponents(t, r, true, true);

  const Vec3 wi = sphericalDirection(radians(c.theta), radians(phi));
  const bool fromAbove = wi.z > 0;
  for (int l = 0; l < 2; ++l) {
    const Complex n2 = sc.mat.ior(lambdas[l]);
    const double nI = fromAbove ? 1.0 : n2.real(), nT = fromAbove ? n2.real() : 1.0;
    const double R = fresnelReflectance(std::abs(wi.z), nI, fromAbove ? n2 : Complex(nT, 0));
    const double T = sc.mat.isConductor() ? 0.0 : 1.0 - R;
    auto [wr, er] = sc.integral(r.fws, r.fwsErr, l, fromAbove);
    auto [wt, et] = sc.integral(r.fws, r.fwsErr, l, !fromAbove);
    double refR = R, refT = T;
    if (!c.window) {
      refR = apertureReference(L, lambdas[l], 1.0, n2, wi, false);
      refT = sc.mat.isConductor() ? 0.0 : apertureReference(L, lambdas[l], 1.0, n2, wi, true);
      RecordProperty("aperture_fraction_" + std::to_string(l), std::to_string(refR / R));
    }
    // Within 1 % of the incident power, and statistically consistent with the estimator's own
    // standard error (4 σ, plus 0.1 % for the quadrature of the references).
    for (auto [got, ref, err] : {std::tuple{wr, refR, er}, std::tuple{wt, refT, et}}) {
      EXPECT_NEAR(got, ref, 0.01) << c.material << " theta " << c.theta;
      EXPECT_NEAR(got, ref, 4 * err + 1e-3 * ref) << c.material << " theta " << c.theta << " (± " << err << ")";
    }
    // incoherent = f_ws − coherent integrates to ~0 where the aperture loses nothing.
    if (c.window) {
      double inc = 0;
      for (bool up : {true, false})
        inc += sc.integral(t.value[int(Component::Incoherent)], t.stdError[int(Component::Incoherent)], l, up).first;
      EXPECT_NEAR(inc, 0.0, 0.01) << c.material << " theta " << c.theta;
    }
    // Nothing is masked on a flat interface.
    for (double v : r.pmsk) EXPECT_EQ(v, 0.0);
    for (double v : t.value[int(Component::Lost)]) EXPECT_EQ(v, 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Cases, WaveFlat,
                         ::testing::Values(FlatCase{"Al", 0.0, true}, FlatCase{"Al", 40.0, true},
                                           FlatCase{"Al", 75.0, true}, FlatCase{"BK7", 0.0, true},
                                           FlatCase{"BK7", 40.0, true}, FlatCase{"BK7", 75.0, true},
                                           FlatCase{"BK7", 180.0 - 30.0, true}, FlatCase{"BK7", 180.0 - 60.0, true},
                                           FlatCase{"Al", 0.0, false}, FlatCase{"Al", 40.0, false},
                                           FlatCase{"Al", 75.0, false}, FlatCase{"BK7", 0.0, false},
                                           FlatCase{"BK7", 40.0, false}, FlatCase{"BK7", 75.0, false},
                                           FlatCase{"BK7", 180.0 - 30.0, false}),
                         [](const auto& info) {
                           return info.param.material + "_" + std::to_string(int(info.param.theta)) +
                                  (info.param.window ? "_window" : "_aperture");
                         });
