#include "geometry/lattice_cell.h"

#include <algorithm>

#include "geometry/facet_index.h"

namespace mbsdf {

namespace {
// Translations by more than this many cells per axis are not looked for (a regularly triangulated
// flat patch repeats at every texel; beyond this the reduction gains nothing measurable).
constexpr int kMaxCopiesPerAxis = 4096;
}  // namespace

LatticeCell latticeCellOf(const Microgeometry& g) {
  LatticeCell cell;
  cell.sizeX = g.sizeX;
  cell.sizeY = g.sizeY;
  auto everyFacet = [&] {
    cell.facets.resize(g.triangles.size());
    for (size_t t = 0; t < cell.facets.size(); ++t) cell.facets[t] = uint32_t(t);
    return cell;
  };
  if (!g.periodic) return everyFacet();
  const FacetIndex index(g);
  if (!index.usable()) return everyFacet();
  const size_t F = index.size();
  auto invariantUnder = [&](const Vec3& shift) {
    for (size_t f = 0; f < F; ++f)
      if (!index.find(index.centroid(f) + shift, index.normal(f))) return false;
    return true;
  };
  // The translations by Lx/n form a group: invariance under Lx/n and Lx/m implies it under
  // Lx/lcm(n, m), so the largest invariant n is the cell (a free action: n divides the facet count).
  auto largest = [&](const Vec3& axis, double size) {
    int best = 1;
    for (int n = 2; n <= kMaxCopiesPerAxis && size_t(n) <= F; ++n)
      if (F % size_t(n) == 0 && invariantUnder(axis * (size / n))) best = n;
    return best;
  };
  const int nx = largest({1, 0, 0}, g.sizeX), ny = largest({0, 1, 0}, g.sizeY);
  if (nx * ny == 1 || F % size_t(nx * ny) != 0) return everyFacet();
  // One facet per orbit: the first (in index order) of each, its nx ny − 1 translates marked taken.
  std::vector<uint8_t> taken(F, 0);
  for (size_t f = 0; f < F; ++f) {
    if (taken[f]) continue;
    cell.facets.push_back(uint32_t(f));
    for (int i = 0; i < nx; ++i)
      for (int j = 0; j < ny; ++j) {
        if (!i && !j) continue;
        const auto t = index.find(index.centroid(f) + Vec3{i * g.sizeX / nx, j * g.sizeY / ny, 0}, index.normal(f));
        if (!t || taken[*t] || *t == f) {  // duplicate facets: not a free action, no reduction
          cell.facets.clear();
          return everyFacet();
        }
        taken[*t] = 1;
      }
  }
  if (cell.facets.size() * size_t(nx * ny) != F) {
    cell.facets.clear();
    return everyFacet();
  }
  cell.nx = nx;
  cell.ny = ny;
  cell.sizeX = g.sizeX / nx;
  cell.sizeY = g.sizeY / ny;
  return cell;
}

}  // namespace mbsdf
