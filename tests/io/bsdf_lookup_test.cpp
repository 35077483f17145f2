// The interpolation between a table's bins (io/bsdf_lookup.h) against closed forms: a function
// linear in θ and φ is reproduced exactly between bin centres, the weights form a partition of unity
// on the direction's side, the pole is approached continuously from every azimuth, and the disk
// grid's empty corner pixels get no weight.
#include "io/bsdf_lookup.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace mbsdf;

namespace {
double sum(const std::vector<std::pair<int, double>>& w) {
  double s = 0;
  for (const auto& [b, x] : w) s += x;
  return s;
}
}  // namespace

TEST(BsdfLookup, ThetaPhiReproducesLinearFunctionsBetweenCentres) {
  const DirectionGrid grid(ThetaPhiGrid{12, 24});
  // g(θ, φ) = θ + 0.3 φ at the bins' centres, evaluated at directions between centres (away from the
  // pole, the horizon and the φ = 0 seam, where g itself is not linear).
  auto g = [](const Vec3& w) { return std::acos(std::abs(w.z)) + 0.3 * sphericalPhi(w); };
  for (double theta_deg : {10.0, 23.1, 47.9, 80.0})
    for (double phi_deg : {20.0, 101.3, 250.0}) {
      for (double side : {1.0, -1.0}) {
        Vec3 w = sphericalDirection(radians(theta_deg), radians(phi_deg));
        w.z *= side;
        const auto weights = interpolationWeights(grid, w);
        EXPECT_NEAR(sum(weights), 1.0, 1e-12);
        double f = 0;
        for (const auto& [b, x] : weights) {
          EXPECT_EQ(grid.isUpper(b), side > 0);
          f += x * g(grid.centre(b));
        }
        EXPECT_NEAR(f, g(w), 1e-9) << theta_deg << " " << phi_deg;
      }
    }
}

TEST(BsdfLookup, PoleIsContinuousFromEveryAzimuth) {
  const DirectionGrid grid(ThetaPhiGrid{12, 24});
  // Just off the pole the value is the first ring's mean whatever the azimuth: f = bin index.
  std::vector<double> near;
  for (double phi_deg = 0; phi_deg < 360; phi_deg += 17) {
    double f = 0;
    for (const auto& [b, x] : interpolationWeights(grid, sphericalDirection(radians(1e-7), radians(phi_deg))))
      f += x * b;
    near.push_back(f);
  }
  for (double f : near) EXPECT_NEAR(f, near.front(), 1e-6);
  EXPECT_NEAR(near.front(), (0 + 23) / 2.0, 1e-6);  // the mean index of ring 0
}

TEST(BsdfLookup, DiskGridSkipsEmptyPixels) {
  const DirectionGrid grid(DiskGrid{9, 9});
  for (double theta_deg = 0; theta_deg <= 89.9; theta_deg += 4.7)
    for (double phi_deg = 0; phi_deg < 360; phi_deg += 29) {
      const auto weights = interpolationWeights(grid, sphericalDirection(radians(theta_deg), radians(phi_deg)));
      EXPECT_NEAR(sum(weights), 1.0, 1e-12);
      for (const auto& [b, x] : weights) {
        if (x > 0) {
          EXPECT_GT(grid.projectedSolidAngle(b), 0) << theta_deg << " " << phi_deg;
        }
      }
    }
}
