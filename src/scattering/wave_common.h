// Pieces shared by the wave estimators: media and Fresnel per wavelength, visibility rays, the list
// of exit bins to compute. Internal to src/scattering.
#pragma once
#include <vector>

#include "core/vecmath.h"
#include "geometry/embree_scene.h"
#include "scattering/kirchhoff.h"
#include "scattering/wave_estimator.h"

namespace mbsdf::wave {

class Media {
 public:
  explicit Media(const WaveContext& ctx);
  // Real index of the medium on the incident side / the other side (for the power scale).
  double incident(int l, bool fromAbove) const { return fromAbove ? nUpper_ : lower_[l].real(); }
  double other(int l, bool fromAbove) const { return fromAbove ? lower_[l].real() : nUpper_; }
  // Fresnel amplitudes at the local cosine, from the incident medium into the other one.
  FresnelAmplitudes fresnel(int l, double cosLocal, bool fromAbove) const;
  bool conductor() const { return conductor_; }

 private:
  double nUpper_;
  std::vector<Complex> lower_;
  bool conductor_, perfect_;
};

// True when a ray from x (offset to the side of `side`) along d leaves the patch on the expected
// side (up when `up`), i.e. the point sees direction d.
bool escapes(const PeriodicScene& scene, const Vec3& x, const Vec3& side, const Vec3& d, unsigned prim, bool up);

// Exit bins with a nonzero projected solid angle on the reflection side (and the transmission side
// for dielectrics), for light arriving from above (fromAbove) or below.
std::vector<int> exitBins(const DirectionGrid& grid, bool fromAbove, bool dielectric);

}  // namespace mbsdf::wave
