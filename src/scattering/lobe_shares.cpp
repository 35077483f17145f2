#include "scattering/lobe_shares.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <variant>

#include "core/overloaded.h"
#include "core/quadrature.h"
#include "core/vecmath.h"

namespace mbsdf {
namespace {

// Φ(z), the standard normal distribution function.
double normalCdf(double z) {
  return 0.5 * std::erfc(-z * (1 / std::numbers::sqrt2));
}

// Shares of the intervals [edge(k), edge(k + 1)), k = k0 … k1, of a unit normal variable z, given
// below(k) = P(z < edge(k)): the first interval takes everything below it and the last everything
// above, unless `cut` (the last interval ends at a true boundary, below(k1 + 1)).
template <typename Below>
void intervalShares(long k0, long k1, const Below& below, bool cut, std::vector<double>* share) {
  share->clear();
  double lo = 0;
  for (long k = k0; k <= k1; ++k) {
    const double hi = k < k1 || cut ? below(k + 1) : 1.0;
    share->push_back(std::max(0.0, hi - lo));
    lo = hi;
  }
}

// Within one ring (the window clear of the pole by 8 sd and of the horizon), each ray's integral
// is the whole ray's, and a sector's share is that of the wedge between its spokes: the share
// clockwise of the spoke at φ_e is Φ(rc sin(φ_e − φc) / sd), the spot's distance from the spoke's
// line over sd, up to the part of the line beyond the origin, e^{−rc²/2sd²} < 1e-13 away.
template <typename BinOf>
void oneRingShares(double rc, double phic, double sd, double dphi, long p0, long p1, const BinOf& binOf,
                   std::vector<std::pair<int, double>>* out) {
  double below = 0;
  for (long p = p0; p <= p1; ++p) {
    const double above = p < p1 ? normalCdf(rc * std::sin(double(p + 1) * dphi - phic) / sd) : 1.0;
    if (above > below) out->push_back({binOf(p), above - below});
    below = above;
  }
}

// The spot's integral over the part [a, b] of a sector (angles) and each ring between the radii
// edge[k] and edge[k + 1], added to value[k]. Along the ray at angle φ, with ψ = φ − φc, the density
// is e^{−rc² sin²ψ / 2sd²} e^{−(r − μ)² / 2sd²} / (2π sd²) with μ = rc cos ψ, so the integral r dr
// over a ring [R0, R1] is closed:
//   sd² (e^{−a²/2} − e^{−b²/2}) + μ sd √(2π) (Φ(b) − Φ(a)),  a = (R0 − μ)/sd, b = (R1 − μ)/sd.
// What remains is a smooth integral over φ. Away from the pole, u = rc sin ψ / sd makes the density
// across the rays exactly e^{−u²/2}, and what multiplies it, (sd/μ) × the ring integrals, varies
// slowly (μ = √(rc² − sd² u²)): each piece at most three units of u wide takes three nodes whose
// weights integrate e^{−u²/2} times any quadratic exactly (from its moments in closed form). Near
// the pole, five-point Gauss–Legendre rules in ψ on cells three angular widths (sd / rc) wide.
// Within 1e-5 of the spot (tests/scattering/lobe_shares_test.cpp).
void sectorRingIntegrals(double rc, double phic, double sd, double a, double b, const std::vector<double>& edge,
                         std::vector<double>* value) {
  const size_t rings = value->size();
  const double norm = 1 / (2 * kPi * sd * sd), root2pi = std::sqrt(2 * kPi);
  auto addRay = [&](double mu, double weight) {
    // The innermost edge, r = 0, lies at −μ/sd: beyond 38 sd both terms underflow anyway.
    const bool farFromPole = mu > 38 * sd;
    double cdfLo = farFromPole ? 0.0 : normalCdf(-mu / sd);
    double pdfLo = farFromPole ? 0.0 : std::exp(-0.5 * (mu / sd) * (mu / sd));
    for (size_t k = 0; k < rings; ++k) {
      const double z = (edge[k + 1] - mu) / sd;
      const double cdfHi = std::isinf(z) ? 1.0 : normalCdf(z), pdfHi = std::isinf(z) ? 0.0 : std::exp(-0.5 * z * z);
      (*value)[k] += weight * (sd * sd * (pdfLo - pdfHi) + mu * sd * root2pi * (cdfHi - cdfLo));
      cdfLo = cdfHi, pdfLo = pdfHi;
    }
  };
  static const QuadratureRule three = gaussLegendre(3, 0.0, 1.0), five = gaussLegendre(5, 0.0, 1.0);
  if (rc > 10 * sd) {
    const double ua = rc * std::sin(a - phic) / sd, ub = rc * std::sin(b - phic) / sd;
    const int pieces = std::max(1, int(std::ceil((ub - ua) / 3)));
    const double h = (ub - ua) / pieces;
    for (int c = 0; c < pieces; ++c) {
      const double u0 = ua + c * h, u1 = u0 + h, e0 = std::exp(-0.5 * u0 * u0), e1 = std::exp(-0.5 * u1 * u1);
      const double m0 = root2pi * (normalCdf(u1) - normalCdf(u0)), m1 = e0 - e1, m2 = m0 + u0 * e0 - u1 * e1;
      double u[3];
      for (int j = 0; j < 3; ++j) u[j] = u0 + h * three.x[size_t(j)];
      for (int j = 0; j < 3; ++j) {
        const double v = u[(j + 1) % 3], w = u[(j + 2) % 3];
        // ∫ e^{−u²/2} ℓ_j(u) du with ℓ_j the Lagrange basis polynomial of node j.
        const double weight = (m2 - (v + w) * m1 + v * w * m0) / ((u[j] - v) * (u[j] - w));
        const double mu = std::sqrt(rc * rc - (u[j] * sd) * (u[j] * sd));
        addRay(mu, weight * norm * sd / mu);
      }
    }
    return;
  }
  const double cellWidth = rc > 0 ? 3 * sd / rc : 2 * kPi;
  const int cells = std::max(1, int(std::ceil((b - a) / cellWidth)));
  const double h = (b - a) / cells;
  for (int c = 0; c < cells; ++c)
    for (size_t i = 0; i < five.x.size(); ++i) {
      const double psi = a + h * (c + five.x[i]) - phic;
      const double across = rc * std::sin(psi) / sd;
      const double weight = std::exp(-0.5 * across * across) * norm * h * five.w[i];
      if (weight > 0) addRay(rc * std::cos(psi), weight);
    }
}

// A theta-phi bin is a rectangle in polar coordinates (r, φ) of the plane.
bool thetaPhiShares(const DirectionGrid& grid, const ThetaPhiGrid& g, double cx, double cy, double sd, int offset,
                    std::vector<std::pair<int, double>>* out) {
  const double rc = std::hypot(cx, cy);
  if (!(rc < 1)) return false;  // beyond the horizon (or not a number)
  auto ringOf = [&](double r) {
    if (r <= 0) return 0;
    if (r >= 1) return g.nTheta - 1;
    int t = std::clamp(int(std::asin(r) * g.nTheta / (0.5 * kPi)), 0, g.nTheta - 1);
    while (t > 0 && grid.ringEdgeSin(t) > r) --t;
    while (t + 1 < g.nTheta && grid.ringEdgeSin(t + 1) <= r) ++t;
    return t;
  };
  const int t0 = ringOf(rc - kLobeWindow * sd), t1 = ringOf(rc + kLobeWindow * sd);
  const double dphi = 2 * kPi / g.nPhi;
  double phic = std::atan2(cy, cx);
  if (phic < 0) phic += 2 * kPi;
  // The angular window: ±kLobeWindow sd across the ray through the centre (the whole circle when
  // the spot covers the pole).
  const double reach = kLobeWindow * sd < rc ? std::asin(kLobeWindow * sd / rc) : kPi;
  const double lo = phic - reach, hi = phic + reach;
  const long p0 = long(std::floor(lo / dphi)), p1 = long(std::floor(hi / dphi));
  auto binOf = [&](int t, long p) { return offset + t * g.nPhi + int(((p % g.nPhi) + g.nPhi) % g.nPhi); };
  if (t0 == t1 && t1 < g.nTheta - 1 && rc > 8 * sd) {
    if (p0 == p1)
      out->push_back({binOf(t0, p0), 1.0});
    else
      oneRingShares(
          rc, phic, sd, dphi, p0, p1, [&](long p) { return binOf(t0, p); }, out);
    return true;
  }
  // Ring edges: the window's innermost ring starts at r = 0 and its outermost (unless it is the
  // grid's last, which ends at the horizon: beyond is evanescent) runs to infinity, so that the
  // tails beyond the window stay in it.
  const int rings = t1 - t0 + 1;
  thread_local std::vector<double> edge, value;
  edge.assign(size_t(rings) + 1, 0.0);
  for (int k = 1; k < rings; ++k) edge[size_t(k)] = grid.ringEdgeSin(t0 + k);
  edge[size_t(rings)] = t1 == g.nTheta - 1 ? 1.0 : HUGE_VAL;
  for (long p = p0; p <= p1; ++p) {
    const double a = std::max(lo, double(p) * dphi), b = std::min(hi, double(p + 1) * dphi);
    if (b <= a) continue;
    value.assign(size_t(rings), 0.0);
    sectorRingIntegrals(rc, phic, sd, a, b, edge, &value);
    for (int k = 0; k < rings; ++k)
      if (value[size_t(k)] > 0) out->push_back({binOf(t0 + k, p), value[size_t(k)]});
  }
  return true;
}

bool diskShares(const DiskGrid& g, double cx, double cy, double sd, int offset,
                std::vector<std::pair<int, double>>* out) {
  // Pixels are squares of the plane: their shares are exact products. Only a spot clear of the
  // rim, where pixels are cut by the unit circle, is taken.
  if (!(std::hypot(cx, cy) + kLobeWindow * sd < 1)) return false;
  thread_local std::vector<double> sx, sy;
  auto range = [&](double c, int n, std::vector<double>* share) {
    auto pixelOf = [&](double v) { return std::clamp(int(std::floor((v + 1) * 0.5 * n)), 0, n - 1); };
    const int k0 = pixelOf(c - kLobeWindow * sd), k1 = pixelOf(c + kLobeWindow * sd);
    intervalShares(
        k0, k1, [&](long k) { return normalCdf((-1 + 2.0 * double(k) / n - c) / sd); }, false, share);
    return k0;
  };
  const int i0 = range(cx, g.width, &sx), j0 = range(cy, g.height, &sy);
  for (size_t j = 0; j < sy.size(); ++j)
    for (size_t i = 0; i < sx.size(); ++i)
      if (sx[i] > 0 && sy[j] > 0) out->push_back({offset + (j0 + int(j)) * g.width + i0 + int(i), sx[i] * sy[j]});
  return true;
}

}  // namespace

bool gaussianLobeShares(const DirectionGrid& grid, double cx, double cy, double sd, bool upper,
                        std::vector<std::pair<int, double>>* out) {
  out->clear();
  if (!(sd > 0)) return false;
  const int offset = upper ? 0 : grid.binsPerHemisphere();
  const bool done =
      std::visit(Overloaded{[&](const ThetaPhiGrid& g) { return thetaPhiShares(grid, g, cx, cy, sd, offset, out); },
                            [&](const DiskGrid& g) { return diskShares(g, cx, cy, sd, offset, out); }},
                 grid.layout());
  if (!done) out->clear();
  return done;
}

}  // namespace mbsdf
