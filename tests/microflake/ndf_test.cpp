// NDFs, extinction and visible-normal sampling against independent quadrature, and the Smith
// functions simulated in the medium against their closed forms (Dupuy et al. 2016, Eqs. 4, 6, 17–22).
#include "microflake/ndf.h"

#include <gtest/gtest.h>

#include "microflake_test_util.h"

namespace mbsdf {
namespace {

// Beckmann α = 0.5 as a table (the general path), and a full-sphere shape D ∝ 1 + cos θ.
TabulatedNdf tabulatedBeckmann(double alpha, int rows = 2000) {
  TabulatedNdf t;
  MicroflakeDistribution b(BeckmannNdf{alpha, alpha});
  for (int i = 0; i < rows; ++i) {
    double mz = double(i) / (rows - 1);
    t.cosTheta.push_back(mz);
    t.value.push_back(b.D({std::sqrt(1 - mz * mz), 0, mz}) * 3.0);  // any scale: normalised by Eq. 17
  }
  return t;
}
TabulatedNdf tabulatedSphere() {
  TabulatedNdf t;
  for (int i = 0; i <= 100; ++i) {
    double mz = -1 + i / 50.0;
    t.cosTheta.push_back(mz);
    t.value.push_back(1 + mz);
  }
  return t;
}

std::vector<std::pair<std::string, Ndf>> ndfs() {
  return {{"tabBeckmann0.5", tabulatedBeckmann(0.5)},
          {"tabSphere", tabulatedSphere()},
          {"beckmann0.2", BeckmannNdf{0.2, 0.2}},
          {"beckmann0.8", BeckmannNdf{0.8, 0.8}},
          {"beckmannAniso", BeckmannNdf{0.3, 0.7}},
          {"ggx0.2", GgxNdf{0.2, 0.2}},
          {"ggx0.8", GgxNdf{0.8, 0.8}},
          {"ggxAniso", GgxNdf{0.6, 0.25}},
          {"vmf0", VonMisesFisherNdf{0.0}},
          {"vmf0.05", VonMisesFisherNdf{0.05}},
          {"vmf0.45", VonMisesFisherNdf{0.45}},
          {"vmf3", VonMisesFisherNdf{3.0}},
          {"vmf40", VonMisesFisherNdf{40.0}}};
}

std::vector<Vec3> travelDirections() {
  std::vector<Vec3> v;
  for (double th : {5.0, 20.0, 60.0, 85.0, 89.9, 90.0, 95.0, 120.0, 160.0, 180.0})
    v.push_back(sphericalDirection(radians(th), radians(35.0)));
  return v;
}

TEST(Ndf, ProjectedAreaIsOneEq17) {
  for (auto& [name, ndf] : ndfs()) {
    MicroflakeDistribution dist(ndf);
    double a =
        test::sphereIntegral([&](const Vec3& m) { return dist.D(m) * std::max(0.0, m.z); }, dist.isHeightfield(), 384);
    EXPECT_NEAR(a, 1.0, 2e-4) << name;
  }
}

// σ(d) = ∫ ⟨−d, m⟩ D(m) dm (Dupuy et al. 2016, Eq. 4) by quadrature, against the closed forms of Eqs. 18–19
// (Λ of docs/physics.md §9) and the vMF table.
TEST(Ndf, ExtinctionMatchesQuadratureEq4) {
  for (auto& [name, ndf] : ndfs()) {
    MicroflakeDistribution dist(ndf);
    for (const Vec3& d : travelDirections()) {
      double ref = test::sphereIntegral([&](const Vec3& m) { return std::max(0.0, -dot(d, m)) * dist.D(m); },
                                        dist.isHeightfield(), 160);
      EXPECT_NEAR(dist.sigma(d), ref, 3e-4 * std::max(1.0, ref) + 1e-6)
          << name << " theta " << degrees(sphericalTheta(d));
      EXPECT_TRUE(std::isfinite(dist.sigma(d)));
    }
  }
}

TEST(Ndf, SmithLambdaClosedForms) {
  // GGX α = 1 at 60°: Λ = (−1 + √(1 + tan²θ))/2 = 0.5; Beckmann Λ(ν = 1) = (erf 1 − 1)/2 + e^{−1}/(2√π).
  MicroflakeDistribution ggx(GgxNdf{1.0, 1.0});
  EXPECT_NEAR(ggx.lambda(sphericalDirection(radians(60.0), 0.3)), 0.5, 1e-14);
  MicroflakeDistribution beck(BeckmannNdf{0.5, 0.5});
  Vec3 w = sphericalDirection(std::atan(2.0), 0.0);  // tan θ = 2 → ν = 1/(α tan θ) = 1
  EXPECT_NEAR(beck.lambda(w), (std::erf(1.0) - 1) / 2 + std::exp(-1.0) / (2 * std::sqrt(kPi)), 1e-14);
  // Large ν (> 20) uses an asymptotic branch: compare with the direct formula in long double, where
  // the cancellation of the two e^{−ν²} terms still leaves ~6 significant digits.
  for (long double nu : {4.9L, 12.0L, 19.9L, 20.1L, 25.0L}) {
    Vec3 wv = sphericalDirection(std::atan(1 / (0.5 * double(nu))), 0.0);
    long double ref = (std::exp(-nu * nu) / (nu * std::sqrt(std::acos(-1.0L))) - std::erfc(nu)) / 2;
    EXPECT_NEAR(beck.lambda(wv) / double(ref), 1.0, 1e-4) << "nu " << double(nu);
  }
}

// A steep downward flight through a smooth Beckmann medium has σ = |d_z| exactly: the shadowed
// term Λ(−d)|d_z| is below half an ulp of |d_z| there; upward, σ is below the walk's bound. Swept over α (isotropic and
// not), azimuth and polar angle from ν = 6.5 down to the vertical, against Λ's closed form.
TEST(Ndf, SteepBeckmannExtinctionIsTheCosineDownAndBoundedUp) {
  for (const BeckmannNdf ndf : {BeckmannNdf{0.01, 0.01}, BeckmannNdf{0.1, 0.1}, BeckmannNdf{0.5, 0.5},
                                BeckmannNdf{2.0, 2.0}, BeckmannNdf{0.05, 0.4}}) {
    MicroflakeDistribution dist(ndf);
    for (double phi = 0; phi < 2 * kPi; phi += 0.37)
      for (double nu = 6.5; nu < 1e4; nu *= 1.05) {
        // ν = |d_z| / (α(φ) sin θ): tan θ = 1 / (α(φ) ν).
        const double alphaPhi = std::hypot(ndf.alphaX * std::cos(phi), ndf.alphaY * std::sin(phi));
        const Vec3 up = sphericalDirection(std::atan(1 / (alphaPhi * nu)), phi), d = -up;
        ASSERT_EQ(dist.sigma(d), up.z) << "alpha " << ndf.alphaX << "/" << ndf.alphaY << " nu " << nu;
        ASSERT_LT(dist.lambda(up) * up.z, std::ldexp(up.z, -54)) << "nu " << nu;
        // The walk's bound on the upward flight's σ, with which it decides certain escapes.
        if (nu > 6.5 * (1 + 1e-9)) {
          ASSERT_GE(dist.upwardSigmaBound(up), dist.sigma(up)) << "nu " << nu;
        }
        ASSERT_LT(dist.upwardSigmaBound(d), 0.0);
      }
    for (double nu = 0.01; nu < 6.4; nu *= 1.05) {  // no bound below ν = 6.5
      const Vec3 up = sphericalDirection(std::atan(1 / (ndf.alphaX * nu)), 0.0);
      ASSERT_LT(dist.upwardSigmaBound(up), 0.0) << "nu " << nu;
    }
  }
}

// The walk's upper bound on an upward GGX flight's σ, q²/(4 d_z), with which it decides certain
// escapes: above σ (to rounding, which the walk's margin of 1e-9 covers) from the vertical down to
// grazing flights, for isotropic and anisotropic α and every azimuth; none for downward flights.
TEST(Ndf, GgxUpwardExtinctionBound) {
  for (const GgxNdf ndf : {GgxNdf{0.01, 0.01}, GgxNdf{0.3, 0.3}, GgxNdf{2.0, 2.0}, GgxNdf{0.05, 0.8}}) {
    MicroflakeDistribution dist(ndf);
    for (double phi = 0; phi < 2 * kPi; phi += 0.37)
      for (double cosTheta = 1; cosTheta > 1e-12; cosTheta *= 0.8) {
        const Vec3 up = sphericalDirection(std::acos(cosTheta), phi);
        const double bound = dist.upwardSigmaBound(up), sigma = dist.sigma(up);
        ASSERT_GE(bound * (1 + 1e-12), sigma) << "alpha " << ndf.alphaX << "/" << ndf.alphaY << " cos " << cosTheta;
        // Tight where σ is small (steep flights of a smooth surface), where the walk meets it.
        if (sigma < 1e-3 * up.z) {
          ASSERT_LE(bound, 1.01 * sigma) << "cos " << cosTheta;
        }
        ASSERT_LT(dist.upwardSigmaBound(-up), 0.0);
      }
  }
}

// Visible normals: sample moments against ∫ g(m) ⟨v,m⟩ D(m) dm / σ(−v) by quadrature (Eq. 6).
TEST(Ndf, VisibleNormalSamplingMatchesEq6) {
  const uint64_t N = 100000;
  for (auto& [name, ndf] : ndfs()) {
    MicroflakeDistribution dist(ndf);
    for (double th : {20.0, 85.0, 130.0}) {
      const Vec3 v = sphericalDirection(radians(th), radians(70.0));
      const double sig = dist.sigma(-v);
      // Sampling costs ∝ 1/σ tries; the walk only samples after a collision, whose rate is ∝ σ, so
      // directions with a vanishing cross-section are never sampled there.
      if (sig < 1e-3) continue;
      std::array<std::function<double(const Vec3&)>, 3> g = {
          [](const Vec3& m) { return m.x; }, [](const Vec3& m) { return m.y; }, [](const Vec3& m) { return m.z; }};
      std::array<double, 3> s1{}, s2{};
      for (uint64_t i = 0; i < N; ++i) {
        Sampler s(7, 0, i);
        auto m = dist.sampleVisible(v, s);
        ASSERT_TRUE(m.has_value()) << name << " theta_v " << th;
        ASSERT_GT(dot(*m, v), 0) << name;
        for (int k = 0; k < 3; ++k) {
          double x = g[k](*m);
          s1[k] += x;
          s2[k] += x * x;
        }
      }
      for (int k = 0; k < 3; ++k) {
        double ref = test::sphereIntegral([&](const Vec3& m) { return g[k](m) * std::max(0.0, dot(v, m)) * dist.D(m); },
                                          dist.isHeightfield(), 96) /
                     sig;
        double mean = s1[k] / N, se = std::sqrt(std::max(0.0, s2[k] / N - mean * mean) / N);
        EXPECT_LT(std::abs(mean - ref), 4 * se + 2e-4) << name << " theta_v " << th << " moment " << k;
      }
    }
  }
}

// Seed Eqs. 20–22 simulated with points z = log U (Eq. 16) and exponential free paths (Eq. 11).
TEST(Ndf, SmithFunctionsBySimulationEqs20to22) {
  const uint64_t N = 400000;
  for (auto& [name, ndf] : ndfs()) {
    if (name.find("Aniso") != std::string::npos || name.rfind("vmf", 0) == 0 || name.rfind("tab", 0) == 0) continue;
    MicroflakeDistribution dist(ndf);
    for (double thI : {20.0, 60.0, 85.0})
      for (double thO : {20.0, 60.0, 85.0}) {
        const Vec3 wi = sphericalDirection(radians(thI), 0.0), wo = sphericalDirection(radians(thO), radians(130.0));
        const double Li = dist.lambda(wi), Lo = dist.lambda(wo);
        uint64_t masked = 0, bistatic = 0, given = 0;
        for (uint64_t n = 0; n < N; ++n) {
          Sampler s(11, uint32_t(thI * 10 + thO), n);
          const double z = std::log1p(-s.get1D());  // Eq. 16: z = log U (U in (0, 1])
          const bool visO = dist.freePath(wo, s.get1D()) * wo.z > -z;
          const bool visI = dist.freePath(wi, s.get1D()) * wi.z > -z;
          masked += visO;
          bistatic += visO && visI;
          // Shadowing given masking: the point is where a path from wi first collides.
          const double z1 = -dist.freePath(-wi, s.get1D()) * wi.z;
          given += dist.freePath(wo, s.get1D()) * wo.z > -z1;
        }
        auto check = [&](uint64_t k, double ref, const char* what) {
          double p = double(k) / N, se = std::sqrt(ref * (1 - ref) / N);
          EXPECT_LE(std::abs(p - ref), 3 * se)
              << name << " " << what << " θi=" << thI << " θo=" << thO << " p=" << p << " ref=" << ref;
        };
        if (thI == 20.0) check(masked, 1 / (1 + Lo), "masking Eq.20");
        check(bistatic, 1 / (1 + Li + Lo), "bistatic Eq.21");
        check(given, (1 + Li) / (1 + Li + Lo), "shadowing-given-masking Eq.22");
      }
  }
}

}  // namespace
}  // namespace mbsdf

namespace mbsdf {
namespace {
TEST(Ndf, TabulatedBeckmannMatchesClosedForm) {
  MicroflakeDistribution b(BeckmannNdf{0.5, 0.5}), t(tabulatedBeckmann(0.5));
  for (double th : {0.0, 30.0, 60.0, 85.0, 90.0, 120.0, 180.0}) {
    Vec3 d = sphericalDirection(radians(th), 0.4);
    EXPECT_NEAR(t.sigma(d), b.sigma(d), 2e-3 * std::max(1.0, b.sigma(d))) << th;
  }
  TabulatedNdf bad;
  bad.cosTheta = {-1.0, -0.5};
  bad.value = {1.0, 1.0};
  EXPECT_THROW(normaliseNdfTable(bad), std::invalid_argument);  // nothing above the horizon
}
}  // namespace
}  // namespace mbsdf
