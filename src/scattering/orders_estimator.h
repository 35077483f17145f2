// The `orders` wave estimator, for a periodic patch under a coherence window much wider than the
// patch (σ ≫ L / 2π): the far field is then a set of narrow lobes around the grating orders, and
// each lobe is integrated exactly instead of being hit by random exit directions.
//
// Derivation (docs/physics.md §5 with the copy sum written by Poisson summation):
//   Σ_s w(x + s) e^{i q·s} = (1/A_fp) Σ_G ŵ(q_xy − G) e^{i (G − q_xy)·x_xy},  ŵ(k) = 2πσ² e^{−σ²|k|²/2},
// G = 2π (a/Lx, b/Ly). Near order G, I(q) ≈ ŵ(q_xy − G) Ĥ_G / A_fp with the order amplitude
//   Ĥ_G = ∫_patch V(x,ωi) V(x,ω_G) g(x, ω_G) e^{i (G·x_xy + q_z(ω_G) z)} dA
// evaluated at the order direction ω_G,xy = −(G + n_i k0 ωi,xy)/(n_o k0). Integrating |ŵ|² over the
// lobe (∫|ŵ|² d²q = 4π³σ², dω = d²q / (n_o² k0² cos θ_G)) and normalising by 16π² W2 cos θi with
// W2 = πσ² gives the power of order G as a fraction of the incident power:
//   P_G = (|Ĥ_G,s|² + |Ĥ_G,p|²)/2 / (4 n_i n_o k0² A_fp² cos θi cos θ_G)
// (a flat mirror at normal incidence: Ĥ_0 = −2 k0 A_fp, P_0 = 1). The lobe is a Gaussian of standard
// deviation 1/(√2 σ n_o k0) in (x, y) of ωo; its power is shared among the bins it covers.
// |Ĥ_G|² is estimated from N points sampled uniformly by area, in 8 independent groups each
// stratified over the surface (Morton order), by the unbiased cross-group form
// (|Σ_g S_g|² − Σ_g |S_g|²) / (n_g² G (G − 1)), with a delete-a-group jackknife standard error. Points and shadow rays
// are shared by all orders and wavelengths; each (point, order direction) needs one masking ray.
//
// `exact` (its facet sum in exact_amplitude.h): the same lobes, but Ĥ_G summed over the facets
// with the phase integrated in closed form (triangle_fourier.h): over a flat facet g is constant,
// so Ĥ_G = Σ_T V_T g_T ∫_T e^{i q·x} dA. Visibility (shadowing towards ωi, masking towards ω_G) is
// tested at the centroid and three inset points of each facet; a facet whose points disagree is
// split into four, down to 4^3 pieces, whose centroid then decides. With a collimated beam the
// result has no sampling noise (standard error 0); with bin-averaged incidence the incidence bin is
// integrated by an n x n Gauss–Legendre rule in its cosine-weighted sample space (n² >=
// wave_incidence_directions) and the standard error is estimated as |Q_n − Q_{n−1}| per bin.
//
// A patch made of nx x ny copies of a smaller cell (geometry/lattice_cell.h) has Ĥ_G = 0 off the
// cell's lattice and nx ny times the cell's sum on it: only the cell's orders are enumerated (by
// every variant), and `exact` sums one cell's facets.
//
// `fft` on a heightfield (heightfield_spectrum.h): the same lobes and incidence rule as `exact`,
// with Ĥ_G of every order from FFTs of the facet fields (one-point rule per facet), and the facets
// masked from (or facing away from) an order direction below the steepest slope subtracted one by
// one (the sparse masking correction; their sum is the masked field for `lost`).
#pragma once
#include <memory>
#include <mutex>

#include "geometry/lattice_cell.h"
#include "geometry/surface_sampler.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

class HeightfieldSpectrum;
class VisibilityTable;
enum class OrderAmplitudes { MonteCarlo, Exact, Fourier };

class OrdersWaveEstimator : public WaveEstimator {
 public:
  // Fourier needs a heightfield (heightGridOf); throws std::invalid_argument otherwise.
  explicit OrdersWaveEstimator(const WaveContext& ctx, OrderAmplitudes amplitudes = OrderAmplitudes::MonteCarlo);
  ~OrdersWaveEstimator() override;
  std::string name() const override;
  std::string notes() const override;
  bool deterministic() const override { return amplitudes_ != OrderAmplitudes::MonteCarlo; }
  double memoryBytes() const override;
  double setupSeconds() const override;
  using WaveEstimator::run;
  WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const override;

 private:
  WaveContext ctx_;
  SurfaceSampler sampler_;
  OrderAmplitudes amplitudes_;
  LatticeCell cell_;  // the cell the patch repeats: orders on its lattice only
  SlopeBound slope_;  // directions a heightfield cannot shadow or mask (no ray cast)
  std::unique_ptr<HeightfieldSpectrum> spectrum_;
  // exact with settings.visibilityTable > 0: built on first use, then shared by every tile.
  const VisibilityTable* visibilityTable() const;
  mutable std::once_flag tableOnce_;
  mutable std::unique_ptr<VisibilityTable> table_;
};

}  // namespace mbsdf
