// The `area` wave estimator (docs/physics.md §5, "Estimating ∫|I|² over a bin"):
//  - points x uniformly by surface area (pdf 1/A_surface) with a shadow ray towards ωi: bounded
//    weights, unlike footprint sampling whose 1/|m·ωi| weights have infinite variance on
//    silhouettes;
//  - |I(ωo)|² from N points by the unbiased pairwise form (|Σ X_j|² − Σ |X_j|²) / (N(N−1)),
//    so no Var/N floor;
//  - M = samples_per_bin / N exit directions per bin drawn uniformly in solid angle, each with its
//    own N points and its own incidence direction (cosine-weighted in the incidence bin): the bin
//    integral is Ω · mean_k p_k, the spread of the M independent p_k gives the standard error, and
//    the variance falls as 1 / samples_per_bin.
// Visibility rays are shared by all wavelengths.
#pragma once
#include "geometry/surface_sampler.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

class AreaWaveEstimator : public WaveEstimator {
 public:
  explicit AreaWaveEstimator(const WaveContext& ctx);
  std::string name() const override { return "area"; }
  using WaveEstimator::run;
  WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const override;

 private:
  WaveContext ctx_;
  SurfaceSampler sampler_;
};

}  // namespace mbsdf
