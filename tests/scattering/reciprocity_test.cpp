// Reciprocity (docs/physics.md §8): the pair rule that halves the wave term, the exit mask of the
// estimators, and the physics it relies on — the bin-averaged Kirchhoff BSDF computed both ways,
// f(i → o) against f(o → i) · n_i² / n_o², within the estimators' own standard errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "core/rng.h"
#include "geometry/generators.h"
#include "scattering/reciprocity.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

// Every unordered pair of incidence bins on the same side is computed by exactly one of its two
// tiles; every tile computes its own bin, the exit bins that are not incidence bins and the other
// side (transmission); the tiles are balanced: ⌈N/2⌉ to ⌊N/2⌋ + 1 same-side incidence columns each.
TEST(ReciprocalPairs, EachPairOnceAndBalanced) {
  for (int nUp = 1; nUp <= 9; ++nUp)
    for (int nDown : {0, 1, 4, 7}) {
      const int perHemisphere = 2 * std::max(nUp, nDown) + 3, nBins = 2 * perHemisphere;
      std::vector<int> bins;
      // Not contiguous: bins 0, 2, ... of each hemisphere are exits only.
      for (int i = 0; i < nUp; ++i) bins.push_back(2 * i + 1);
      for (int i = 0; i < nDown; ++i) bins.push_back(perHemisphere + 2 * i + 1);
      ReciprocalPairs p(bins, nBins, perHemisphere);
      const int n = int(bins.size());
      int total = 0;
      for (int i = 0; i < n; ++i) {
        const bool up = bins[i] < perHemisphere;
        const int nSide = up ? nUp : nDown;
        EXPECT_TRUE(p.computes(i, bins[i]));
        int columns = 0;
        for (int b = 0; b < nBins; ++b) {
          if (p.incidenceOf(b) < 0 || (b < perHemisphere) != up)
            EXPECT_TRUE(p.computes(i, b));
          else
            columns += p.computes(i, b);
        }
        EXPECT_GE(columns, (nSide + 1) / 2) << "tile " << i;
        EXPECT_LE(columns, nSide / 2 + 1) << "tile " << i;
        total += columns;
        for (int j = i + 1; j < n; ++j) {
          if ((bins[j] < perHemisphere) == up)
            EXPECT_NE(p.computes(i, bins[j]), p.computes(j, bins[i])) << "pair " << i << " " << j;
          else
            EXPECT_TRUE(p.computes(i, bins[j]) && p.computes(j, bins[i])) << "pair " << i << " " << j;
        }
        std::vector<uint8_t> m = p.exitMask(i);
        for (int b = 0; b < nBins; ++b) EXPECT_EQ(m[b] != 0, p.computes(i, b));
      }
      EXPECT_DOUBLE_EQ(p.computedFraction(), double(total) / (double(nUp) * nUp + double(nDown) * nDown));
    }
  EXPECT_THROW(ReciprocalPairs({1, 1}, 4, 2), std::invalid_argument);
  EXPECT_THROW(ReciprocalPairs({5}, 4, 2), std::invalid_argument);
}

// The exit mask only skips bins: the bins an estimator computes are bit-identical to the run
// without a mask (their random numbers are keyed by bin), the others hold 0, and the sample count
// falls with the number of bins.
TEST(ReciprocalPairs, MaskedEstimatorsComputeTheSameBins) {
  for (const char* estimator : {"area", "paper"}) {
    WaveSettings ws;
    ws.estimator = waveEstimatorKind(estimator);
    ws.samplesPerBin = 256;
    WaveScenario sc(makeGaussian(10, 10, 0.3, 1.0, 64, 64, 3), material("Al"), ThetaPhiGrid{4, 8}, {0.55}, 0.0, ws);
    const int inc = sc.grid.binOf(sphericalDirection(radians(40), radians(30)));
    WaveTileResult full = sc.estimator->run(3, inc, std::nullopt);
    std::vector<uint8_t> mask(size_t(sc.grid.binCount()), 0);
    for (int b = 0; b < sc.grid.binsPerHemisphere(); b += 3) mask[size_t(b)] = 1;
    WaveTileResult part = sc.estimator->run(3, inc, std::nullopt, {}, mask);
    EXPECT_EQ(part.computed, mask);
    int computed = 0;
    for (int b = 0; b < sc.grid.binCount(); ++b) {
      if (mask[size_t(b)]) {
        ++computed;
        EXPECT_EQ(part.fws[size_t(b)], full.fws[size_t(b)]) << estimator << " bin " << b;
        EXPECT_EQ(part.fwsErr[size_t(b)], full.fwsErr[size_t(b)]) << estimator << " bin " << b;
      } else {
        EXPECT_EQ(part.fws[size_t(b)], 0.0);
      }
    }
    if (std::string(estimator) == "area") {
      EXPECT_EQ(part.samples * uint64_t(sc.grid.binsPerHemisphere()), full.samples * uint64_t(computed));
    }
  }
}

