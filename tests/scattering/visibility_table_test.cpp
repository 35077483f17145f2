// The shared visibility table of `exact` (scattering/visibility_table.h): where it answers, it
// answers as the ray does; `exact`'s tables with it match those that cast every ray, with far fewer
// rays per tile.
#include "scattering/visibility_table.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/rng.h"
#include "geometry/generators.h"
#include "scattering/wave_common.h"
#include "wave_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

// Random first-level points of a hemisphere cell and random directions of both hemispheres (glass:
// the lower table too): every answer the table gives equals the ray's, and it answers most queries.
TEST(VisibilityTable, AnswersAsTheRayDoes) {
  const Microgeometry g =
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.5});
  const PeriodicScene scene(g);
  const LatticeCell cell = latticeCellOf(g);
  const VisibilityTable table(g, scene, cell, 64, true);
  Sampler s(7, 0, 0, 0);
  int answered = 0, wrong = 0, queries = 0;
  for (int q = 0; q < 100000; ++q) {
    const uint32_t t = uint32_t(std::min<size_t>(g.triangles.size() - 1, size_t(s.get1D() * g.triangles.size())));
    const int k = std::min(3, int(s.get1D() * 4));
    const bool up = s.get1D() < 0.5;
    const double z = s.get1D(), phi = 2 * kPi * s.get1D(), r = std::sqrt(std::max(0.0, 1 - z * z));
    const Vec3 d{r * std::cos(phi), r * std::sin(phi), up ? z : -z};
    const Vec3 n = normalize(g.triangleNormal(t)), side = up ? n : -n;
    if (dot(side, d) <= 0) continue;
    ++queries;
    const auto& tri = g.triangles[t];
    const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
    const std::optional<bool> e = table.escapes(t, k, side, d, up);
    if (!e) continue;
    ++answered;
    wrong += *e != wave::escapes(scene, pts[size_t(k)], side, d, t, up);
  }
  RecordProperty("queries", queries);
  RecordProperty("answered", answered);
  RecordProperty("wrong", wrong);
  EXPECT_GT(answered, queries * 7 / 10);
  EXPECT_LE(wrong, answered / 10000) << wrong << " of " << answered;
}

namespace {
// Relative L1 distance of `exact`'s WS tables with and without the table, and their ray counts.
void expectTableKeepsExact(const Microgeometry& g, const Material& m, double theta, double phi) {
  WaveSettings rays, table;
  rays.estimator = table.estimator = WaveEstimatorKind::Exact;
  table.visibilityTable = 128;  // the production value (at 64 one of these cases differed by 1.1e-3)
  const WaveScenario a(g, m, ThetaPhiGrid{15, 30}, {0.6}, 60.0, rays),
      b(g, m, ThetaPhiGrid{15, 30}, {0.6}, 60.0, table);
  const WaveTileResult ra = a.run(theta, phi, true), rb = b.run(theta, phi, true);
  const WaveTileResult rb2 = b.run(theta, phi, true);  // the table is built once, by the first tile
  double d = 0, n = 0;
  for (int bin = 0; bin < a.grid.binCount(); ++bin) {
    const double op = a.grid.projectedSolidAngle(bin);
    ASSERT_TRUE(std::isfinite(rb.fws[size_t(bin)]));
    d += std::abs(rb.fws[size_t(bin)] - ra.fws[size_t(bin)]) * op;
    n += std::abs(ra.fws[size_t(bin)]) * op;
  }
  EXPECT_LT(d / n, 1e-4);
  EXPECT_EQ(rb2.fws, rb.fws);
  EXPECT_LT(double(rb2.rays), 0.85 * double(ra.rays)) << rb2.rays << " vs " << ra.rays;
  ::testing::Test::RecordProperty("relative_L1", std::to_string(d / n));
  ::testing::Test::RecordProperty("rays_without", std::to_string(ra.rays));
  ::testing::Test::RecordProperty("rays_with", std::to_string(rb2.rays));
}
}  // namespace

// Mirror hemispheres at 50° (shadowing and masking between domes), OVERHANG at 40° (caps over
// stems) and glass hemispheres at 30° (the lower table: transmitted orders): the same tables, far
// fewer rays per tile.
TEST(VisibilityTable, ExactTablesMatchCastingEveryRay) {
  Material glass;
  glass.model = Dielectric{ConstantIndex{1.5, 0}};
  expectTableKeepsExact(
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.5}),
      material("mirror"), 50.0, 20.0);
  expectTableKeepsExact(makeOverhang({.size_um = {5, 5},
                                      .spacing_um = 5,
                                      .stem_radius_um = 0.6,
                                      .stem_height_um = 1.0,
                                      .cap_radius_um = 1.8,
                                      .cap_height_um = 0.6,
                                      .resolution_um = 0.5}),
                        material("mirror"), 40.0, 10.0);
  expectTableKeepsExact(
      makeDomeLattice({.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.5}), glass,
      30.0, 0.0);
}
