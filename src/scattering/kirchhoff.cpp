#include "scattering/kirchhoff.h"

#include <cmath>

namespace mbsdf {

KirchhoffValue kirchhoffIntegrand(const Vec3& x, const Vec3& m, const Vec3& wi, const Vec3& wo, double k0, double nI,
                                  double nO, const FresnelAmplitudes& F, bool transmission) {
  const double k1n = nI * k0, k2n = nO * k0;
  const Vec3 k1 = wi * (-k1n), k2 = wo * k2n;
  const Vec3 q = k1 - k2;
  KirchhoffValue v;
  v.qx = q.x;
  v.qy = q.y;
  // Phase in double: |q·x| reaches 2 k0 |x| ~ 10^3 rad on a 100 µm patch.
  const Complex phase = std::polar(1.0, dot(q, x));
  if (!transmission) {
    const double mq = dot(m, q), mk = dot(m, k1 + k2);
    v.s = (F.rs * mq - mk) * phase;
    v.p = (F.rp * mq - mk) * phase;
  } else {
    const double k1m = dot(k1, m);
    const double rad = k2n * k2n - k1n * k1n + k1m * k1m;
    if (rad < 0) return v;  // total internal reflection: t = 0
    const double ktm = -std::sqrt(rad);
    // m·(kt + k2) = kt·m + k2·m (the tangential part of kt is orthogonal to m).
    const double g = ktm + dot(k2, m);
    v.s = F.ts * g * phase;
    v.p = F.tp * g * phase;
  }
  return v;
}

}  // namespace mbsdf