namespace {
// f_ws(i → o) and f_ws(o → i) for random pairs of bins of `sides` (0: both above, 1: i above and o
// below, 2: both below), each estimated alone through the exit mask; returns the z-scores of
// f(i → o) / n_o² − f(o → i) / n_i². Transmission pairs take o as the bin of the refracted
// direction of i's centre, where the transmitted lobe is (elsewhere the values are within noise of
// zero and would not test the n² factor).
std::vector<double> reciprocityZ(const WaveScenario& sc, int sides, int pairs, double nBelow) {
  const int nU = sc.grid.binsPerHemisphere();
  Sampler pick(7, uint32_t(sides), 0);
  std::vector<double> z;
  auto one = [&](int tile, int from, int to, double* se) {
    std::vector<uint8_t> mask(size_t(sc.grid.binCount()), 0);
    mask[size_t(to)] = 1;
    WaveTileResult r = sc.estimator->run(tile, from, std::nullopt, {}, mask);
    *se = r.fwsErr[size_t(to)];
    return r.fws[size_t(to)];
  };
  for (int attempt = 0; attempt < 10 * pairs && int(z.size()) < pairs; ++attempt) {
    int i = int(pick.get1D() * nU) + (sides == 2 ? nU : 0);
    int o = int(pick.get1D() * nU) + (sides >= 1 ? nU : 0);
    if (sides == 1) {
      // Snell: the tangential component shrinks by 1/n (the direction stays in the plane of incidence).
      const Vec3 c = sc.grid.centre(i);
      const double tx = -c.x / nBelow, ty = -c.y / nBelow;
      o = sc.grid.binOf(Vec3{tx, ty, -std::sqrt(1 - tx * tx - ty * ty)});
    }
    if (i == o) continue;
    const double ni = sc.grid.isUpper(i) ? 1.0 : nBelow, no = sc.grid.isUpper(o) ? 1.0 : nBelow;
    double sa, sb;
    const double a = one(2 * attempt, i, o, &sa) / (no * no), b = one(2 * attempt + 1, o, i, &sb) / (ni * ni);
    sa /= no * no;
    sb /= ni * ni;
    // The standard errors come from 128 independent exit directions per bin: reliable enough for a
    // z-score whether or not the value is resolved.
    if (!(sa > 0 && sb > 0)) continue;
    z.push_back((a - b) / std::sqrt(sa * sa + sb * sb));
  }
  return z;
}

void expectReciprocal(const std::vector<double>& z, int minPairs, const std::string& what) {
  ASSERT_GE(int(z.size()), minPairs) << what;
  ASSERT_FALSE(z.empty());
  double z2 = 0, maxZ = 0;
  for (double v : z) {
    EXPECT_LT(std::abs(v), 4.0) << what;
    z2 += v * v;
    maxZ = std::max(maxZ, std::abs(v));
  }
  // Mean z² of n standard normals: 1 ± sqrt(2/n); 2.5 is more than 4 standard deviations for n ≥ 12.
  EXPECT_LT(z2 / double(z.size()), 2.5) << what;
  ::testing::Test::RecordProperty(what + "_mean_z2", std::to_string(z2 / double(z.size())));
  ::testing::Test::RecordProperty(what + "_max_abs_z", std::to_string(maxZ));
}
}  // namespace

// A rough aluminium gaussian surface (rms 0.3 µm, correlation 1 µm, 10 µm patch, no window) at
// 550 nm, bin-averaged incidence on a 4 x 8 grid: f_ws(i → o) = f_ws(o → i) within 4 standard
// errors for 16 random bin pairs.
TEST(WaveReciprocity, RoughConductor) {
  WaveSettings ws;
  ws.samplesPerBin = 65536;
  ws.pointsPerDirection = 2048;
  WaveScenario sc(makeGaussian(10, 10, 0.3, 1.0, 100, 100, 11), material("Al"), ThetaPhiGrid{4, 8}, {0.55}, 0.0, ws);
  expectReciprocal(reciprocityZ(sc, 0, 16, 1.0), 12, "reflection_Al");
}

// The same surface as glass (n = 1.5): reflection above and reflection inside the glass (where
// total internal reflection is part of the bin pairs), and transmission, f(i → o)/n_o² =
// f(o → i)/n_i², with o the bin of i's refracted direction. Transmission from inside the glass is
// evaluated on the air side's tangent plane (wave::integrandAt); while it used the glass side's,
// whose integrand drops every facet past the critical angle, these pairs were not reciprocal and
// their estimates heavy-tailed (the sum over 32 pairs moved by 6.6 between point budgets against
// standard errors of 1.1–1.7).
TEST(WaveReciprocity, RoughDielectric) {
  WaveSettings ws;
  ws.samplesPerBin = 65536;
  ws.pointsPerDirection = 2048;
  const double n = 1.5;
  Material glass;
  glass.model = Dielectric{ConstantIndex{n, 0}};
  WaveScenario sc(makeGaussian(10, 10, 0.3, 1.0, 100, 100, 11), glass, ThetaPhiGrid{4, 8}, {0.55}, 0.0, ws);
  expectReciprocal(reciprocityZ(sc, 0, 12, n), 8, "reflection_above");
  expectReciprocal(reciprocityZ(sc, 1, 16, n), 12, "transmission");
  expectReciprocal(reciprocityZ(sc, 2, 12, n), 8, "reflection_below");
}
