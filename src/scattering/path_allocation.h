// How many paths each incidence slice gets when the file stores each same-side pair of incidence
// bins once ([output] pairs = "once", [sampling] path_allocation = "equal-error").
//
// The stored value of a pair is the weighted mean of f(i → o), tallied by slice i's paths into exit
// bin o, and f(o → i), tallied by slice o's paths into bin i (reciprocalPairWeight). A path-traced
// tally's variance is about f / (N Ω⊥) of the bin it lands in, so the mean's variance is
// f / (N_i Ω⊥(o) + N_o Ω⊥(i)): a slice whose own bin is large (the middle rings of a theta-phi
// grid) gains from its partners' paths, one whose bin is small (the pole and horizon rings) hardly
// at all. With the same paths everywhere the small-bin slices set the error of the table, and the
// others are better than they need to be.
//
// The allocation gives each slice the paths that make its predicted L1 error per slice, for a table
// that is constant over the exit bins, the same as that of the slice that gains least:
//   L1(i) ∝ Σ_o √(Ω⊥(o) w_io) / √N_i,   w_io = N_i Ω⊥(o) / (N_i Ω⊥(o) + N_o Ω⊥(i))
// (w_io = 1 for an exit bin with no partner: the slice's own bin, a bin of the other hemisphere
// where the material transmits, an exit bin that is no incidence bin), solved by fixed-point
// iteration N_i ∝ (Σ_o √(Ω⊥(o) w_io))². Slices are grouped by their bin's projected solid angle, so
// that slices which map onto each other under the grid's symmetries get the same count. On the
// paper's 75 × 300 theta-phi grid the model reproduces the fold's measured gains per ring (pole
// 0.98, 45° 0.63, horizon 0.98 of the error unfolded, against 0.99, 0.66, 0.98 measured on
// HEMISPHERES' `multiple`), and the allocation's mean is 0.55 of the largest count.
#pragma once
#include <cstdint>
#include <vector>

#include "core/direction_grid.h"

namespace mbsdf {

// The share of the largest count each incidence gets (in (0, 1], the largest exactly 1), for
// incidences at sphere bins `incidenceBins` whose same-side pairs are stored once; `transmits`: the
// material lets light through, so the other hemisphere's exit bins (never paired) count too.
std::vector<double> equalErrorPathShares(const DirectionGrid& grid, const std::vector<int>& incidenceBins,
                                         bool transmits);

// The paths of each incidence: ⌈share × pathsPerSlice⌉ (at least 1).
std::vector<uint64_t> equalErrorSlicePaths(const DirectionGrid& grid, const std::vector<int>& incidenceBins,
                                           bool transmits, uint64_t pathsPerSlice);

}  // namespace mbsdf
