// A table as the preview's material (render/tabulated_material.h). Its draws must be what it says
// they are: for viewers swept from the normal to grazing, the mean of the draws' weights f |cos θi| / pdf
// equals ∫ f(wi → wo) |cos θi| dωi by quadrature of eval (within 4 standard errors of the draws and the
// quadrature's error, estimated by halving its cells), and the density integrates to at most 1 (the tent's mass beyond
// the horizon is lost, not double counted). A lobe one bin wide (a tabulated mirror) and a broad lobe with
// transmission; both on a theta-phi and on a disk grid.
#include "render/tabulated_material.h"

#include <gtest/gtest.h>

#include <cmath>

#include "render_tables.h"

using namespace mbsdf;

namespace {

// ∫ g(w) dω over the sphere by the midpoint rule on n × 2n cells of (θ, φ).
template <class G>
double sphereQuadrature(const G& g, int n) {
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double th = kPi * (i + 0.5) / n, dOmega = std::sin(th) * (kPi / n) * (kPi / n);
    for (int j = 0; j < 2 * n; ++j) sum += g(sphericalDirection(th, kPi * (j + 0.5) / n)) * dOmega;
  }
  return sum;
}

void expectConsistentSampling(const TabulatedMaterial& m, const char* what) {
  for (double thetaO : {0.0, 30.0, 60.0, 85.0, 89.5})
    for (double phiO : {0.0, 73.0}) {
      const Vec3 wo = sphericalDirection(radians(thetaO), radians(phiO));
      auto fCos = [&](const Vec3& wi) {
        const Colour3 f = m.eval(wi, wo);
        return (f[0] + f[1] + f[2]) / 3 * std::abs(wi.z);
      };
      // The midpoint rule's error estimated by halving its cells.
      const double integral = sphereQuadrature(fCos, 360);
      const double quadratureError = std::abs(integral - sphereQuadrature(fCos, 180));
      const double mass = sphereQuadrature([&](const Vec3& wi) { return m.pdf(wo, wi); }, 360);
      EXPECT_LE(mass, 1 + std::abs(mass - sphereQuadrature([&](const Vec3& wi) { return m.pdf(wo, wi); }, 180)))
          << what << " θo " << thetaO;
      EXPECT_GT(mass, 0.5) << what << " θo " << thetaO;
      const int n = 20000;
      double sum = 0, sum2 = 0;
      for (int i = 0; i < n; ++i) {
        Sampler s(7, 1, uint64_t(i));
        const auto d = m.sample(wo, s);
        if (!d) continue;
        ASSERT_TRUE(std::isfinite(d->weight[0]) && d->pdf > 0);
        EXPECT_NEAR(d->pdf, m.pdf(wo, d->wi), 1e-9 * d->pdf);
        const double x = (d->weight[0] + d->weight[1] + d->weight[2]) / 3;
        sum += x, sum2 += x * x;
      }
      const double mean = sum / n, se = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
      EXPECT_NEAR(mean, integral, 4 * se + quadratureError) << what << " θo " << thetaO << " φo " << phiO;
    }
}

}  // namespace

TEST(TabulatedMaterial, MirrorLobeDrawsMatchTheirDensity) {
  std::vector<double> thetas;
  for (double t = 1; t < 90; t += 2) thetas.push_back(t);
  // All the light in the exit bin of the mirror direction (the two beside it when φ = 180° is an edge).
  for (const char* grid : {"n_theta = 45\nn_phi = 180", "grid = \"disk\"\nwidth = 61\nheight = 61"}) {
    const std::string path =
        test::writeGreyTable("mirror", grid, thetas,
                             [](const Vec3& wi, int b, const DirectionGrid& g) { return test::mirrorBin(wi, b, g); });
    const BsdfFileReader file(path);
    const TabulatedMaterial m(file, "GS");
    expectConsistentSampling(m, grid);
  }
}

TEST(TabulatedMaterial, BroadLobeWithTransmissionDrawsMatchTheirDensity) {
  std::vector<double> thetas;
  for (double t = 2.5; t < 90; t += 5) thetas.push_back(t);
  // A cosine-power lobe about the mirror direction (0.6 of the light) and a Lambertian transmission (0.3).
  auto lobe = [](const Vec3& wi, int b, const DirectionGrid& g) {
    const Vec3 w = g.centre(b);
    if (w.z < 0) return 0.3 / kPi;
    const double c = std::max(0.0, dot(w, Vec3{-wi.x, -wi.y, wi.z}));
    return 0.6 * 12 / (2 * kPi) * std::pow(c, 10) / std::max(w.z, 1e-3);
  };
  for (const char* grid : {"n_theta = 18\nn_phi = 72", "grid = \"disk\"\nwidth = 24\nheight = 24"}) {
    const std::string path = test::writeGreyTable("broad", grid, thetas, lobe);
    const BsdfFileReader file(path);
    const TabulatedMaterial m(file, "GS");
    expectConsistentSampling(m, grid);
  }
}
