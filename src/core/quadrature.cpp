#include "core/quadrature.h"

#include <cmath>
#include <limits>

#include "core/vecmath.h"

namespace mbsdf {

QuadratureRule gaussLegendre(int n, double a, double b) {
  QuadratureRule q;
  q.x.resize(n);
  q.w.resize(n);
  const double xm = 0.5 * (b + a), xl = 0.5 * (b - a);
  for (int i = 0; i < (n + 1) / 2; ++i) {
    double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), pp = 0;
    for (int it = 0; it < 100; ++it) {
      double p1 = 1, p2 = 0;
      for (int j = 0; j < n; ++j) {
        const double p3 = p2;
        p2 = p1;
        p1 = ((2.0 * j + 1.0) * z * p2 - j * p3) / (j + 1);
      }
      pp = n * (z * p1 - p2) / (z * z - 1.0);
      const double z1 = z;
      z = z1 - p1 / pp;
      if (std::abs(z - z1) < 1e-15) break;
    }
    q.x[i] = xm - xl * z;
    q.x[n - 1 - i] = xm + xl * z;
    q.w[i] = q.w[n - 1 - i] = 2.0 * xl / ((1.0 - z * z) * pp * pp);
  }
  return q;
}

double tanhSinh(const std::function<double(double, double)>& f, double a, double b, double relTol,
                double* errorEstimate) {
  // x = c + h·tanh(π/2 · sinh t), weights π/2 · cosh t / cosh²(π/2 · sinh t).
  const double half = 0.5 * (b - a);
  auto term = [&](double t) {
    const double s = 0.5 * kPi * std::sinh(t), ch = std::cosh(s);
    const double w = 0.5 * kPi * std::cosh(t) / (ch * ch);
    // Distance from the nearer endpoint, computed without cancellation: 1 − tanh(s) = e^{−s}/cosh s.
    const double fromEnd = half * std::exp(-std::abs(s)) / ch;
    if (!(fromEnd > 0) || w == 0) return 0.0;
    const double x = t >= 0 ? b - fromEnd : a + fromEnd;
    return w * (f(x, fromEnd) + 0.0);
  };
  const double tMax = 6.5;  // weights below 1e-300 beyond this
  double h = 0.5, sum = term(0.0);
  for (double t = h; t <= tMax; t += h) sum += term(t) + term(-t);
  double prev = sum * h * half, result = prev, err = std::numeric_limits<double>::infinity();
  for (int level = 1; level <= 12; ++level) {
    h *= 0.5;
    for (double t = h; t <= tMax; t += 2 * h) sum += term(t) + term(-t);
    result = sum * h * half;
    err = std::abs(result - prev);
    if (level >= 3 && err <= relTol * std::abs(result)) break;
    prev = result;
  }
  if (errorEstimate) *errorEstimate = err;
  return result;
}

QuadratureRule compositeGaussLegendre(int n, int cells) {
  const QuadratureRule r = gaussLegendre(n, 0.0, 1.0);
  QuadratureRule q;
  for (int c = 0; c < cells; ++c)
    for (size_t i = 0; i < r.x.size(); ++i) {
      q.x.push_back((c + r.x[i]) / cells);
      q.w.push_back(r.w[i] / cells);
    }
  return q;
}

}  // namespace mbsdf
