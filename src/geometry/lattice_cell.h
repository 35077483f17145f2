// The smallest rectangular cell a periodic patch repeats (the paper's HEMISPHERES: 4 x 4 cells of
// 5 µm in a 20 µm patch; a 20 µm sine grating of period 5 µm: 4 x 1; a regularly triangulated flat
// patch: one texel).
//
// Why it matters (docs/physics.md §5, orders_estimator.h): a patch made of nx x ny copies of a cell has
// order amplitudes Ĥ_G only on the cell's reciprocal lattice G = 2π (a nx/Lx, b ny/Ly) — for any
// other G of the patch's lattice the copies' phases e^{i G·t} sum to zero — and there
// Ĥ_G(patch) = nx ny Ĥ_G(cell), the visibility being periodic with the cell too. So the lobes of the
// far field are 2π/L_cell apart rather than 2π/L: the grating-order regime holds for windows with
// 2πσ/L_cell >= 4 (the paper's HEMISPHERES under sunlight, δc = 50 µm: 2πσ/L = 2.6 for the patch,
// 10.5 for its cell), and `exact` sums one cell's facets over the cell's orders (nx² ny² times less
// work than the patch's facets over the patch's orders).
//
// Found by mapping every facet (centroid and normal, FacetIndex) onto a facet of the patch
// translated by (Lx/n, 0) and by (0, Ly/n): the largest such n along each axis. Oblique lattices
// (a translation by (Lx/2, Ly/2) alone) are not looked for.
#pragma once
#include <cstdint>
#include <vector>

#include "geometry/microgeometry.h"

namespace mbsdf {

struct LatticeCell {
  int nx = 1, ny = 1;           // copies of the cell along x and y
  double sizeX = 0, sizeY = 0;  // the cell: Lx/nx, Ly/ny
  // One facet (triangle index) of each orbit of the translations, in index order: a cell's worth
  // of the surface. Every facet when nx = ny = 1.
  std::vector<uint32_t> facets;
  int copies() const { return nx * ny; }
};

// The patch itself (nx = ny = 1) for a patch that does not repeat, or whose facets the index cannot
// tell apart (FacetIndex::usable).
LatticeCell latticeCellOf(const Microgeometry& g);

}  // namespace mbsdf
