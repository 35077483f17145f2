// Conditioning of a measured height map against closed forms: the Laplace fill reproduces harmonic
// functions (planes, the saddle x² − y²) through interior holes, levelling removes a plane or a
// paraboloid exactly and ignores unmeasured points, crops, mirrors and windows do what they say.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "geometry/topography_conditioning.h"

namespace mbsdf {
namespace {

Topography grid(int nx, int ny, double dx, double dy, auto&& f) {
  Topography t;
  t.nx = nx;
  t.ny = ny;
  t.dx_um = dx;
  t.dy_um = dy;
  t.source = "test";
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) t.z_um.push_back(f(i, j));
  return t;
}

// Holes away from the border, at random: ~20 % of the points, some in clusters.
std::vector<uint8_t> interiorHoles(int nx, int ny, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<uint8_t> valid(size_t(nx) * ny, 1);
  for (int j = 1; j < ny - 1; ++j)
    for (int i = 1; i < nx - 1; ++i)
      if (rng() % 5 == 0) valid[size_t(j) * nx + i] = 0;
  for (int j = 10; j < 20; ++j)  // one 10 x 10 hole
    for (int i = 5; i < 15; ++i) valid[size_t(j) * nx + i] = 0;
  return valid;
}

TEST(TopographyConditioning, LaplaceFillReproducesHarmonicFunctions) {
  const int nx = 40, ny = 30;
  const auto plane = [](int i, int j) { return 0.3 + 0.01 * i - 0.02 * j; };
  const auto saddle = [](int i, int j) { return 1e-3 * (double(i - 17) * (i - 17) - double(j - 11) * (j - 11)); };
  for (auto f : {std::function<double(int, int)>(plane), std::function<double(int, int)>(saddle)}) {
    Topography t = grid(nx, ny, 0.1, 0.1, f);
    t.valid = interiorHoles(nx, ny, 7);
    for (size_t k = 0; k < t.size(); ++k)
      if (!t.valid[k]) t.z_um[k] = 1e3;  // whatever the instrument left there must not matter
    ConditioningReport r;
    fillInvalidPoints(t, &r);
    EXPECT_GT(r.filled, 100u);
    EXPECT_TRUE(t.valid.empty());
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) ASSERT_NEAR(t.z_um[size_t(j) * nx + i], f(i, j), 1e-8) << i << ", " << j;
  }
}

TEST(TopographyConditioning, FillAtTheBorderStaysWithinTheMeasuredRange) {
  const int n = 24;
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0, 1);
  Topography t = grid(n, n, 1, 1, [&](int, int) { return g(rng); });
  t.valid.assign(t.size(), 1);
  for (int i = 0; i < n; ++i) t.valid[i] = t.valid[size_t(i) * n] = 0;  // the first row and column
  double lo = 1e300, hi = -1e300;
  for (size_t k = 0; k < t.size(); ++k)
    if (t.valid[k]) lo = std::min(lo, t.z_um[k]), hi = std::max(hi, t.z_um[k]);
  fillInvalidPoints(t, nullptr);
  for (double z : t.z_um) {
    EXPECT_TRUE(std::isfinite(z));
    EXPECT_GE(z, lo - 1e-9);
    EXPECT_LE(z, hi + 1e-9);
  }
}

TEST(TopographyConditioning, NothingMeasuredIsAnError) {
  Topography t = grid(4, 4, 1, 1, [](int, int) { return 0.0; });
  t.valid.assign(16, 0);
  EXPECT_THROW(fillInvalidPoints(t, nullptr), InputError);
}

