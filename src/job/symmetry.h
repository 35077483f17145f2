// Azimuthal symmetry of an isotropic surface. Rotating an isotropic surface about z by any angle
// leaves its BSDF unchanged, so on a theta-phi grid (rings of nPhi equal bins at every θ, in both hemispheres) the
// slice of the incidence bin (t, p) is the slice of (t, 0) with every exit bin's φ index shifted by p:
//   f((t, p) → (t', p')) = f((t, 0) → (t', p' − p mod nPhi)).
// This is exact for bin-averaged values (a rotation by whole bins maps bins onto bins, with their
// solid angles) and for collimated beams through bin centres. A job with incidence = "all" then
// computes one tile per ring (the representative, φ index 0) and writes the ring's other slices as
// rotations of it: nPhi times fewer tiles. A surface that is only invariant under rotations by
// 2π/n about the patch centre (a square lattice: n = 4; any periodic patch rotated by 180°: n = 2)
// gets the same with rotations by multiples of nPhi/n bins: the representatives are the first
// nPhi/n azimuths of each ring, n times fewer tiles. A mirror y -> −y (φ -> −φ, bin p -> nPhi − 1 − p)
// halves that again: the slice of T(rep) is the representative's with exit bins mapped by T^-1.
// patchSymmetryOf() detects both for explicit geometry by mapping every facet onto a facet of the
// transformed patch.
#pragma once
#include <cstdint>
#include <vector>

#include "core/direction_grid.h"
#include "job/job.h"
#include "scattering/tile_result.h"

namespace mbsdf {

// Symmetries of a microgeometry about the patch centre, found by mapping every facet (centroid and
// normal, wrapped into the periodic cell) onto a facet within 1e-6 of the patch's side along each
// axis (or, for the mirror, onto the surface: symmetry.cpp): the largest
// n in {4, 2} with invariance under rotation by 2π/n (4 needs a square patch; 1 if neither), and
// invariance under the mirror y -> −y (φ -> −φ).
struct PatchSymmetry {
  int rotationOrder = 1;
  bool mirror = false;
};
PatchSymmetry patchSymmetryOf(const Microgeometry& g);

class AzimuthalSymmetry {
 public:
  // Requires job.symmetryReduced() (a theta-phi grid and incidence = "all").
  AzimuthalSymmetry(const Job& job, const DirectionGrid& grid);
  // The incidence index whose tile is computed for incidence index i, and the φ steps from it.
  int representative(int i) const { return rep_[size_t(i)]; }
  int shift(int i) const { return shift_[size_t(i)]; }
  // Incidence indices whose slices are rotations of representative r's (r included).
  const std::vector<int>& members(int r) const { return members_[size_t(r)]; }
  int representativeCount() const { return count_; }
  // The slice of incidence index `target` from its representative's tile (rotated, and mirrored
  // when the map from the representative includes the mirror).
  TileResult mappedSlice(const TileResult& representativeTile, int target, int targetBin) const;

 private:
  int nPhi_ = 1;
  std::vector<int> rep_, shift_;
  std::vector<uint8_t> mirror_;
  std::vector<std::vector<int>> members_;
  int count_ = 0;
};

}  // namespace mbsdf
