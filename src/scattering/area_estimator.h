// The `area` wave estimator (docs/physics.md §5, "Estimating ∫|I|² over a bin"):
//  - points x uniformly by surface area (pdf 1/A_surface) with a shadow ray towards ωi: bounded
//    weights, unlike footprint sampling whose 1/|m·ωi| weights have infinite variance on
//    silhouettes;
//  - |I(ωo)|² from N points by the unbiased pairwise form (|Σ X_j|² − Σ |X_j|²) / (N(N−1)),
//    so no Var/N floor;
//  - M = samples_per_bin / N exit directions per bin, each with its own N points and its own
//    incidence direction (cosine-weighted in the incidence bin), drawn from the uniform density and
//    the grating orders' lobes of that incidence (area_estimator.cpp): the bin integral is
//    mean_k p_k / pdf_k, the spread of the M independent terms gives the standard error, and the
//    variance falls as 1 / samples_per_bin. N shrinks (to a quarter) where the control variate
//    below leaves little point noise, and M grows to give each lobe two directions;
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
  int pointsFor(int b, int N0, const wave::Media& media, bool fromAbove, const std::optional<Vec3>& exactDirection,
                int incidenceBin) const;
  WaveContext ctx_;
  SurfaceSampler sampler_;
  MeanPlaneControl control_;
};

}  // namespace mbsdf
