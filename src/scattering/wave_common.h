// Pieces shared by the wave estimators: media and Fresnel per wavelength, visibility rays, the list
// of exit bins to compute. Internal to src/scattering.
#pragma once
#include <optional>
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
  // Whether transmission from this side is from the denser medium: the wave term then evaluates
  // it on the reverse path (integrandAt below).
  bool reverseTransmission(int l, bool fromAbove) const { return incident(l, fromAbove) > other(l, fromAbove); }

 private:
  double nUpper_;
  std::vector<Complex> lower_;
  bool conductor_, perfect_;
};

// The Kirchhoff integrand (kirchhoff.h) at x for light of wavelength index l from the side
// `fromAbove`, with the media's indices and Fresnel amplitudes.
//
// Transmission is always evaluated on the tangent plane of the optically thinner medium: light
// from the denser side (ωi in the medium of index n_i > n_o) takes the integrand of the reverse
// path, light from the thinner medium along ωo leaving along ωi. Its phase is the same
// (k1' − k2' = k1 − k2), and with kirchhoffPowerScale its |I|² is the power of the forward path
// that reciprocity requires, f(i → o)/n_o² = f(o → i)/n_i², so the model is reciprocal by
// construction. At stationary points (the facet refracts ωi into ωo) both tangent planes give the
// same amplitude, since n_o cos θ_o t_io = n_i cos θ_i t_oi for s and p (Born & Wolf §1.5.2): the
// geometric limit is unchanged. Elsewhere they differ, and the denser side's is the worse: it
// drops every facet steeper than the critical angle (t = 0 under total internal reflection), where
// the field the wave sends on is not zero. On a lattice of glass hemispheres (docs/validation.md)
// Meep's zero order transmits 0.075–0.077 either way; the thinner side's tangent plane gives 0.085
// both ways, the denser side's gave 0.22 from inside.
inline KirchhoffValue integrandAt(const Media& media, int l, const Vec3& x, const Vec3& m, const Vec3& wi,
                                  const Vec3& wo, double k0, bool fromAbove, bool transmission) {
  const double nI = media.incident(l, fromAbove);
  if (!transmission)
    return kirchhoffIntegrand(x, m, wi, wo, k0, nI, nI, media.fresnel(l, dot(m, wi), fromAbove), false);
  const double nO = media.other(l, fromAbove);
  if (!media.reverseTransmission(l, fromAbove))
    return kirchhoffIntegrand(x, m, wi, wo, k0, nI, nO, media.fresnel(l, dot(m, wi), fromAbove), true);
  // The reverse path's amplitude does not vanish as the facet turns edge-on to ωi (the forward
  // one does, with t): a facet that ωi only grazes within rounding — a vertical wall under
  // normal incidence — takes no light, or rounding would light one wall of a symmetric ridge and
  // not the other.
  if (dot(m, wi) < 1e-9) {
    KirchhoffValue none;
    const Vec3 q = wi * (-nI * k0) - wo * (nO * k0);
    none.qx = q.x;
    none.qy = q.y;
    return none;
  }
  return kirchhoffIntegrand(x, -m, wo, wi, k0, nO, nI, media.fresnel(l, -dot(m, wo), !fromAbove), true);
}

// True when a ray from x (offset to the side of `side`) along d leaves the patch on the expected
// side (up when `up`), i.e. the point sees direction d.
bool escapes(const PeriodicScene& scene, const Vec3& x, const Vec3& side, const Vec3& d, unsigned prim, bool up);

// V(x, ωo) of docs/physics.md §5 for a point x with normal m facing the incident medium.
//  Visible: front-facing on the side the light leaves by, and unblocked.
//  Blocked: front-facing but blocked by other geometry — the masked field of §6 (1 − V).
//  BackFacing: the facet itself faces away. V = 0, but it is not part of the masked field either:
//    the Kirchhoff integrand there is the forward "shadow-forming" field (for ωo = −ωi it does not
//    vanish), not light that was reflected and then blocked; counting it as masked would add about
//    the incident power again.
// Counts the ray it casts in *rays.
enum class ExitVisibility { BackFacing, Visible, Blocked };
inline ExitVisibility visibleExit(const PeriodicScene& scene, const Vec3& x, const Vec3& m, const Vec3& wo,
                                  unsigned prim, bool fromAbove, bool transmission, uint64_t* rays) {
  const double mo = dot(m, wo);
  if (transmission ? mo >= 0 : mo <= 0) return ExitVisibility::BackFacing;
  ++*rays;
  bool sees = transmission ? escapes(scene, x, -m, wo, prim, !fromAbove) : escapes(scene, x, m, wo, prim, fromAbove);
  return sees ? ExitVisibility::Visible : ExitVisibility::Blocked;
}

// Exit bins with a nonzero projected solid angle on the reflection side, and on the other side for
// dielectrics (transmission) or when the masked field is wanted (a conductor's facets can face
// below the horizon: their masked field points into the other hemisphere, where the geometric
// geo_masked tally of the same light lands too).
// Bins with mask[b] == 0 are left out (an empty mask keeps all).
std::vector<int> exitBins(const DirectionGrid& grid, bool fromAbove, bool dielectric, bool masked,
                          const std::vector<uint8_t>& mask = {});

// Whether any exit bin on the other side of the surface from the light is wanted (an empty mask
// wants every bin): the transmitted orders and directions can be skipped otherwise.
inline bool otherSideWanted(const DirectionGrid& grid, bool fromAbove, const std::vector<uint8_t>& mask) {
  if (mask.empty()) return true;
  for (int b = 0; b < grid.binCount(); ++b)
    if (grid.isUpper(b) != fromAbove && mask[size_t(b)]) return true;
  return false;
}

// Whether an exit direction is transmitted (the Kirchhoff transmission integrand) or reflected:
// only a dielectric transmits; a conductor's directions on the other side are reflected (masked).
inline bool isTransmission(bool conductor, bool fromAbove, const Vec3& wo) {
  return !conductor && (wo.z >= 0) != fromAbove;
}

// The incidence directions of a tile for the deterministic evaluators (`exact`, `fft`): one
// collimated beam (weight 1, high), or the nodes of an n x n (high) and an (n−1) x (n−1) (low)
// Gauss–Legendre rule over the incidence bin in its cosine-weighted sample space, n² >=
// `directions`. Σ weight over each rule is 1; |Q_high − Q_low| estimates the quadrature error.
struct IncidenceNode {
  Vec3 wi;
  double weight;
  bool high;
};
std::vector<IncidenceNode> incidenceRule(const DirectionGrid& grid, int incidenceBin,
                                         const std::optional<Vec3>& exactDirection, int directions);

}  // namespace mbsdf::wave
