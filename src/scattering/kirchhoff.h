// The Kirchhoff integrand with ray-traced shadowing and masking (docs/physics.md §5; Falster et al. 2020, Eqs. 13–18,
// after Kajiya 1985, Sancer 1969, Caron et al. 2002):
//   I(ωo) = ∫ V(x,ωi) V(x,ωo) w(x) g(x,ωo) e^{i (k1 − k2)·x} dA
//   reflection:   g = m · [ (k1 − k2) r − (k1 + k2) ]
//   transmission: g = m · (kt + k2) t,  kt = k1 − (k1·m) m + (kt·m) m,
//                 kt·m = −sqrt(k2² − k1² + (k1·m)²)   (Falster et al. 2020, Eq. 15; negative radicand: t = 0)
// with k1 = −n_i k0 ωi, k2 = n_o k0 ωo, k0 = 2π/λ, m the facet normal facing the incident medium,
// and r, t the Fresnel amplitudes at the local angle |m·ωi|, s and p separately.
// Power per unit solid angle as a fraction of the incident power (docs/physics.md §5):
//   p(ωo) = (n_o/n_i) · (|I_s|² + |I_p|²)/2 / (16 π² W2 cos θi).
#pragma once
#include <complex>

#include "core/vecmath.h"
#include "optics/fresnel.h"

namespace mbsdf {

struct KirchhoffValue {
  Complex s, p;           // g_s e^{iφ}, g_p e^{iφ}
  double qx = 0, qy = 0;  // tangential part of k1 − k2 (for the coherence-window copies)
};

// x: point (µm), m: unit normal facing the incident medium, wi/wo: unit directions away from the
// surface, k0 = 2π/λ (1/µm), nI/nO: real indices of the incident and exit media, F: Fresnel
// amplitudes at |m·wi| from the incident medium into the other one.
KirchhoffValue kirchhoffIntegrand(const Vec3& x, const Vec3& m, const Vec3& wi, const Vec3& wo, double k0, double nI,
                                  double nO, const FresnelAmplitudes& F, bool transmission);

// 1 / (16 π² W2 cos θi) · n_o / n_i: turns |I|² (mean of s and p) into p(ωo).
inline double kirchhoffPowerScale(double w2, double cosTheta_i, double nI, double nO) {
  return nO / nI / (16.0 * kPi * kPi * w2 * cosTheta_i);
}

}  // namespace mbsdf
