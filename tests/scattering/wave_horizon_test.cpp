// Orders at the horizon (Rayleigh anomalies): a periodic patch of period Λ sends its order m exactly
// to grazing when n Λ / λ = m. The wavelength is swept through such crossings — exactly, ± 1e-9 and
// ± 1e-3 relative — for a 1-D grating and a 2-D lattice, a conductor and a dielectric lit from both
// sides, through every wave estimator. Every value must be finite and no bin may carry more than the
// incident power. The hemispherical energy stays within the physical bound, R + T ≤ 1 (lossless
// dielectric) and R ≤ 1 (conductor), within 4 reported errors plus the scalar model's own excess at
// an anomaly: a newly propagating order keeps a finite power (lobeSecant) that the other orders do
// not give up, 2.7 % at most on these shallow structures (before, the centre's 1/cos θ_G made it
// 2778 on a binary grating lit from inside glass). The `paper` estimator is held to finiteness only:
// its Var/P bias puts bins and energies far above 1 whenever a lobe is narrower than a bin, at any
// wavelength (the paper's method, kept for comparison; `auto` never picks it).
#include <gtest/gtest.h>

#include <cmath>

#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {

struct HorizonCase {
  const char* name;
  Microgeometry geometry;
  std::vector<const char*> estimators;
};

// Wavelengths that put an order of a period-2 µm patch at the horizon of air (Λ/m) or glass
// (1.5 Λ/m) at normal incidence, each exactly and at ± 1e-9 and ± 1e-3 relative.
std::vector<double> horizonWavelengths() {
  std::vector<double> l;
  for (double crossing : {2.0 / 4, 3.0 / 5, 2.0 / 3, 3.0 / 4})
    for (double d : {-1e-3, -1e-9, 0.0, 1e-9, 1e-3}) l.push_back(crossing * (1 + d));
  return l;
}

constexpr double kModelExcess = 0.03;

void checkTile(const WaveScenario& sc, const WaveTileResult& r, bool conductor, bool fromAbove, bool bounded,
               const std::string& what) {
  const int nL = int(sc.lambda_um.size());
  for (int l = 0; l < nL; ++l) {
    for (int b = 0; b < sc.grid.binCount(); ++b) {
      const size_t i = size_t(l) * sc.grid.binCount() + size_t(b);
      ASSERT_TRUE(std::isfinite(r.fws[i]) && std::isfinite(r.fwsErr[i])) << what << " λ " << sc.lambda_um[l];
      if (!bounded) continue;
      const double op = sc.grid.projectedSolidAngle(b);
      // No bin carries more than the incident power, of either sign (the Monte Carlo estimators'
      // unbiased |Σ X|² − Σ |X|² may be negative), at 6 reported errors: ~10⁵ bins are checked.
      EXPECT_LE(std::abs(r.fws[i]) * op, 1.0 + 6 * r.fwsErr[i] * op)
          << what << " λ " << sc.lambda_um[l] << " bin " << b;
    }
    auto [R, eR] = sc.integral(r.fws, r.fwsErr, l, fromAbove);
    auto [T, eT] = sc.integral(r.fws, r.fwsErr, l, !fromAbove);
    const double total = R + (conductor ? 0.0 : T), err = conductor ? eR : std::hypot(eR, eT);
    if (bounded) {
      EXPECT_LE(total, 1 + kModelExcess + 4 * err) << what << " λ " << sc.lambda_um[l] << ": R " << R << " T " << T;
    }
  }
}

}  // namespace

TEST(WaveHorizon, OrdersThroughTheHorizonStayFiniteAndBounded) {
  const std::vector<double> lambdas = horizonWavelengths();
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  std::vector<HorizonCase> cases;
  cases.push_back(
      {"binary grating", makeBinaryGrating(2, 0.5, 2, 0.05, 0.5, 0.05), {"exact", "orders", "area", "paper"}});
  cases.push_back(
      {"dome lattice",
       makeDomeLattice({.size_um = {2, 2}, .spacing_um = {2, 2}, .radii_um = {0.6, 0.6, 0.1}, .resolution_um = 0.1}),
       {"exact", "orders", "area"}});
  cases.push_back({"gaussian heightfield", makeGaussian(2, 2, 0.02, 0.5, 32, 32, 5), {"fft", "exact"}});
  int tiles = 0;
  for (const HorizonCase& c : cases)
    for (const char* est : c.estimators)
      for (bool conductor : {true, false}) {
        WaveSettings ws;
        ws.estimator = waveEstimatorKind(est);
        const std::string name = est;
        ws.samplesPerBin = name == "paper" ? 16 : name == "orders" ? 512 : 128;
        ws.pointsPerDirection = 16;
        WaveScenario sc(c.geometry, conductor ? material("Al") : glass, ThetaPhiGrid{12, 24}, lambdas, 20.0, ws);
        for (double theta : conductor ? std::vector<double>{0.0} : std::vector<double>{0.0, 180.0}) {
          const std::string what = std::string(c.name) + " " + est + (conductor ? " Al" : " glass") +
                                   (theta > 90 ? " from inside" : " from above");
          // A collimated beam (the crossing is exact) and the incidence bin around it.
          for (bool exact : {true, false}) {
            WaveTileResult r = sc.run(theta, 0.0, exact, tiles++);
            checkTile(sc, r, conductor, theta < 90, name != "paper", what + (exact ? " collimated" : " bin-averaged"));
          }
        }
      }
  RecordProperty("tiles", tiles);
}

// The case that found it: a binary glass grating (period 5 µm, depth 0.25 µm) lit from inside the
// glass at 500 nm, where n Λ / λ = 15 sends the reflected orders ±15 exactly to grazing. `exact`
// reported a reflected energy of 2778 with a relative error of 6e-4, `orders` 6785.
TEST(WaveHorizon, BinaryGratingFromInsideGlassAtAWholeNumber) {
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  for (const char* est : {"exact", "orders"}) {
    WaveSettings ws;
    ws.estimator = waveEstimatorKind(est);
    ws.samplesPerBin = 1024;
    WaveScenario sc(makeBinaryGrating(5, 1, 5, 0.25, 0.5, 0.05), glass, ThetaPhiGrid{72, 4}, {0.499, 0.5, 0.501}, 50.0,
                    ws);
    WaveTileResult r = sc.run(180.0, 0.0, /*exact=*/true);
    checkTile(sc, r, false, false, true, est);
    for (int l = 0; l < 3; ++l) {
      auto [up, eUp] = sc.integral(r.fws, r.fwsErr, l, true);
      auto [down, eDown] = sc.integral(r.fws, r.fwsErr, l, false);
      RecordProperty(std::string(est) + "_total_" + std::to_string(l), std::to_string(up + down));
      EXPECT_NEAR(up + down, 1.0, 0.05 + 4 * std::hypot(eUp, eDown)) << est << " λ " << sc.lambda_um[size_t(l)];
    }
  }
}
