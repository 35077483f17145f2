// Rotation symmetry of explicit microgeometry (symmetry.h): detected from the facets themselves.
#include <gtest/gtest.h>

#include "geometry/generators.h"
#include "job/symmetry.h"

using namespace mbsdf;

TEST(Symmetry, RotationOrderOfPatches) {
  // A square lattice of hemispheres: 4-fold.
  EXPECT_EQ(rotationOrderOf(makeDomeLattice(10, 10, 5, 5, 2, 2, 2, 0.25)), 4);
  // The same lattice with elliptic domes (rx != ry): only 2-fold.
  EXPECT_EQ(rotationOrderOf(makeDomeLattice(10, 10, 5, 5, 2, 1.5, 1.5, 0.25)), 2);
  // A random heightfield: none.
  EXPECT_EQ(rotationOrderOf(makeGaussian(10, 10, 0.3, 1.0, 64, 64, 3)), 1);
  // A rectangular flat patch (two triangles): 2-fold, not 4 (the patch is not square).
  EXPECT_EQ(rotationOrderOf(makeFlat(10, 6, 10)), 2);
  // A 4-fold lattice shifted off the patch centre is still 4-fold: periodic wrap-around.
  Microgeometry shifted = makeDomeLattice(10, 10, 5, 5, 2, 2, 2, 0.25);
  for (auto& v : shifted.vertices) v.x += 2.5, v.y += 2.5;
  EXPECT_EQ(rotationOrderOf(shifted), 4);
}
