// Procedural microgeometry: watertight where it must be, areas against closed forms, and
// statistics of the random surfaces.
#include "geometry/generators.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "geometry/random_field.h"

using namespace mbsdf;

namespace {
// Edges used by exactly one triangle that are not on the patch boundary: holes.
size_t interiorBoundaryEdges(const Microgeometry& g) {
  std::map<std::pair<uint32_t, uint32_t>, int> count;
  for (auto& t : g.triangles)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = t[k], b = t[(k + 1) % 3];
      count[{std::min(a, b), std::max(a, b)}]++;
    }
  size_t holes = 0;
  double tol = 1e-9 * g.sizeX;
  auto onBoundary = [&](const Vec3& v) {
    return std::abs(std::abs(v.x) - g.sizeX / 2) < tol || std::abs(std::abs(v.y) - g.sizeY / 2) < tol;
  };
  for (auto& [e, n] : count) {
    if (n == 2) continue;
    if (n == 1 && onBoundary(g.vertices[e.first]) && onBoundary(g.vertices[e.second])) continue;
    ++holes;
  }
  return holes;
}
// Every triangle normal consistent with the orientation of its neighbours (each shared edge is
// traversed in opposite directions by the two triangles).
size_t inconsistentEdges(const Microgeometry& g) {
  std::map<std::pair<uint32_t, uint32_t>, int> dir;
  for (auto& t : g.triangles)
    for (int k = 0; k < 3; ++k) dir[{t[k], t[(k + 1) % 3]}]++;
  size_t bad = 0;
  for (auto& [e, n] : dir)
    if (n > 1) ++bad;
  return bad;
}
}  // namespace

TEST(Generators, DomeLatticeIsWatertightWithHemisphereArea) {
  const double r = 2.0;
  Microgeometry g =
      makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {r, r, r}, .resolution_um = 0.05});
  EXPECT_EQ(interiorBoundaryEdges(g), 0u);
  EXPECT_EQ(inconsistentEdges(g), 0u);
  // 16 cells: ground 25 − π r² plus dome 2π r² each.
  double expected = 16 * (25 - kPi * r * r + 2 * kPi * r * r);
  EXPECT_NEAR(g.surfaceArea(), expected, 0.005 * expected);
  EXPECT_NEAR(g.zMax(), r, 1e-12);
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    Vec3 n = g.triangleNormal(t);
    // Outward: on the dome, along the radius; on the ground, up.
    Vec3 c = (g.vertices[g.triangles[t][0]] + g.vertices[g.triangles[t][1]] + g.vertices[g.triangles[t][2]]) / 3.0;
    if (c.z > 1e-6) {
      Vec3 cell{std::floor(c.x / 5) * 5 + 2.5, std::floor(c.y / 5) * 5 + 2.5, 0};
      ASSERT_GT(dot(n, c - cell), 0) << "dome triangle " << t;
    } else {
      ASSERT_GT(n.z, 0) << "ground triangle " << t;
    }
  }
}

TEST(Generators, OverhangIsWatertightAndOverhangs) {
  Microgeometry g = makeOverhang({.size_um = {10, 10},
                                  .spacing_um = 5,
                                  .stem_radius_um = 0.8,
                                  .stem_height_um = 1.5,
                                  .cap_radius_um = 2.0,
                                  .cap_height_um = 1.0,
                                  .resolution_um = 0.1});
  EXPECT_EQ(interiorBoundaryEdges(g), 0u);
  EXPECT_EQ(inconsistentEdges(g), 0u);
  size_t down = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t)
    if (g.triangleNormal(t).z < -1e-12) ++down;
  EXPECT_GT(down, 0u) << "the cap's underside faces down: not a heightfield";
  // Per cell: ground 25 − π rs², stem wall 2π rs h, underside π(rc² − rs²), dome 2π rc² (capH = rc
  // would be a hemisphere; here an oblate spheroid, so only bound it).
  double rs = 0.8, h = 1.5, rc = 2.0;
  double lower = 4 * (25 - kPi * rs * rs + 2 * kPi * rs * h + kPi * (rc * rc - rs * rs) + kPi * rc * rc);
  EXPECT_GT(g.surfaceArea(), lower);
}

TEST(Generators, ProfilesAreExactAndPeriodic) {
  Microgeometry v = makeRidged(10, 4, 2.0, 90.0, 0);
  EXPECT_NEAR(v.zMax(), 1.0, 1e-12);  // 90° apex: depth = period / 2
  EXPECT_NEAR(v.surfaceArea(), 10 * 4 * std::sqrt(2.0), 1e-9);
  Microgeometry b = makeBinaryGrating(10, 4, 2.0, 0.3, 0.5, 0);
  EXPECT_NEAR(b.surfaceArea(), 10 * 4 + 2 * 5 * 0.3 * 4, 1e-9);
  EXPECT_THROW(makeRidged(10, 4, 3.0, 90.0, 0), std::invalid_argument);  // 10/3 periods
  Microgeometry s = makeSineGrating(10, 4, 5.0, 0.05, 64, 0);
  EXPECT_NEAR(s.zMax(), 0.05, 1e-4);
  EXPECT_NEAR(s.zMin(), -0.05, 1e-4);
}

TEST(RandomField, GaussianHasRequestedRmsAndCorrelation) {
  const int n = 256;
  const double L = 32, rms = 0.2, corr = 2.0;
  auto h = gaussianRandomField(n, n, L, L, rms, corr, 11);
  double s2 = 0, m = 0;
  for (double v : h) {
    m += v;
    s2 += v * v;
  }
  EXPECT_NEAR(m / h.size(), 0.0, 1e-12);
  EXPECT_NEAR(std::sqrt(s2 / h.size()), rms, 1e-12);
  // Autocorrelation at lag = corr along x: exp(-1) of the variance (statistical: ±0.1).
  int lag = int(corr / (L / n));
  double c = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) c += h[j * n + i] * h[j * n + (i + lag) % n];
  c /= double(h.size()) * rms * rms;
  EXPECT_NEAR(c, std::exp(-1.0), 0.1);
}

TEST(RandomField, SparseConvolutionNoiseIsNormalisedAndSeeded) {
  auto a = sparseConvolutionNoise(128, 128, 20, 20, 0.132, 5.0, 3.0, 1);
  auto b = sparseConvolutionNoise(128, 128, 20, 20, 0.132, 5.0, 3.0, 1);
  auto c = sparseConvolutionNoise(128, 128, 20, 20, 0.132, 5.0, 3.0, 2);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  double s2 = 0;
  for (double v : a) s2 += v * v;
  EXPECT_NEAR(std::sqrt(s2 / a.size()), 0.132, 1e-12);
}

TEST(Generators, GroundNoiseDisplacesAllVerticesPeriodically) {
  Microgeometry g = makeFlat(10, 10, 0.05);
  addGroundNoise(g, 0.01, 0.2, 4);
  double s2 = 0;
  for (auto& v : g.vertices) s2 += v.z * v.z;
  EXPECT_NEAR(std::sqrt(s2 / g.vertices.size()), 0.01, 0.002);
  // Periodic: opposite edges have the same heights.
  std::map<long, double> left, right;
  for (auto& v : g.vertices) {
    if (std::abs(v.x + 5) < 1e-9) left[std::lround(v.y * 1e6)] = v.z;
    if (std::abs(v.x - 5) < 1e-9) right[std::lround(v.y * 1e6)] = v.z;
  }
  ASSERT_FALSE(left.empty());
  for (auto& [y, z] : left) EXPECT_NEAR(z, right[y], 1e-12);
}
