#include "microflake/chandrasekhar.h"

#include <cmath>

#include "core/quadrature.h"
#include "core/vecmath.h"

namespace mbsdf {

namespace {
// log(1 − a t cot t) without cancellation near t = 0, where t cot t = 1 − t²/3 − t⁴/45 − 2t⁶/945 − …
// (so the argument is (1 − a) + a(t²/3 + t⁴/45 + …), which vanishes at t = 0 when a = 1).
double logTerm(double t, double a) {
  if (t < 0.1) {
    const double t2 = t * t;
    const double S = 1.0 / 3 + t2 * (1.0 / 45 + t2 * (2.0 / 945 + t2 * (1.0 / 4725 + t2 * 2.0 / 93555)));
    // (1 − a) + a t² S; when a → 1 and t → 0 write it as 2 log t + log(a S) so that t² never
    // underflows into log(0).
    if ((1.0 - a) > 1e-17 * a * t2 * S) return std::log((1.0 - a) + a * t2 * S);
    return 2 * std::log(t) + std::log(a * S);
  }
  return std::log((1.0 - a) + a * (1.0 - t / std::tan(t)));
}
}  // namespace

double chandrasekharH(double u, double a) {
  if (u <= 0) return 1.0;
  if (a <= 0) return 1.0;
  a = std::min(a, 1.0);
  const double u2 = u * u;
  // The singular end is t = 0; `fromEnd` is the exact distance to the nearer end, so near t = 0
  // we evaluate at t = fromEnd instead of the rounded node.
  const double I = tanhSinh(
      [&](double t, double fromEnd) {
        if (t < 0.25 * kPi) t = fromEnd;
        const double s = std::sin(t), c = std::cos(t);
        return logTerm(t, a) / (u2 * s * s + c * c);
      },
      0.0, 0.5 * kPi, 1e-14);
  return std::exp(-u / kPi * I);
}

double isotropicMediumSingleBRDF(double mu_i, double mu_o, double a) {
  return a / (4 * kPi * (mu_i + mu_o));
}

double isotropicMediumBRDF(double mu_i, double mu_o, double a) {
  return a / (4 * kPi) * chandrasekharH(mu_i, a) * chandrasekharH(mu_o, a) / (mu_i + mu_o);
}

}  // namespace mbsdf
