// The `paper` wave estimator: Falster et al. 2020, Appendix A, kept as the baseline that the others
// are measured against. One incidence direction per slice; per progressive pass and exit bin, one
// point found by tracing a ray from a footprint point (uniform, or Gaussian-distributed under the
// coherence window: "the projected visible area A0 modulated by the coherence area Gaussian") and
// one random ωo in the bin; the complex values are accumulated per bin and the bin power is
// |mean|². Its weights carry 1/|m·ωi| (unbounded on silhouettes) and |mean|² is biased by Var/P,
// which shows as a diffuse floor. The reported error is that bias estimate, Var(X)/P.
#pragma once
#include "scattering/wave_estimator.h"

namespace mbsdf {

class PaperWaveEstimator : public WaveEstimator {
 public:
  explicit PaperWaveEstimator(const WaveContext& ctx) : ctx_(ctx) {}
  std::string name() const override { return "paper"; }
  using WaveEstimator::run;
  WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const override;

 private:
  WaveContext ctx_;
};

}  // namespace mbsdf
