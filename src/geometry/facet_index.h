// Facets of a microgeometry looked up by centroid and normal: the test behind the patch's symmetries
// (job/symmetry.h: is the rotated or mirrored facet a facet of the patch?) and its lattice cell
// (lattice_cell.h: is the translated facet one?).
//
// Centroids are wrapped into the periodic cell and match within 1e-6 of the patch size along each
// axis (a long thin patch needs the tolerance of its short side: with the long side's, a mirrored
// centroid of a 5000 x 1 µm grating "matched" another facet a third of a row away); normals within
// 1e-9 in their dot product. Facets are hashed by the cell of 2 tol that holds the centroid, so a
// lookup costs O(1) for any patch shape (a grid of cells of 1e-3 L held thousands of facets each on
// a 5000 x 1 µm grating of 1e7 facets: the symmetry check took 227 s, then 11 s).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "geometry/microgeometry.h"

namespace mbsdf {

class FacetIndex {
 public:
  explicit FacetIndex(const Microgeometry& g);
  // False for a mesh this index cannot tell apart: empty, 2^32 facets, centroids beyond 4e3 patch
  // sizes of the centre, or more than 64 facets whose centroids coincide within 2e-6 L.
  bool usable() const { return usable_; }
  size_t size() const { return facets_.size(); }
  const Vec3& centroid(size_t f) const { return facets_[f].first; }  // wrapped into the cell
  const Vec3& normal(size_t f) const { return facets_[f].second; }   // unit
  const std::vector<std::pair<Vec3, Vec3>>& facets() const { return facets_; }
  // A coordinate wrapped into the periodic cell [−size/2, size/2) (unchanged for a patch that does
  // not repeat).
  double wrap(double v, double size) const { return periodic_ && size > 0 ? v - size * std::floor(v / size + 0.5) : v; }
  // The facet at centroid c (any copy of the cell) with unit normal n, if there is one.
  std::optional<uint32_t> find(const Vec3& c, const Vec3& n) const;

 private:
  using Key = std::array<int32_t, 3>;
  Key keyOf(const Vec3& c) const;
  size_t slotOf(const Key& k) const;
  bool indexable(const Vec3& c) const;
  std::optional<uint32_t> findNear(const Vec3& c, const Vec3& n) const;

  double sizeX_, sizeY_;
  bool periodic_, usable_ = false;
  Vec3 tol_, cell_;
  std::vector<std::pair<Vec3, Vec3>> facets_;
  std::vector<uint32_t> table_;  // open addressing, linear probing, load <= 1/2
  size_t mask_ = 0;
};

}  // namespace mbsdf
