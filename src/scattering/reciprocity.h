// Reciprocity (docs/physics.md §8) used to halve the work of the wave term on a full-sphere job:
//   reflection    f(ωi, ωo) = f(ωo, ωi).
// For bin-averaged incidence the bin-to-bin table obeys it exactly (both bins are averaged with the
// weight cos θ dω), so each unordered pair of incidence bins on the same side of the surface needs
// the wave estimator once. The pair is owned by one tile by a circulant rule within that side: with
// d = (rank(j) − rank(i)) mod N_side, tile i computes it when 2d < N_side (and i < j when
// 2d = N_side), so every tile computes ⌈N/2⌉ to ⌊N/2⌋ + 1 of its side's incidence columns and the
// tiles stay equally expensive. Exit bins that are not incidence bins (a conductor's lower
// hemisphere) and exit bins on the other side (transmission) are always the tile's own:
// transmission obeys f(i → o)/n_o² = f(o → i)/n_i², but the Kirchhoff estimate with light from
// inside a dielectric has heavy tails (its standard error is not reliable enough to trust a mirrored
// value; tests/scattering/reciprocity_test.cpp measures it), so it is computed both ways.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/direction_grid.h"

namespace mbsdf {

// The weight of f(i → o) in the mean of a reciprocal pair's two estimates, f(o → i) having the
// rest, where each was tallied by paths into its exit bin (o, and the bin of i): a tally's variance
// is about f / (N Ω⊥) of its bin, f the same both ways, so w = N_i Ω⊥(o) / (N_i Ω⊥(o) + N_o Ω⊥(i))
// gives the mean of least variance (pathsRatio = N_o / N_i, the partner slice's paths over slice
// i's: 1 unless the job allocates paths per slice, path_allocation.h). With independent estimates
// that mean's variance is w times the first's. BsdfFileWriter's fold of pairs stored once uses it,
// and `plan` to predict it. Equal halves where both bins are empty.
inline double reciprocalPairWeight(double exitOmega, double incidenceOmega, double pathsRatio = 1.0) {
  const double a = exitOmega, b = incidenceOmega * pathsRatio;
  return a + b > 0 ? a / (a + b) : 0.5;
}
// The same for two bins of a grid.
inline double reciprocalPairWeight(const DirectionGrid& grid, int exitBin, int incidenceBin, double pathsRatio = 1.0) {
  return reciprocalPairWeight(grid.projectedSolidAngle(exitBin), grid.projectedSolidAngle(incidenceBin), pathsRatio);
}

class ReciprocalPairs {
 public:
  // incidenceBins[i]: the sphere bin of incidence index i; nBins: bins of the full sphere, the first
  // binsPerHemisphere of them above the surface.
  ReciprocalPairs(std::vector<int> incidenceBins, int nBins, int binsPerHemisphere);

  int incidenceCount() const { return int(incidenceBins_.size()); }
  int incidenceBin(int i) const { return incidenceBins_[std::size_t(i)]; }
  // Incidence index whose bin is `bin`, or −1.
  int incidenceOf(int bin) const { return incidenceOfBin_[std::size_t(bin)]; }
  // Whether the tile of incidence index i computes f(i → exitBin) itself; otherwise the value is
  // f(j → bin(i)) of the tile j = incidenceOf(exitBin).
  bool computes(int i, int exitBin) const;
  // computes(i, b) for every exit bin b.
  std::vector<uint8_t> exitMask(int i) const;
  // Fraction of the (incidence, exit) pairs on the same side computed: Σ_side (N + N(N−1)/2) / Σ N².
  double computedFraction() const;

 private:
  bool upper(int bin) const { return bin < binsPerHemisphere_; }
  std::vector<int> incidenceBins_;
  std::vector<int> incidenceOfBin_;
  std::vector<int> rank_;      // rank of each incidence index among the incidence bins of its side
  int sideCount_[2] = {0, 0};  // incidence bins above, below
  int binsPerHemisphere_;
};

}  // namespace mbsdf
