// ∫_T e^{i q·x} dA in closed form (triangle_fourier.h) against quadrature, over random, sliver and
// degenerate triangles and |q|·edge from 1e-8 to 1e4.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <complex>

#include "core/quadrature.h"
#include "core/rng.h"
#include "scattering/triangle_fourier.h"

using namespace mbsdf;
using LC = std::complex<long double>;

namespace {

// F(α, β) = ∫_0^1 du e^{iαu} ∫_0^{1−u} e^{iβv} dv: the inner integral in closed form (its Taylor
// series where β(1 − u) is small), the outer by composite 24-point Gauss–Legendre on panels of at
// most 1/8 of a period, in long double.
LC referenceUnitFourier(double alpha, double beta) {
  const long double a = alpha, b = beta;
  const QuadratureRule rule = gaussLegendre(24, 0.0, 1.0);
  const int panels = std::max(8, int(std::ceil((std::abs(alpha) + std::abs(beta)) / (2 * kPi) * 8)));
  LC sum = 0;
  for (int p = 0; p < panels; ++p)
    for (size_t k = 0; k < rule.x.size(); ++k) {
      const long double u = (p + (long double)rule.x[k]) / panels, w = (long double)rule.w[k] / panels;
      const long double len = 1 - u, t = b * len;
      LC inner;  // ∫_0^len e^{iβv} dv
      if (std::abs(t) < 1e-3L) {
        // len Σ (iβ len)^n / (n + 1)!
        LC term = len, s = 0;
        for (int n = 0; n < 12; ++n) {
          s += term;
          term *= LC(0, t) / (long double)(n + 2);
        }
        inner = s;
      } else {
        inner = (std::polar(1.0L, t) - 1.0L) / LC(0, b);
      }
      sum += w * std::polar(1.0L, a * u) * inner;
    }
  return sum;
}

// The same by a 2-D tensor Gauss rule on the triangle (Duffy map, no closed form at all), for
// moderate |q|.
LC duffyUnitFourier(double alpha, double beta) {
  const QuadratureRule r = gaussLegendre(48, 0.0, 1.0);
  LC sum = 0;
  for (size_t i = 0; i < r.x.size(); ++i)
    for (size_t j = 0; j < r.x.size(); ++j) {
      const long double s = r.x[i], t = r.x[j];
      const long double u = s * (1 - t), v = s * t;  // dudv = s ds dt
      sum += (long double)r.w[i] * r.w[j] * s * std::polar(1.0L, (long double)alpha * u + (long double)beta * v);
    }
  return sum;
}

double relError(std::complex<double> got, LC ref) {
  const long double d = std::abs(LC(got.real(), got.imag()) - ref);
  return double(d / std::abs(ref));
}

}  // namespace

TEST(TriangleFourier, UnitIntegralAgainstQuadrature) {
  Sampler rng(2024, 0, 0);
  double worst = 0;
  int cases = 0;
  for (double scale : {1e-8, 1e-5, 1e-2, 0.3, 1.0, 3.0, 30.0, 300.0, 1e4}) {
    for (int k = 0; k < (scale > 1000 ? 12 : 40); ++k) {  // fewer at 1e4: the reference costs ~25k panels
      double alpha = scale * (2 * rng.get1D() - 1), beta = scale * (2 * rng.get1D() - 1);
      if (k % 4 == 1) beta = alpha * (1 + 1e-9 * (2 * rng.get1D() - 1));  // α ≈ β
      if (k % 4 == 2) beta = 1e-10 * scale * (2 * rng.get1D() - 1);       // β ≈ 0
      if (k % 4 == 3) alpha = -beta + 1e-7 * (2 * rng.get1D() - 1);       // α ≈ −β
      const LC ref = referenceUnitFourier(alpha, beta);
      const double e = relError(triangleUnitFourier(alpha, beta), ref);
      EXPECT_LT(e, 1e-10) << "alpha " << alpha << " beta " << beta;
      worst = std::max(worst, e);
      ++cases;
      if (scale <= 30) {
        const double e2 = double(std::abs(duffyUnitFourier(alpha, beta) - ref) / std::abs(ref));
        EXPECT_LT(e2, 1e-10) << "reference check, alpha " << alpha << " beta " << beta;
      }
    }
  }
  EXPECT_NEAR(triangleUnitFourier(0, 0).real(), 0.5, 1e-16);
  RecordProperty("cases", cases);
  RecordProperty("worst_relative_error", ([&] {
                   char b[32];
                   std::snprintf(b, sizeof b, "%.3g", worst);
                   return std::string(b);
                 })());
}

// Whole triangles: random ones, slivers (a vertex 1e-9 off the opposite edge) and degenerate ones
// (collinear: 0), with |q|·edge from 1e-8 to 1e4; the result is 2A e^{iq·a} F(q·e1, q·e2), so the
// checks are the area, the phase origin and the independence of the vertex order.
TEST(TriangleFourier, TrianglesAnyOrderSliversDegenerate) {
  Sampler rng(7, 0, 0);
  auto point = [&]() { return Vec3{2 * rng.get1D() - 1, 2 * rng.get1D() - 1, 2 * rng.get1D() - 1}; };
  for (double qe : {1e-8, 1e-3, 1.0, 50.0, 1e4}) {
    for (int k = 0; k < (qe > 1000 ? 9 : 30); ++k) {
      Vec3 a = point(), b = point(), c = point();
      if (k % 3 == 1) c = (a + b) * 0.5 + normalize(point()) * 1e-9;  // sliver
      const double edge = std::max({length(b - a), length(c - b), length(a - c)});
      const Vec3 q = normalize(point()) * (qe / edge);
      const std::complex<double> abc = triangleFourier(a, b, c, q), bca = triangleFourier(b, c, a, q),
                                 acb = triangleFourier(a, c, b, q);
      // The vertex order changes the area's rounding, 1e-16 edge² (relative 1e-7 for a sliver of
      // height 1e-9): compared to that or 1e-10 relative.
      const double tol = 1e-10 * std::abs(abc) + 1e-15 * edge * edge;
      EXPECT_LT(std::abs(abc - bca), tol) << qe;
      EXPECT_LT(std::abs(abc - acb), tol) << qe;
      // Against the reference F with the same parametrisation.
      const Vec3 e1 = b - a, e2 = c - a;
      const LC ref = LC(length(cross(e1, e2))) * std::polar(1.0L, (long double)dot(q, a)) *
                     referenceUnitFourier(dot(q, e1), dot(q, e2));
      EXPECT_LT(relError(abc, ref), 1e-10) << "qe " << qe << " sliver " << (k % 3 == 1);
      // Small |q|: the integral tends to the area.
      if (qe <= 1e-3) {
        EXPECT_NEAR(std::abs(abc), 0.5 * length(cross(e1, e2)), 1e-3 * 0.5 * length(cross(e1, e2)) + 1e-300);
      }
    }
  }
  const Vec3 a{0, 0, 0}, b{1, 1, 1};
  EXPECT_EQ(triangleFourier(a, b, b * 2.0, Vec3{3, 1, 2}), std::complex<double>(0.0));  // collinear
}
