// The `area` wave estimator (docs/physics.md §5, "Estimating ∫|I|² over a bin"):
//  - points x uniformly by surface area (pdf 1/A_surface) with a shadow ray towards ωi: bounded
//    weights, unlike footprint sampling whose 1/|m·ωi| weights have infinite variance on
//    silhouettes;
//  - |I(ωo)|² from N points by the unbiased pairwise form (|Σ X_j|² − Σ |X_j|²) / (N(N−1)),
//    so no Var/N floor;
//  - M = samples_per_bin / N exit directions per bin, each with its own N points. Under a collimated
//    beam they are drawn from the uniform density and the grating orders' lobes (multi-sample MIS);
//    over an incidence bin each is a pair: ωo cosine-weighted in the exit bin, ωi cosine-weighted or
//    around the incidence directions whose orders reach ωo, each order weighted by its power from a
//    per-tile pilot (area_estimator.cpp), with four times the pairs and a quarter of the points. The
//    bin integral is mean_k p_k / pdf_k, the spread of the M independent terms within their strata
//    gives the standard error, and the variance falls as 1 / samples_per_bin. N shrinks (to a
//    quarter) where the control variate below leaves little point noise, and M grows to give each
//    lobe two directions;
// - the mean plane's field as a control variate (mean_plane_control.h): a flat surface's
//   Kirchhoff integral comes back exact, a shallow one's with little noise.
// Visibility rays are shared by all wavelengths.
#pragma once
#include "core/rng.h"
#include "geometry/surface_sampler.h"
#include "scattering/mean_plane_control.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace wave {
class Media;
}

// Weights of the grating orders G = 2π(a/Lx, b/Ly) that carry light from an incidence bin's centre
// into each exit hemisphere (AreaWaveEstimator's pilot). Empty: every order weighs 1.
struct GratingOrderWeights {
  long aMin = 0, bMin = 0, na = 0, nb = 0;
  std::vector<double> byHemisphere[2];  // [0] exit above the surface, [1] below; na × nb each
  double of(int hemisphere, long a, long b) const {
    const std::vector<double>& w = byHemisphere[hemisphere];
    const long i = a - aMin, j = b - bMin;
    if (w.empty() || i < 0 || j < 0 || i >= na || j >= nb) return 1.0;
    return w[size_t(i * nb + j)];
  }
};

class AreaWaveEstimator : public WaveEstimator {
 public:
  explicit AreaWaveEstimator(const WaveContext& ctx);
  std::string name() const override { return "area"; }
  using WaveEstimator::run;
  WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const override;

 private:
  struct Direction {
    Vec3 wi, wo;
    bool transmission;
    double pdf;
  };
  // Per (direction k, wavelength): p_k / pdf_k, and its variance over the points given the
  // direction (jackknife of the pairwise power).
  struct Powers {
    std::vector<double> p, within;
  };
  void directionPowers(const Direction& d, int k, int nL, int N, bool masked, const wave::Media& media, bool fromAbove,
                       Sampler& s, Powers& pv, Powers& pm, uint64_t* rays) const;
  GratingOrderWeights orderWeights(int tile, int incidenceBin, const wave::Media& media, bool fromAbove,
                                   uint64_t budget, uint64_t* rays) const;
  int pointsFor(int b, int N0, const wave::Media& media, bool fromAbove, const std::optional<Vec3>& exactDirection,
                int incidenceBin) const;
  WaveContext ctx_;
  SurfaceSampler sampler_;
  MeanPlaneControl control_;
};

}  // namespace mbsdf
