// The microflake random walk against analytic references: depth 1 against the
// single-scattering microfacet BRDF, white furnace, reciprocity (with the n² scaling for
// transmission), Chandrasekhar's isotropic medium (Dupuy et al. 2016, Eqs. 25 and 30) and the vMF limits.
#include "microflake/microflake_walk.h"

#include <gtest/gtest.h>

#include <memory>

#include "microflake/chandrasekhar.h"
#include "microflake_test_util.h"
#include "../scattering/scattering_test_util.h"

namespace mbsdf {
namespace {

struct WalkCase {
  MicroflakeDistribution dist;
  Material mat;
  DirectionGrid grid;
  std::vector<double> lambda_um;
  MicroflakeWalk walk;
  WalkCase(Ndf ndf, Material m, DirectionGrid::Layout layout, MicroflakeSettings s, std::vector<double> l = {0.55})
      : dist(ndf), mat(std::move(m)), grid(layout), lambda_um(std::move(l)), walk(dist, mat, lambda_um, grid, s) {}
};

// H(μ) tabulated for the references (linear interpolation on 4001 points: error < 1e-5, far below
// the Monte Carlo standard errors it is compared with).
std::function<double(double)> hTable(double a) {
  auto t = std::make_shared<std::vector<double>>(4001);
  for (int i = 0; i <= 4000; ++i) (*t)[i] = chandrasekharH(i / 4000.0, a);
  return [t](double mu) {
    double x = std::clamp(mu, 0.0, 1.0) * 4000;
    int i = std::min(3999, int(x));
    return (*t)[i] + (x - i) * ((*t)[i + 1] - (*t)[i]);
  };
}

MicroflakeSettings settings(uint64_t paths, int maxDepth = 1000, double albedo = 1.0) {
  MicroflakeSettings s;
  s.paths = paths;
  s.maxDepth = maxDepth;
  s.flakeAlbedo = albedo;
  return s;
}

// Per-bin comparison: every significant bin within 5 standard errors, ≥ 95 % within 3 (the
// expectation for a correct estimator is 99.7 %), and at least `minBins` bins compared.
void expectBinsMatch(const TileResult& r, const DirectionGrid& g, Component c,
                     const std::function<double(int bin)>& reference, int minBins, const std::string& what) {
  int compared = 0, within3 = 0;
  for (int b = 0; b < r.nBins; ++b) {
    const double v = r.at(c, 0, b), se = r.stdError[int(c)][b];
    const double ref = reference(b);
    ASSERT_TRUE(std::isfinite(v) && std::isfinite(se));
    if (ref <= 0 && v == 0) continue;
    if (!(se > 0) || se > 0.2 * std::max(ref, 1e-300)) continue;  // too few samples to say anything
    ++compared;
    const double z = (v - ref) / se;
    within3 += std::abs(z) < 3;
    EXPECT_LT(std::abs(z), 5) << what << " bin " << b << " value " << v << " ref " << ref << " se " << se;
  }
  EXPECT_GE(compared, minBins) << what;
  EXPECT_GE(within3, minBins) << what;
  EXPECT_GE(within3, 0.95 * compared) << what << ": " << within3 << " of " << compared << " bins within 3 SE";
}

// All orders (coherent + multiple, errors combined) against Chandrasekhar's Eq. 30 for albedo a.
void expectChandrasekharEq30(const WalkCase& c, const TileResult& r, const Vec3& wi, double a,
                             const std::string& what) {
  TileResult sum = r;
  for (int b = 0; b < r.nBins; ++b) {
    sum.at(Component::Coherent, 0, b) += r.at(Component::Multiple, 0, b);
    sum.stdError[0][b] = std::hypot(r.stdError[0][b], r.stdError[int(Component::Multiple)][b]);
  }
  const double Hi = chandrasekharH(wi.z, a);
  auto H = hTable(a);
  expectBinsMatch(
      sum, c.grid, Component::Coherent,
      [&](int b) {
        return c.grid.isUpper(b)
                   ? test::binAverage(c.grid, b,
                                      [&](const Vec3& wo) { return a / (4 * kPi) * Hi * H(wo.z) / (wi.z + wo.z); })
                   : 0.0;
      },
      20, what);
}

// Depth 1 = F D G2 / (4 cos θi cos θo) with the height-correlated G2 (Heitz 2014 Eq. 99).
TEST(MicroflakeWalk, SingleScatteringEqualsMicrofacetBRDF) {
  const std::vector<std::pair<std::string, Ndf>> cases = {
      {"beckmann", BeckmannNdf{0.5, 0.5}}, {"ggx", GgxNdf{0.4, 0.4}}, {"ggxAniso", GgxNdf{0.25, 0.6}}};
  for (auto& [name, ndf] : cases) {
    WalkCase c(ndf, test::material("Al"), ThetaPhiGrid{9, 16}, settings(400000));
    const Vec3 wi = sphericalDirection(radians(40.0), radians(10.0));
    TileResult r = c.walk.run(0, 0, c.grid.binOf(wi), wi);
    const Complex eta = c.mat.ior(0.55);
    auto f1 = [&](const Vec3& wo) {
      if (wo.z <= 0) return 0.0;
      const Vec3 h = normalize(wi + wo);
      return fresnelReflectance(dot(wi, h), 1.0, eta) * c.dist.D(h) * c.dist.G2(wi, wo) / (4 * wi.z * wo.z);
    };
    expectBinsMatch(
        r, c.grid, Component::Coherent, [&](int b) { return test::binAverage(c.grid, b, f1); }, 20, name);
  }
}

TEST(MicroflakeWalk, WhiteFurnace) {
  for (Ndf ndf :
       {Ndf(BeckmannNdf{0.1, 0.1}), Ndf(BeckmannNdf{0.5, 0.5}), Ndf(BeckmannNdf{1.0, 1.0}), Ndf(BeckmannNdf{2.0, 2.0}),
        Ndf(GgxNdf{0.1, 0.1}), Ndf(GgxNdf{0.5, 0.5}), Ndf(GgxNdf{1.0, 1.0}), Ndf(GgxNdf{2.0, 2.0})}) {
    WalkCase c(ndf, test::material("mirror"), ThetaPhiGrid{6, 12}, settings(100000, 10000));
    for (double th : {0.0, 60.0, 85.0}) {
      TileResult r = c.walk.run(0, 0, c.grid.binOfAngles(th, 0), sphericalDirection(radians(th), 0));
      double e = 0, se2 = 0;
      for (Component comp : {Component::Coherent, Component::Multiple}) {
        e += test::energy(r, c.grid, comp, 0, true);
        double s = test::energyStdError(r, c.grid, comp, 0, true);
        se2 += s * s;
        EXPECT_EQ(test::energy(r, c.grid, comp, 0, false), 0.0);
      }
      // Every path leaves upward: the albedo is 1 up to the truncated paths.
      EXPECT_LT(std::abs(e - 1), 3 * std::sqrt(se2) + 1e-12) << c.dist.describe() << " θ=" << th;
      EXPECT_NEAR(e + r.truncated[0], 1.0, 1e-12) << c.dist.describe();
      EXPECT_LT(r.truncated[0], 1e-3) << c.dist.describe();
    }
  }
}

// Diffuse (Lambertian) flakes (Heitz et al. 2016 Sec. 6): energy conserving with albedo 1, and
// reciprocal with an absorbing albedo.
TEST(MicroflakeWalk, DiffuseFlakes) {
  MicroflakeSettings s = settings(100000, 10000);
  s.flakes = FlakeKind::Diffuse;
  for (Ndf ndf : {Ndf(BeckmannNdf{0.3, 0.3}), Ndf(GgxNdf{1.0, 1.0}), Ndf(VonMisesFisherNdf{0.0})}) {
    WalkCase c(ndf, test::material("Au"), ThetaPhiGrid{6, 12}, s);  // the material is ignored
    for (double th : {0.0, 70.0}) {
      TileResult r = c.walk.run(0, 0, c.grid.binOfAngles(th, 0), sphericalDirection(radians(th), 0));
      const double e =
          test::energy(r, c.grid, Component::Coherent, 0, true) + test::energy(r, c.grid, Component::Multiple, 0, true);
      EXPECT_NEAR(e + r.truncated[0], 1.0, 1e-12) << c.dist.describe();
      // A conservative volume (the sphere NDF) has heavy-tailed walk lengths, P(depth > n) ~ n^(−1/2):
      // about 1 % of the paths pass 10⁴ collisions. Surface-like NDFs let paths out quickly.
      EXPECT_LT(r.truncated[0], c.dist.isHeightfield() ? 1e-3 : 0.03) << c.dist.describe();
    }
  }
  // Reciprocity in bins (bin-averaged incidence), GGX 0.5 diffuse flakes of albedo 0.7.
  s.flakeAlbedo = 0.7;
  s.paths = 400000;
  WalkCase c(GgxNdf{0.5, 0.5}, test::material("mirror"), ThetaPhiGrid{5, 8}, s);
  std::vector<int> ids;
  std::vector<TileResult> res;
  for (auto [th, ph] : std::vector<std::pair<double, double>>{{9, 10}, {45, 200}, {81, 20}}) {
    ids.push_back(c.grid.binOfAngles(th, ph));
    res.push_back(c.walk.run(int(res.size()), 0, ids.back()));
  }
  for (size_t a = 0; a < ids.size(); ++a)
    for (size_t b = a + 1; b < ids.size(); ++b) {
      double x = 0, y = 0, v = 0;
      for (Component comp : {Component::Coherent, Component::Multiple}) {
        x += res[a].at(comp, 0, ids[b]);
        y += res[b].at(comp, 0, ids[a]);
        v += std::pow(res[a].stdError[int(comp)][ids[b]], 2) + std::pow(res[b].stdError[int(comp)][ids[a]], 2);
      }
      EXPECT_LT(std::abs(x - y), 4 * std::sqrt(v)) << ids[a] << " " << ids[b];
    }
}

TEST(MicroflakeWalk, DielectricConservesEnergy) {
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  for (Ndf ndf : {Ndf(BeckmannNdf{0.3, 0.3}), Ndf(GgxNdf{1.0, 1.0})})
    for (double th : {30.0, 89.0, 150.0}) {  // 150°: from inside the glass, beyond the critical angle
      WalkCase c(ndf, glass, ThetaPhiGrid{6, 12}, settings(100000, 10000));
      TileResult r = c.walk.run(0, 0, c.grid.binOfAngles(th, 0), sphericalDirection(radians(th), 0));
      double e = r.truncated[0];
      for (Component comp : {Component::Coherent, Component::Multiple})
        for (bool up : {true, false}) e += test::energy(r, c.grid, comp, 0, up);
      EXPECT_NEAR(e, 1.0, 1e-12) << c.dist.describe() << " θ=" << th;
      EXPECT_GT(test::energy(r, c.grid, Component::Coherent, 0, th < 90), 0.0);
    }
}

// Bin-averaged incidence makes the table exactly reciprocal in bins: f(I→O) Ω⊥... = f(O→I); for
// transmission f(I→O)/n_O² = f(O→I)/n_I² (radiance BSDF, docs/physics.md §8).
void checkReciprocity(const Ndf& ndf, const Material& mat, const std::vector<std::pair<double, double>>& bins,
                      const std::string& what) {
  WalkCase c(ndf, mat, ThetaPhiGrid{5, 8}, settings(600000, 1000));
  std::vector<int> ids;
  std::vector<TileResult> res;
  for (auto [th, ph] : bins) {
    ids.push_back(c.grid.binOfAngles(th, ph));
    res.push_back(c.walk.run(int(res.size()), 0, ids.back()));
  }
  const double nLower = mat.isConductor() ? 1.0 : mat.ior(0.55).real();
  auto n = [&](int bin) { return c.grid.isUpper(bin) ? mat.outsideIor : nLower; };
  int compared = 0;
  for (size_t a = 0; a < ids.size(); ++a)
    for (size_t b = a + 1; b < ids.size(); ++b) {
      double fab = 0, fba = 0, sab = 0, sba = 0;
      for (Component comp : {Component::Coherent, Component::Multiple}) {
        fab += res[a].at(comp, 0, ids[b]);
        fba += res[b].at(comp, 0, ids[a]);
        sab += std::pow(res[a].stdError[int(comp)][ids[b]], 2);
        sba += std::pow(res[b].stdError[int(comp)][ids[a]], 2);
      }
      // Radiance reciprocity: f(a→b)/n_b² = f(b→a)/n_a².
      const double x = fab / (n(ids[b]) * n(ids[b])), y = fba / (n(ids[a]) * n(ids[a]));
      const double se = std::sqrt(sab / std::pow(n(ids[b]), 4) + sba / std::pow(n(ids[a]), 4));
      if (x == 0 && y == 0) continue;
      ++compared;
      EXPECT_LT(std::abs(x - y), 4 * se) << what << " bins " << ids[a] << " " << ids[b] << ": " << x << " vs " << y;
    }
  EXPECT_GE(compared, int(ids.size() * (ids.size() - 1) / 2) - 1) << what;
}

TEST(MicroflakeWalk, ReciprocityConductor) {
  checkReciprocity(BeckmannNdf{0.6, 0.6}, test::material("Au"), {{9, 10}, {27, 100}, {45, 200}, {63, 300}, {81, 20}},
                   "Au Beckmann 0.6");
}

TEST(MicroflakeWalk, ReciprocityDielectricWithEtaSquared) {
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  checkReciprocity(GgxNdf{0.5, 0.5}, glass, {{27, 10}, {63, 200}, {180 - 27, 100}, {180 - 63, 300}, {180 - 81, 20}},
                   "glass GGX 0.5");
}

// Chandrasekhar's semi-infinite isotropic medium: the constant full-sphere NDF with mirror flakes
// of albedo a. Depth 1 → Eq. 25, all orders → Eq. 30.
TEST(MicroflakeWalk, ConstantNdfIsChandrasekharsMedium) {
  const double a = 0.9;
  WalkCase c(VonMisesFisherNdf{0.0}, test::material("mirror"), ThetaPhiGrid{8, 6}, settings(1000000, 5000, a));
  for (double th : {10.0, 70.0}) {
    const Vec3 wi = sphericalDirection(radians(th), 0);
    TileResult r = c.walk.run(0, 0, c.grid.binOf(wi), wi);
    expectBinsMatch(
        r, c.grid, Component::Coherent,
        [&](int b) {
          return c.grid.isUpper(b)
                     ? test::binAverage(c.grid, b,
                                        [&](const Vec3& wo) { return isotropicMediumSingleBRDF(wi.z, wo.z, a); })
                     : 0.0;
        },
        20, "Eq. 25");
    expectChandrasekharEq30(c, r, wi, a, "Eq. 30");
  }
}

TEST(MicroflakeWalk, VonMisesFisherLimits) {
  // Large κ: albedo of gold flakes within 2 % of Beckmann with α = √(2/κ).
  for (double alpha : {0.1, 0.2, 0.3}) {
    const double kappa = 2 / (alpha * alpha);
    for (double th : {0.0, 45.0, 70.0}) {
      const Vec3 wi = sphericalDirection(radians(th), 0);
      auto albedo = [&](Ndf ndf) {
        WalkCase c(ndf, test::material("Au"), ThetaPhiGrid{4, 4}, settings(100000));
        TileResult r = c.walk.run(0, 0, c.grid.binOf(wi), wi);
        return test::energy(r, c.grid, Component::Coherent, 0, true) +
               test::energy(r, c.grid, Component::Multiple, 0, true);
      };
      const double av = albedo(VonMisesFisherNdf{kappa}), ab = albedo(BeckmannNdf{alpha, alpha});
      EXPECT_NEAR(av / ab, 1.0, 0.02) << "alpha " << alpha << " theta " << th;
    }
  }
  // κ → 0: Chandrasekhar's medium (mirror flakes of albedo a, Eq. 30).
  const double a = 0.8;
  WalkCase c(VonMisesFisherNdf{1e-3}, test::material("mirror"), ThetaPhiGrid{6, 4}, settings(400000, 5000, a));
  const Vec3 wi = sphericalDirection(radians(30.0), 0);
  expectChandrasekharEq30(c, c.walk.run(0, 0, c.grid.binOf(wi), wi), wi, a, "vMF κ=1e-3 vs Eq. 30");
}

// The general path (tabulated NDF: numeric σ table, rejection sampling) reproduces the closed-form
// Beckmann walk: albedo per component within 3 combined standard errors + the table's 1e-3.
TEST(MicroflakeWalk, TabulatedNdfMatchesClosedForm) {
  TabulatedNdf t;
  MicroflakeDistribution b(BeckmannNdf{0.5, 0.5});
  for (int i = 0; i < 2000; ++i) {
    double mz = i / 1999.0;
    t.cosTheta.push_back(mz);
    t.value.push_back(b.D({std::sqrt(1 - mz * mz), 0, mz}));
  }
  for (double th : {20.0, 70.0}) {
    const Vec3 wi = sphericalDirection(radians(th), 0);
    WalkCase cb(BeckmannNdf{0.5, 0.5}, test::material("Al"), ThetaPhiGrid{6, 8}, settings(200000));
    WalkCase ct(t, test::material("Al"), ThetaPhiGrid{6, 8}, settings(200000));
    TileResult rb = cb.walk.run(0, 0, cb.grid.binOf(wi), wi), rt = ct.walk.run(1, 0, ct.grid.binOf(wi), wi);
    for (Component c : {Component::Coherent, Component::Multiple}) {
      double eb = test::energy(rb, cb.grid, c, 0, true), et = test::energy(rt, ct.grid, c, 0, true);
      double se =
          std::hypot(test::energyStdError(rb, cb.grid, c, 0, true), test::energyStdError(rt, ct.grid, c, 0, true));
      EXPECT_LT(std::abs(eb - et), 3 * se + 1e-3) << componentName(c) << " θ=" << th;
    }
  }
}

TEST(MicroflakeWalk, DeterministicAndReplayable) {
  WalkCase c(GgxNdf{0.7, 0.7}, test::material("Cu"), ThetaPhiGrid{6, 12}, settings(20000), {0.45, 0.55, 0.65});
  TileResult a = c.walk.run(3, 0, c.grid.binOfAngles(30, 0)), b = c.walk.run(3, 0, c.grid.binOfAngles(30, 0));
  EXPECT_EQ(a.value[0], b.value[0]);
  EXPECT_EQ(a.value[2], b.value[2]);
  auto rec = c.walk.replay(3, c.grid.binOfAngles(30, 0), 17);
  auto rec2 = c.walk.replay(3, c.grid.binOfAngles(30, 0), 17);
  EXPECT_EQ(rec.exitBin, rec2.exitBin);
  EXPECT_GE(rec.depth, 1);
  ASSERT_EQ(rec.weight.size(), 3u);
  for (double w : rec.weight) EXPECT_TRUE(w >= 0 && w <= 1);
}

// The standard error of a slice's albedo from the per-path energies (TileResult::pathMoments):
// z-scores against Chandrasekhar's directional albedo of the semi-infinite isotropic medium,
// A(μ) = 1 − H(μ) √(1 − a) (Chandrasekhar 1960, Ch. V), for 60 cases of flake albedo a and
// incidence; mean z² within 4 standard deviations (√(2/n)) of 1.
TEST(MicroflakeWalk, AlbedoStandardErrorIsHonest) {
  std::vector<double> z;
  double rssOverSe = 0;
  for (double a : {0.3, 0.5, 0.7, 0.8, 0.9, 0.95}) {
    WalkCase c(VonMisesFisherNdf{0.0}, test::material("mirror"), ThetaPhiGrid{8, 6}, settings(4000, 5000, a));
    const auto H = hTable(a);
    for (double th : {3.0, 15.0, 27.0, 36.0, 45.0, 53.0, 61.0, 69.0, 77.0, 84.0}) {
      const Vec3 wi = sphericalDirection(radians(th), 0);
      TileResult r = c.walk.run(int(z.size()), 0, c.grid.binOf(wi), wi);
      const std::vector<Component> model{Component::Coherent, Component::Multiple};
      const double se = r.pathEnergyStdError(model, -1)[0];
      double albedo = 0, rss = 0;
      for (Component comp : model)
        for (bool up : {true, false}) {
          albedo += test::energy(r, c.grid, comp, 0, up);
          rss += std::pow(test::energyStdError(r, c.grid, comp, 0, up), 2);
        }
      ASSERT_GT(se, 0);
      z.push_back((albedo - (1 - H(wi.z) * std::sqrt(1 - a))) / se);
      rssOverSe += std::sqrt(rss) / se;
    }
  }
  double z2 = 0;
  for (double v : z) z2 += v * v / double(z.size());
  EXPECT_NEAR(z2, 1.0, 4 * std::sqrt(2.0 / double(z.size()))) << z.size() << " cases";
  RecordProperty("mean_z2", std::to_string(z2));
  RecordProperty("rss_over_se", std::to_string(rssOverSe / double(z.size())));
}

}  // namespace
}  // namespace mbsdf
