// Chandrasekhar's H function (Dupuy et al. 2016, Eq. 31) against its moments and tabulated value.
#include "microflake/chandrasekhar.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/quadrature.h"

namespace mbsdf {
namespace {

TEST(Chandrasekhar, ZerothMomentClosedForm) {
  // ∫_0^1 H(μ) dμ = 2 (1 − √(1 − a)) / a (Chandrasekhar 1960, Eq. V.(25)).
  for (double a : {0.5, 0.9, 0.99, 1.0}) {
    double m0 = tanhSinh([&](double mu, double) { return chandrasekharH(mu, a); }, 0.0, 1.0, 1e-12);
    EXPECT_NEAR(m0, 2 * (1 - std::sqrt(1 - a)) / a, 1e-6) << "a = " << a;
  }
}

TEST(Chandrasekhar, ConservativeValuesAndIntegralEquation) {
  EXPECT_NEAR(chandrasekharH(1.0, 1.0), 2.9078, 5e-5);
  EXPECT_DOUBLE_EQ(chandrasekharH(0.0, 1.0), 1.0);
  // H satisfies 1/H(μ) = √(1−a) + (a/2) ∫_0^1 μ' H(μ') / (μ + μ') dμ' (Chandrasekhar Eq. V.(37)).
  for (double a : {0.3, 0.9, 1.0})
    for (double mu : {0.05, 0.5, 1.0}) {
      double I = tanhSinh([&](double m, double) { return m * chandrasekharH(m, a) / (mu + m); }, 0.0, 1.0, 1e-10);
      EXPECT_NEAR(1 / chandrasekharH(mu, a), std::sqrt(1 - a) + a / 2 * I, 1e-9) << a << " " << mu;
    }
  // Finite and monotone near a → 1.
  double prev = 1;
  for (double mu = 0.0; mu <= 1.0; mu += 0.01) {
    double h = chandrasekharH(mu, 1 - 1e-12);
    EXPECT_TRUE(std::isfinite(h));
    EXPECT_GE(h, prev - 1e-12);
    prev = h;
  }
}

}  // namespace
}  // namespace mbsdf
