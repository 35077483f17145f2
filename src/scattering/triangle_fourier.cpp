#include "scattering/triangle_fourier.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace mbsdf {
namespace {

using C = std::complex<double>;

// sin(x)/x, with its series below 1e-4 (relative error < 1e-17 there).
double sinc(double x) {
  const double x2 = x * x;
  if (std::abs(x) < 1e-4) return 1 - x2 / 6 * (1 - x2 / 20);
  return std::sin(x) / x;
}

// e^{ix}[a, b] = (e^{ib} − e^{ia}) / (b − a) = i e^{i(a+b)/2} sinc((b − a)/2).
C firstDifference(double a, double b) {
  const double m = 0.5 * (a + b);
  return C(0, 1) * std::polar(1.0, m) * sinc(0.5 * (b - a));
}

// e^{ix}[x0, x1, x2] for nodes within a spread < ~1.5 of their mean: the Taylor series (see header).
C secondDifferenceSeries(const std::array<double, 3>& x) {
  const double c = (x[0] + x[1] + x[2]) / 3;
  const double d0 = x[0] - c, d1 = x[1] - c, d2 = x[2] - c;
  // h_m(d0, d1, d2) by the recurrences h_m(d0) = d0^m, h_m(d0, d1) = d1 h_{m−1}(d0, d1) + d0^m,
  // h_m(d0, d1, d2) = d2 h_{m−1}(d0, d1, d2) + h_m(d0, d1).
  double p0 = 1, h01 = 1, h012 = 1;  // m = 0
  C sum = 0, ik = C(-1, 0);          // i^2
  double fact = 2;                   // 2!
  for (int m = 0; m < 40; ++m) {
    if (m > 0) {
      p0 *= d0;
      h01 = d1 * h01 + p0;
      h012 = d2 * h012 + h01;
    }
    const C term = ik * (h012 / fact);
    sum += term;
    // |term| is |h012| / m! (i^k is a unit), and |sum| <= |Re| + |Im|: the modulus of the sum, a
    // hypot, is taken only when the term may have become small enough.
    if (m > 4) {
      const double t = std::abs(h012 / fact);
      if (t < 2e-18 * (std::abs(sum.real()) + std::abs(sum.imag())) && t < 1e-18 * std::abs(sum)) break;
    }
    ik *= C(0, 1);
    fact *= double(m + 3);
  }
  return std::polar(1.0, c) * sum;
}

}  // namespace

C triangleUnitFourier(double alpha, double beta) {
  std::array<double, 3> x{0.0, alpha, beta};
  std::sort(x.begin(), x.end());
  const double spread = x[2] - x[0];
  if (spread < 1.0) return -secondDifferenceSeries(x);
  return -(firstDifference(x[1], x[2]) - firstDifference(x[0], x[1])) / spread;
}

C triangleFourier(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& q) {
  const Vec3 e1 = b - a, e2 = c - a;
  const double twiceArea = length(cross(e1, e2));
  if (twiceArea == 0) return 0;
  return twiceArea * std::polar(1.0, dot(q, a)) * triangleUnitFourier(dot(q, e1), dot(q, e2));
}

}  // namespace mbsdf
