// Rotation symmetry of explicit microgeometry (symmetry.h): detected from the facets themselves.
#include <gtest/gtest.h>

#include "geometry/generators.h"
#include "job/symmetry.h"

using namespace mbsdf;

TEST(Symmetry, RotationAndMirrorOfPatches) {
  auto expect = [](const Microgeometry& g, int order, bool mirror, const char* what) {
    const PatchSymmetry s = patchSymmetryOf(g);
    EXPECT_EQ(s.rotationOrder, order) << what;
    EXPECT_EQ(s.mirror, mirror) << what;
  };
  // A square lattice of hemispheres: 4-fold and mirror.
  expect(makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}), 4,
         true, "hemispheres");
  // The same lattice with elliptic domes (rx != ry): 2-fold and mirror.
  expect(makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 1.5, 1.5}, .resolution_um = 0.25}),
         2, true, "elliptic domes");
  // A random heightfield: none.
  expect(makeGaussian(10, 10, 0.3, 1.0, 64, 64, 3), 1, false, "gaussian");
  // A rectangular flat patch of two triangles: 2-fold (not 4: not square); the mirror maps its
  // diagonal onto the other one, but the surface (a plane) is mirror symmetric.
  expect(makeFlat(10, 6, 10), 2, true, "flat");
  // A sine profile along x: z(−x) = −z(x) is no rotation symmetry, but y -> −y is a mirror.
  expect(makeSineGrating(5, 1, 5, 0.1, 32, 0), 1, true, "sine grating");
  // A 4-fold lattice whose facets are shifted by half a period (out of the centred cell) is still
  // 4-fold: facets are compared modulo the period.
  Microgeometry shifted =
      makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25});
  for (auto& v : shifted.vertices) v.x += 2.5, v.y += 2.5;
  EXPECT_EQ(patchSymmetryOf(shifted).rotationOrder, 4);
  // A long thin grating (500 × 1 µm, 100 periods, 20 rows): centroids are matched within 1e-6 of
  // each side's own length, so rows 0.05 µm apart are told apart; its surface is mirror symmetric.
  expect(makeSineGrating(500, 1, 5, 0.05, 64, 0.05), 1, true, "long thin grating");
  // More than 64 facets on one spot: too degenerate to check, reported as no symmetry.
  Microgeometry stacked = makeFlat(10, 10, 10);
  const auto tri = stacked.triangles.front();
  for (int k = 0; k < 70; ++k) stacked.triangles.push_back(tri);
  expect(stacked, 1, false, "stacked facets");
}
