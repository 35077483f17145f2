#include "optics/fresnel.h"

#include <algorithm>
#include <cmath>

namespace mbsdf {

FresnelAmplitudes fresnelAmplitudes(double cosTheta_i, double n1, Complex n2) {
  cosTheta_i = std::clamp(cosTheta_i, 0.0, 1.0);
  double sin2 = std::max(0.0, 1.0 - cosTheta_i * cosTheta_i);
  // w = n2 cos θt, with Im(w) >= 0 (decaying or outgoing transmitted wave).
  Complex w = std::sqrt(n2 * n2 - Complex(n1 * n1 * sin2, 0.0));
  if (w.imag() < 0 || (w.imag() == 0 && w.real() < 0)) w = -w;
  FresnelAmplitudes f;
  f.cosTheta_t = w / n2;
  f.totalInternalReflection = n2.imag() == 0 && n1 * n1 * sin2 >= n2.real() * n2.real();
  Complex n1c(n1, 0), ci(cosTheta_i, 0);
  Complex ds = n1c * ci + w;
  Complex dp = n2 * n2 * ci + n1c * w;  // n2 cos θi + n1 cos θt, multiplied through by n2
  if (std::abs(ds) == 0) {              // grazing incidence onto an index-matched medium: limit r = -1
    f.rs = -1;
    f.rp = -1;
    f.ts = 0;
    f.tp = 0;
    return f;
  }
  f.rs = (n1c * ci - w) / ds;
  f.rp = (n2 * n2 * ci - n1c * w) / dp;
  f.ts = 2.0 * n1c * ci / ds;
  f.tp = 2.0 * n1c * n2 * ci / dp;
  return f;
}

double fresnelReflectance(double cosTheta_i, double n1, Complex n2) {
  FresnelAmplitudes f = fresnelAmplitudes(cosTheta_i, n1, n2);
  return std::clamp(0.5 * (std::norm(f.rs) + std::norm(f.rp)), 0.0, 1.0);
}

FresnelAmplitudes perfectConductorAmplitudes() {
  FresnelAmplitudes f;
  f.rs = -1;
  f.rp = 1;
  f.ts = 0;
  f.tp = 0;
  f.cosTheta_t = 0;
  return f;
}

}  // namespace mbsdf
