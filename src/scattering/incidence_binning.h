// An order's power binned over an incidence bin (`exact`, `fft` and `orders` with bin-averaged
// incidence), and the Gaussian lobe helpers the binning shares with the collimated case.
#pragma once
#include <cstdint>
#include <vector>

#include "core/direction_grid.h"
#include "core/vecmath.h"
#include "scattering/wave_common.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

// One propagating grating order G of one wavelength.
struct Order {
  long a, b;   // G = 2π (a/Lx, b/Ly)
  bool below;  // a conductor's reflected order below the horizon (masked field only)
  int lambda;
  Vec3 wo;  // order direction
  bool transmission;
  double scale;  // Q_G / |Ĥ_G|² (mean of s and p), Q_G = P_G cos θ_G (lobeBins applies 1/cos θ_G)
  double sd;     // lobe standard deviation in (x, y) of ωo
};

// exact/fft over an incidence bin: one order's Q = P_G · cos θ_G (the power without its 1/cos θ_G,
// which is singular where the order grazes the horizon; lobeSecant restores it, finite, at each
// sub-direction) at every node of the incidence rule, visible and masked, and whether the order
// propagates there.
struct NodePowers {
  Order ord;
  std::vector<double> q;         // [node * 2 + msk], the high rule's n² nodes first
  std::vector<double> var;       // the Monte Carlo variance of q (orders), else empty
  std::vector<uint8_t> present;  // [node]
};

// The K-point stratified pattern of a unit normal: Φ⁻¹((i + ½)/K), K a power of two from
// kMinSubdirections / 2 (the coarse binning's) to kMaxSubdirections, each made once.
const std::vector<double>& lobeNodes(int K);
// The factor of the lobe's fractions inside the disk: 1/cos θ_G, or the finite mean near the horizon.
double lobeSecant(double cx, double cy, double sd);

// exact and fft over an incidence bin. Each order's power P_G(ωi) is smooth across the bin, but
// which exit bin its direction ωo(ωi) = −(G + n_i k0 ωi,xy)/(n_o k0) (+ its lobe) falls in jumps:
// a Gauss–Legendre rule over the bin converges slowly there and not monotonically (Al grating,
// Λ = 2 µm, 39.4°: rule orders 2…6 gave L1 errors of 0.17, 0.060, 0.073, 0.062, 0.047 per slice).
// So the powers computed at the n × n nodes (the costly facet sums) are interpolated (Lagrange in
// the bin's cosine-weighted (u, v) square) to M × M sub-directions ([sampling] wave_subdirections,
// 16 by default), and at each the lobe's share of every bin is integrated (lobe_shares.h): the
// jumps are smoothed by the lobe itself, so a midpoint rule over the sub-directions converges fast.
// Where the shares cannot be integrated (a disk grid's rim), the sub-direction takes one point of
// the lobe's M × M stratified pattern, paired by a fixed scrambled permutation (both marginals
// exact). Error per bin: the interpolation's, |B(P_n) − B(P_{n−1})| from the (n − 1) × (n − 1)
// companion nodes, plus the binning's, |B_M − B_{M/2}| with M/2 × M/2 sub-directions (both
// estimates of the coarser, on the safe side).
// WaveExact.IncidenceBinAverageMatchesDenseCollimatedMean: that grating at 5°, 39.4°, 65° within
// 0.002–0.007 (L1 per slice) of the mean of 24 × 24 collimated tables over the bin, reported
// 0.010–0.044. The paper's HEMISPHERES at 75 × 300 bins, θi = 30°, 8 wavelengths: M = 16 is
// 0.04–0.08 % (L1) from M = 64 and M = 32 0.01 %; sampling the lobe at one point per sub-direction
// instead, as before, left 6–8 % at M = 32 and about 1 % at M = 256 (docs/accuracy.md).
void binOverIncidenceBin(const WaveContext& ctx, const DirectionGrid& grid, int incidenceBin, bool fromAbove,
                         const wave::Media& media, const std::vector<NodePowers>& nodePower, bool masked,
                         WaveTileResult* r);

}  // namespace mbsdf