TEST(TopographyConditioning, LevellingRemovesPlaneAndParaboloidFromMeasuredPointsOnly) {
  const int nx = 50, ny = 40;
  const double dx = 0.2, dy = 0.25, sx = 0.03, sy = -0.04;  // slopes, µm per µm
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0, 0.01);
  std::vector<double> texture(size_t(nx) * ny);
  for (double& v : texture) v = g(rng);
  // A plane: the fitted plane of (plane + texture) differs from the plane by the texture's own fit.
  Topography t = grid(nx, ny, dx, dy, [&](int i, int j) { return 1.0 + sx * i * dx + sy * j * dy; });
  t.valid = interiorHoles(nx, ny, 9);
  for (size_t k = 0; k < t.size(); ++k)
    if (!t.valid[k]) t.z_um[k] = -50;  // not measured: must not pull the fit
  ConditioningReport r;
  removePolynomial(t, 1, &r);
  EXPECT_NEAR(r.removedTilt_deg, std::atan(std::hypot(sx, sy)) * 180 / M_PI, 1e-9);
  for (size_t k = 0; k < t.size(); ++k) {
    if (t.valid[k]) {
      ASSERT_NEAR(t.z_um[k], t.z_um[0], 1e-10);
    }
  }
  // A paraboloid with texture, order 2: what remains is the texture minus its own quadratic part,
  // which is small; the paraboloid's curvature is gone.
  Topography p = grid(nx, ny, dx, dy, [&](int i, int j) {
    const double x = i * dx - 4, y = j * dy - 5;
    return 0.2 * x * x - 0.1 * x * y + 0.3 * y * y + texture[size_t(j) * nx + i];
  });
  removePolynomial(p, 2, nullptr);
  double rms = 0, rmsTexture = 0;
  for (size_t k = 0; k < p.size(); ++k) rms += (p.z_um[k] - p.z_um[0]) * (p.z_um[k] - p.z_um[0]);
  for (double v : texture) rmsTexture += (v - texture[0]) * (v - texture[0]);
  EXPECT_LT(std::sqrt(rms / p.size()), 1.1 * std::sqrt(rmsTexture / p.size()));
  EXPECT_GT(std::sqrt(rms / p.size()), 0.8 * std::sqrt(rmsTexture / p.size()));
}

TEST(TopographyConditioning, CropMirrorWindow) {
  const auto f = [](int i, int j) { return 0.01 * i + 0.1 * std::sin(0.3 * j) + 0.02 * i * j; };
  const Topography t = grid(20, 16, 0.5, 0.5, f);
  TopographyConditioning c;
  c.crop = std::array<int, 4>{3, 2, 10, 8};
  ConditioningReport r;
  const Topography cropped = conditionTopography(t, c, "test.toml: [geometry] crop_texels", &r);
  ASSERT_EQ(cropped.nx, 10);
  ASSERT_EQ(cropped.ny, 8);
  for (int j = 0; j < 8; ++j)
    for (int i = 0; i < 10; ++i) EXPECT_EQ(cropped.z_um[size_t(j) * 10 + i], f(i + 3, j + 2));
  c.crop = std::array<int, 4>{12, 2, 10, 8};
  try {
    conditionTopography(t, c, "test.toml: [geometry] crop_texels", nullptr);
    FAIL() << "a crop outside the grid was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("crop_texels"), std::string::npos) << e.what();
  }
  // Mirror: 2(n-1) per side, even about the last column and row, so the wrap meets itself.
  c.crop.reset();
  c.edges = EdgeTreatment::Mirror;
  const Topography m = conditionTopography(t, c, "test", &r);
  ASSERT_EQ(m.nx, 38);
  ASSERT_EQ(m.ny, 30);
  for (int j = 0; j < m.ny; ++j)
    for (int i = 0; i < m.nx; ++i) {
      const int si = i < 20 ? i : 38 - i, sj = j < 16 ? j : 30 - j;
      ASSERT_EQ(m.z_um[size_t(j) * m.nx + i], f(si, sj));
    }
  // Window: the border at the mean, the inside untouched.
  c.edges = EdgeTreatment::Window;
  c.windowFraction = 0.25;
  const Topography w = conditionTopography(t, c, "test", &r);
  double mean = 0;
  for (double z : t.z_um) mean += z;
  mean /= double(t.size());
  for (int i = 0; i < 20; ++i) EXPECT_NEAR(w.z_um[i], mean, 1e-12);
  EXPECT_EQ(w.z_um[size_t(8) * 20 + 10], t.z_um[size_t(8) * 20 + 10]);
  c.windowFraction = 0.7;
  EXPECT_THROW(conditionTopography(t, c, "test", nullptr), InputError);
}

}  // namespace
}  // namespace mbsdf
