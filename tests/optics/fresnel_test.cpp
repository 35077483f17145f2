// Fresnel amplitudes against closed forms that do not share our code path.
#include "optics/fresnel.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/vecmath.h"
#include "optics/material.h"

using namespace mbsdf;

namespace {
// Conductor reflectance in the a², b² form (Born & Wolf; Heckbert; pbrt-v3 FrConductor), an
// independent formulation of the same physics.
double conductorReflectanceReference(double cosT, double n1, double eta, double k) {
  eta /= n1;
  k /= n1;
  double c2 = cosT * cosT, s2 = 1 - c2;
  double e2 = eta * eta, k2 = k * k;
  double t0 = e2 - k2 - s2;
  double a2b2 = std::sqrt(t0 * t0 + 4 * e2 * k2);
  double a = std::sqrt(0.5 * (a2b2 + t0));
  double t1 = a2b2 + c2, t2 = 2 * cosT * a;
  double Rs = (t1 - t2) / (t1 + t2);
  double t3 = c2 * a2b2 + s2 * s2, t4 = t2 * s2;
  double Rp = Rs * (t3 - t4) / (t3 + t4);
  return 0.5 * (Rs + Rp);
}
}  // namespace

TEST(Fresnel, NormalIncidenceMatchesClosedForm) {
  for (Complex n2 : {Complex(1.5, 0), Complex(1.0, 0), Complex(0.96, 6.69), Complex(2.5, 3.0)}) {
    double expected = std::norm((1.0 - n2) / (1.0 + n2));
    EXPECT_NEAR(fresnelReflectance(1.0, 1.0, n2), expected, 1e-14);
  }
}

TEST(Fresnel, ConductorMatchesIndependentFormula) {
  for (double eta : {0.2, 0.96, 1.5, 2.8})
    for (double k : {0.5, 3.0, 6.7})
      for (double deg = 0; deg <= 89.9; deg += 4.7) {
        double c = std::cos(radians(deg));
        EXPECT_NEAR(fresnelReflectance(c, 1.0, Complex(eta, k)), conductorReflectanceReference(c, 1.0, eta, k), 1e-12)
            << eta << " " << k << " " << deg;
      }
}

TEST(Fresnel, BrewsterAngleHasNoPReflection) {
  double n = 1.5;
  double c = std::cos(std::atan(n));
  auto f = fresnelAmplitudes(c, 1.0, Complex(n, 0));
  EXPECT_NEAR(std::abs(f.rp), 0.0, 1e-14);
}

TEST(Fresnel, DielectricEnergyConservation) {
  // R + T = 1 with T = (n2 cos θt / n1 cos θi) |t|², for s and p separately.
  for (double n1 : {1.0, 1.5})
    for (double n2 : {1.0, 1.33, 1.5, 2.4})
      for (double deg = 0; deg < 90; deg += 3.1) {
        double ci = std::cos(radians(deg));
        auto f = fresnelAmplitudes(ci, n1, Complex(n2, 0));
        if (f.totalInternalReflection) {
          EXPECT_NEAR(std::norm(f.rs), 1.0, 1e-12);
          EXPECT_NEAR(std::norm(f.rp), 1.0, 1e-12);
          continue;
        }
        double ct = f.cosTheta_t.real();
        double Ts = n2 * ct / (n1 * ci) * std::norm(f.ts);
        double Tp = n2 * ct / (n1 * ci) * std::norm(f.tp);
        EXPECT_NEAR(std::norm(f.rs) + Ts, 1.0, 1e-12);
        EXPECT_NEAR(std::norm(f.rp) + Tp, 1.0, 1e-12);
      }
}

TEST(Fresnel, CriticalAngleAndGrazingAreFinite) {
  double n1 = 1.5, n2 = 1.0;
  double crit = std::asin(n2 / n1);
  for (double d : {-1e-6, 0.0, 1e-6}) {
    double ci = std::cos(crit + d);
    double R = fresnelReflectance(ci, n1, Complex(n2, 0));
    EXPECT_TRUE(std::isfinite(R));
    EXPECT_GE(R, 0.0);
    EXPECT_LE(R, 1.0);
    if (d > 0) {
      EXPECT_DOUBLE_EQ(R, 1.0);
    }
  }
  for (Complex n : {Complex(1.5, 0), Complex(1.0, 0), Complex(1.0 + 1e-9, 0), Complex(0.96, 6.69)}) {
    double R = fresnelReflectance(0.0, 1.0, n);
    EXPECT_TRUE(std::isfinite(R));
    EXPECT_NEAR(R, 1.0, 1e-9);  // grazing incidence reflects everything
  }
}

TEST(Fresnel, PerfectConductor) {
  auto f = perfectConductorAmplitudes();
  EXPECT_DOUBLE_EQ(std::norm(f.rs), 1.0);
  EXPECT_DOUBLE_EQ(std::norm(f.rp), 1.0);
}

TEST(Material, TablesInterpolateAndReject) {
  Material al;
  ASSERT_TRUE(builtinMaterial("Al", &al));
  // Table node at 551.040771 nm: eta 0.963, k 6.70.
  Complex n = al.ior(0.551040771);
  EXPECT_NEAR(n.real(), 0.963, 1e-9);
  EXPECT_NEAR(n.imag(), 6.70, 1e-9);
  EXPECT_THROW(al.ior(0.2), std::out_of_range);
  Material bk7;
  ASSERT_TRUE(builtinMaterial("BK7", &bk7));
  // Schott N-BK7: n_d = 1.5168 at 587.56 nm.
  EXPECT_NEAR(bk7.ior(0.5875618).real(), 1.5168, 1e-4);
  EXPECT_FALSE(bk7.directionsIndependentOfLambda());
  EXPECT_TRUE(al.directionsIndependentOfLambda());
}
