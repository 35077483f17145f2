// The cell a periodic patch repeats (geometry/lattice_cell.h): found for the lattices the generators
// build, not found where a single facet breaks the repetition or the patch does not repeat, and one
// facet per orbit kept (a cell's worth of surface area).
#include "geometry/lattice_cell.h"

#include <gtest/gtest.h>

#include "geometry/generators.h"

using namespace mbsdf;

namespace {
double areaOf(const Microgeometry& g, const std::vector<uint32_t>& facets) {
  double a = 0;
  for (uint32_t t : facets) a += g.triangleArea(t);
  return a;
}
}  // namespace

// The paper's HEMISPHERES: 4 x 4 domes in a 20 µm patch repeat a 5 µm cell; a rectangular lattice
// (20 x 10 µm, spacing 5 x 2.5 µm) likewise, per axis.
TEST(LatticeCell, DomeLatticesRepeatTheirSpacing) {
  const Microgeometry g =
      makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 8});
  const LatticeCell c = latticeCellOf(g);
  EXPECT_EQ(c.nx, 4);
  EXPECT_EQ(c.ny, 4);
  EXPECT_DOUBLE_EQ(c.sizeX, 5.0);
  EXPECT_DOUBLE_EQ(c.sizeY, 5.0);
  ASSERT_EQ(c.facets.size() * 16, g.triangles.size());
  EXPECT_NEAR(areaOf(g, c.facets), g.surfaceArea() / 16, 1e-9 * g.surfaceArea());
  const LatticeCell r = latticeCellOf(
      makeDomeLattice({.size_um = {20, 10}, .spacing_um = {5, 2.5}, .radii_um = {1, 1, 1}, .resolution_um = 0.25}));
  EXPECT_EQ(r.nx, 4);
  EXPECT_EQ(r.ny, 4);
  EXPECT_DOUBLE_EQ(r.sizeY, 2.5);
}

// A sine grating of 4 periods repeats its period along x; along y its strips span the patch.
TEST(LatticeCell, GratingRepeatsItsPeriod) {
  const LatticeCell c = latticeCellOf(makeSineGrating(20, 20, 5, 0.05, 64, 0));
  EXPECT_EQ(c.nx, 4);
  EXPECT_EQ(c.ny, 1);
}

// No false cells: a random heightfield, a non-periodic patch, a lattice with one vertex moved by
// 1e-4 of the patch (every translation then maps that dome's facets onto nothing), a single cell.
TEST(LatticeCell, NoCellWhereThePatchDoesNotRepeat) {
  const Microgeometry gauss = makeGaussian(10, 10, 0.1, 1.0, 64, 64, 3);
  const LatticeCell c = latticeCellOf(gauss);
  EXPECT_EQ(c.copies(), 1);
  EXPECT_EQ(c.facets.size(), gauss.triangles.size());
  Microgeometry open =
      makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25});
  open.periodic = false;
  EXPECT_EQ(latticeCellOf(open).copies(), 1);
  Microgeometry broken =
      makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25});
  size_t top = 0;
  for (size_t v = 0; v < broken.vertices.size(); ++v)
    if (broken.vertices[v].z > broken.vertices[top].z) top = v;
  broken.vertices[top].z -= 2e-3;
  EXPECT_EQ(latticeCellOf(broken).copies(), 1);
  EXPECT_EQ(latticeCellOf(makeDomeLattice(
                              {.size_um = {5, 5}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}))
                .copies(),
            1);
}
