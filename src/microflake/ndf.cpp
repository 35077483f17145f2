#include "microflake/ndf.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/overloaded.h"
#include "core/quadrature.h"

namespace mbsdf {

namespace {

constexpr double kSqrtPi = 1.7724538509055160273;
constexpr int kVmfTableSize = 1025;
constexpr int kMaxRejections = 1 << 22;
// Below this κ the vMF family's visible normals are proposed cosine-weighted about v (as for κ = 0)
// and thinned by exp(κ(m_z − 1)): at least e^{−2κ} of the tries are kept (0.37 here), where the vMF
// proposal keeps about a quarter near κ = 0.
constexpr double kCosineProposalKappa = 0.5;

// I0(x) e^{−x} (exponentially scaled modified Bessel function), without overflow.
double besselI0Scaled(double x) {
  if (x < 200) return std::cyl_bessel_i(0.0, x) * std::exp(-x);
  // Asymptotic series (Abramowitz & Stegun 9.7.1); the next term is below 1e-12 for x >= 200.
  const double t = 1.0 / (8 * x);
  return (1 + t * (1 + t * (4.5 + t * (37.5 + t * 459.375)))) / std::sqrt(2 * kPi * x);
}

// ∫_0^1 μ e^{κ(μ−1)} dμ = (κ − 1 + e^{−κ}) / κ², by series for small κ.
double vmfProjectedMass(double kappa) {
  if (kappa < 1e-2) return 0.5 - kappa / 6 + kappa * kappa / 24 - kappa * kappa * kappa / 120;
  return (kappa + std::expm1(-kappa)) / (kappa * kappa);
}

// Orthonormal frame (t, b) around a unit vector n (Duff et al. 2017).
void frame(const Vec3& n, Vec3* t, Vec3* b) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z), c = n.x * n.y * a;
  *t = {1 + sign * n.x * n.x * a, sign * c, -sign * n.x};
  *b = {c, sign + n.y * n.y * a, -n.y};
}

// Anisotropic stretch: q = sqrt(αx² d_x² + αy² d_y²) = α(φ) sin θ.
template <typename N>
double stretchedSin(const N& n, const Vec3& d) {
  return std::sqrt(n.alphaX * n.alphaX * d.x * d.x + n.alphaY * n.alphaY * d.y * d.y);
}

}  // namespace

void normaliseNdfTable(TabulatedNdf& t) {
  const size_t n = t.cosTheta.size();
  if (n < 2 || t.value.size() != n) throw std::invalid_argument("an NDF table needs at least two rows");
  for (size_t i = 0; i < n; ++i) {
    if (!(t.cosTheta[i] >= -1 && t.cosTheta[i] <= 1) || !(t.value[i] >= 0) || !std::isfinite(t.value[i]))
      throw std::invalid_argument("NDF table: cos θ must be in [−1, 1] and D finite and >= 0");
    if (i > 0 && !(t.cosTheta[i] > t.cosTheta[i - 1]))
      throw std::invalid_argument("NDF table: θ must be strictly monotone");
  }
  // Eq. 17: ∫ D ⟨m,z⟩ dm = 2π ∫_0^1 D(μ) μ dμ, exact (Simpson) for the piecewise-linear D.
  double proj = 0;
  for (size_t i = 1; i < n; ++i) {
    const double a = t.cosTheta[i - 1], b = t.cosTheta[i], da = t.value[i - 1], db = t.value[i];
    const double lo = std::max(a, 0.0);
    if (!(b > lo)) continue;
    auto Dl = [&](double x) { return da + (db - da) * (x - a) / (b - a); };
    const double m = 0.5 * (lo + b);
    proj += 2 * kPi * (b - lo) / 6 * (lo * Dl(lo) + 4 * m * Dl(m) + b * Dl(b));
  }
  if (!(proj > 0) || !std::isfinite(proj)) throw std::invalid_argument("NDF table: no normals above the horizon");
  for (double& v : t.value) v /= proj;
}

double standardNormal(double u1, double u2) {
  return std::sqrt(-2.0 * std::log1p(-u1)) * std::cos(2 * kPi * u2);
}

MicroflakeDistribution::MicroflakeDistribution(Ndf ndf) : ndf_(ndf) {
  std::visit(Overloaded{[](const BeckmannNdf& n) {
                          if (!(n.alphaX > 0 && n.alphaY > 0)) throw std::invalid_argument("alpha must be positive");
                        },
                        [](const GgxNdf& n) {
                          if (!(n.alphaX > 0 && n.alphaY > 0)) throw std::invalid_argument("alpha must be positive");
                        },
                        [&](const VonMisesFisherNdf& n) {
                          if (!(n.kappa >= 0 && n.kappa <= 1e4))
                            throw std::invalid_argument("kappa must be in [0, 1e4]");
                          vmfNorm_ = 1.0 / (2 * kPi * vmfProjectedMass(n.kappa));
                          if (n.kappa == 0) return;
                          // σ(μ) = C 2π ∫_0^1 u e^{κ(−uμ − 1)} I0(κ s √(1−u²)) du, s = √(1−μ²): the
                          // azimuthal integral around −d done in closed form (modified Bessel I0).
                          const double k = n.kappa;
                          const int panels = 48;
                          QuadratureRule gl = gaussLegendre(12, 0.0, 1.0 / panels);
                          sigmaTable_.resize(kVmfTableSize);
                          for (int i = 0; i < kVmfTableSize; ++i) {
                            const double mu = -1.0 + 2.0 * i / (kVmfTableSize - 1);
                            const double s = safeSqrt(1 - mu * mu);
                            double sum = 0;
                            for (int p = 0; p < panels; ++p)
                              for (size_t j = 0; j < gl.x.size(); ++j) {
                                const double u = gl.x[j] + double(p) / panels;
                                const double x = k * s * safeSqrt(1 - u * u);
                                sum += gl.w[j] * u * std::exp(k * (-u * mu - 1) + x) * besselI0Scaled(x);
                              }
                            sigmaTable_[i] = vmfNorm_ * 2 * kPi * sum;
                          }
                        },
                        [&](TabulatedNdf& t) {
                          normaliseNdfTable(t);
                          const size_t n = t.cosTheta.size();
                          tabCdf_.assign(n, 0.0);
                          for (size_t i = 1; i < n; ++i)
                            tabCdf_[i] = tabCdf_[i - 1] +
                                         0.5 * (t.value[i - 1] + t.value[i]) * (t.cosTheta[i] - t.cosTheta[i - 1]);
                          for (double& c : tabCdf_) c /= tabCdf_.back();
                          // σ(μ) by quadrature in the frame around −d: u = ⟨−d,m⟩, ψ the azimuth.
                          QuadratureRule gu = gaussLegendre(8, 0.0, 1.0 / 32), gp = gaussLegendre(8, 0.0, kPi / 8);
                          sigmaTable_.resize(kVmfTableSize);
                          for (int i = 0; i < kVmfTableSize; ++i) {
                            const double mu = -1.0 + 2.0 * i / (kVmfTableSize - 1), sd = safeSqrt(1 - mu * mu);
                            double sum = 0;
                            for (int p = 0; p < 32; ++p)
                              for (size_t j = 0; j < gu.x.size(); ++j) {
                                const double u = gu.x[j] + double(p) / 32, r = safeSqrt(1 - u * u);
                                double inner = 0;
                                for (int q = 0; q < 8; ++q)
                                  for (size_t k = 0; k < gp.x.size(); ++k)
                                    inner += gp.w[k] * tabulatedD(-u * mu + r * sd * std::cos(gp.x[k] + q * kPi / 8));
                                sum += gu.w[j] * u * 2 * inner;  // ψ ∈ [0, π] twice
                              }
                            sigmaTable_[i] = sum;
                          }
                        }},
             ndf_);
}

double MicroflakeDistribution::tabulatedD(double mz) const {
  const auto& t = std::get<TabulatedNdf>(ndf_);
  if (mz < t.cosTheta.front() || mz > t.cosTheta.back()) return 0.0;
  const size_t i =
      std::min(t.cosTheta.size() - 2,
               size_t(std::upper_bound(t.cosTheta.begin(), t.cosTheta.end(), mz) - t.cosTheta.begin()) - 1);
  const double f = (mz - t.cosTheta[i]) / (t.cosTheta[i + 1] - t.cosTheta[i]);
  return t.value[i] + f * (t.value[i + 1] - t.value[i]);
}

std::string MicroflakeDistribution::describe() const {
  return std::visit(
      Overloaded{[](const BeckmannNdf& n) { return fmt::format("Beckmann αx={} αy={}", n.alphaX, n.alphaY); },
                 [](const GgxNdf& n) { return fmt::format("GGX αx={} αy={}", n.alphaX, n.alphaY); },
                 [](const VonMisesFisherNdf& n) {
                   return n.kappa == 0 ? std::string("constant full-sphere NDF (isotropic medium)")
                                       : fmt::format("von Mises–Fisher κ={}", n.kappa);
                 },
                 [](const TabulatedNdf& n) {
                   return fmt::format("tabulated isotropic NDF ({} rows, θ from {:.3g}° to {:.3g}°)", n.cosTheta.size(),
                                      degrees(std::acos(n.cosTheta.back())), degrees(std::acos(n.cosTheta.front())));
                 }},
      ndf_);
}

double MicroflakeDistribution::D(const Vec3& m) const {
  return std::visit(
      Overloaded{[&](const BeckmannNdf& n) {
                   if (m.z <= 0) return 0.0;
                   const double z2 = m.z * m.z;
                   const double e = (m.x * m.x / (n.alphaX * n.alphaX) + m.y * m.y / (n.alphaY * n.alphaY)) / z2;
                   return std::exp(-e) / (kPi * n.alphaX * n.alphaY * z2 * z2);
                 },
                 [&](const GgxNdf& n) {
                   if (m.z <= 0) return 0.0;
                   const double z2 = m.z * m.z;
                   const double e = (m.x * m.x / (n.alphaX * n.alphaX) + m.y * m.y / (n.alphaY * n.alphaY)) / z2;
                   return 1.0 / (kPi * n.alphaX * n.alphaY * z2 * z2 * (1 + e) * (1 + e));
                 },
                 [&](const VonMisesFisherNdf& n) { return vmfNorm_ * std::exp(n.kappa * (m.z - 1)); },
                 [&](const TabulatedNdf&) { return tabulatedD(m.z); }},
      ndf_);
}

double MicroflakeDistribution::sigmaUpHeightfield(const Vec3& d) const {
  return std::visit(
      Overloaded{[&](const BeckmannNdf& n) {
                   // Λ cos θ = [q e^{−ν²}/√π − d_z erfc ν] / 2 with ν = d_z / q (finite at the horizon).
                   const double q = stretchedSin(n, d);
                   if (q == 0) return 0.0;
                   const double nu = d.z / q;
                   if (nu > 20) {
                     // Asymptotic expansion of erfc (relative error < 1e-8 here); below ν = 20 the direct form
                     // loses only log10(2ν²) digits to cancellation.
                     const double i2 = 1.0 / (nu * nu);
                     return q * std::exp(-nu * nu) / (2 * kSqrtPi) *
                            (0.5 * i2 - 0.75 * i2 * i2 + 1.875 * i2 * i2 * i2 - 6.5625 * i2 * i2 * i2 * i2);
                   }
                   return 0.5 * (q * std::exp(-nu * nu) / kSqrtPi - d.z * std::erfc(nu));
                 },
                 [&](const GgxNdf& n) {
                   // Λ cos θ = (√(d_z² + q²) − d_z) / 2, rationalised.
                   const double q = stretchedSin(n, d);
                   return 0.5 * q * q / (d.z + std::sqrt(d.z * d.z + q * q));
                 },
                 [](const auto&) { return 0.0; }},
      ndf_);
}

double MicroflakeDistribution::lambda(const Vec3& w) const {
  if (!isHeightfield()) throw std::logic_error("Smith Λ is defined for heightfield NDFs only");
  if (w.z <= 0) return std::numeric_limits<double>::infinity();
  return sigmaUpHeightfield(w) / w.z;
}

double MicroflakeDistribution::sigmaTable(double mu) const {
  const double x = (std::clamp(mu, -1.0, 1.0) + 1) * 0.5 * (kVmfTableSize - 1);
  const int i = std::min(kVmfTableSize - 2, int(x));
  const double t = x - i;
  return (1 - t) * sigmaTable_[i] + t * sigmaTable_[i + 1];
}

double MicroflakeDistribution::sigma(const Vec3& d) const {
  if (const auto* v = std::get_if<VonMisesFisherNdf>(&ndf_)) return v->kappa == 0 ? 1.0 : sigmaTable(d.z);
  if (std::holds_alternative<TabulatedNdf>(ndf_)) return sigmaTable(d.z);
  if (d.z >= 0) return sigmaUpHeightfield(d);
  if (const auto* b = std::get_if<BeckmannNdf>(&ndf_)) {
    // Steep downward flights of a smooth Beckmann surface: Λ(−d)|d_z| <= q e^{−ν²} / (2√π) is below
    // 2^−54 |d_z| once ν = |d_z| / q > 6.5, so the sum below rounds to |d_z| exactly; skip its
    // exponential and erfc (a third of a short walk's cost at α = 0.1).
    const double q = stretchedSin(*b, d);
    if (-d.z > 6.5 * q) return -d.z;
  }
  return -d.z + sigmaUpHeightfield(-d);  // Dupuy et al. 2016, Eq. 19: (1 + Λ(−d)) |d_z|
}

double MicroflakeDistribution::upwardSigmaBound(const Vec3& d) const {
  if (!(d.z > 0)) return -1;
  if (const auto* g = std::get_if<GgxNdf>(&ndf_)) {
    // σ = q² / (2 (d_z + √(d_z² + q²))) (sigmaUpHeightfield) <= q² / (4 d_z).
    const double q2 = g->alphaX * g->alphaX * d.x * d.x + g->alphaY * g->alphaY * d.y * d.y;
    return q2 / (4 * d.z);
  }
  const auto* b = std::get_if<BeckmannNdf>(&ndf_);
  if (!b) return -1;
  // σ(d) = Λ(d) d_z <= q e^{−ν²} / (2√π) with q = d_z / ν (the erfc term is subtracted); for
  // ν >= 6.5 that is at most 1.95e-20 d_z.
  const double q = stretchedSin(*b, d);
  return d.z > 6.5 * q ? 2e-20 * d.z : -1;
}

double MicroflakeDistribution::freePathAt(double sigma, double u) {
  if (!(sigma > 0)) return std::numeric_limits<double>::infinity();
  return -std::log1p(-u) / sigma;
}

MicroflakeDistribution::VisibleFrom MicroflakeDistribution::visibleFrom(const Vec3& v) const {
  VisibleFrom f;
  f.v = v;
  if (const auto* n = std::get_if<BeckmannNdf>(&ndf_)) {
    // Slope space (Heitz & d'Eon 2014): D(m)⟨v,m⟩dm = P22(s) max(0, v_z − v_x s_x − v_y s_y) ds. After
    // stretching to α = 1 and rotating v' = (αx v_x, αy v_y) onto +x, the weight is
    // max(0, v_z − r s∥) with r = |v'| and the isotropic P22_11 factorises into P2(s∥) P(s⊥).
    const double vx = n->alphaX * v.x, vy = n->alphaY * v.y;
    f.r = std::sqrt(vx * vx + vy * vy);
    f.cosPhi = f.r > 0 ? vx / f.r : 1.0;
    f.sinPhi = f.r > 0 ? vy / f.r : 0.0;
    // Envelope |v_z| + r|s∥|: a mixture of P2 and |s|P2 (E|s| = 1/√π for Beckmann).
    f.pFirst = std::abs(v.z) / (std::abs(v.z) + f.r / kSqrtPi);
  } else if (const auto* g = std::get_if<GgxNdf>(&ndf_)) {
    f.vStretched = normalize(Vec3{g->alphaX * v.x, g->alphaY * v.y, v.z});
  }
  return f;
}

std::optional<Vec3> MicroflakeDistribution::sampleVisible(const VisibleFrom& from, Sampler& s) const {
  const Vec3& v = from.v;
  auto beckmann = [&](double ax, double ay) -> std::optional<Vec3> {
    // The weight max(0, v_z − r s∥) in the stretched frame rotated by (cphi, sphi) (visibleFrom).
    const double r = from.r, cphi = from.cosPhi, sphi = from.sinPhi, pFirst = from.pFirst;
    // s⊥ ~ N(0, 1/2) independent of s∥: when s∥ came from P2 by Box–Muller, the pair's other
    // deviate is one (acceptance looks at s∥ and u3 only), which saves a logarithm and a cosine.
    double sPar = 0, sPerp = std::numeric_limits<double>::quiet_NaN();
    for (int tries = 0;; ++tries) {
      if (tries == kMaxRejections) return std::nullopt;
      const double u0 = s.get1D(), u1 = s.get1D(), u2 = s.get1D(), u3 = s.get1D();
      if (u0 < pFirst) {
        const double radius = std::sqrt(-std::log1p(-u1)), phi = 2 * kPi * u2;  // N(0, 1/2) pair
        sPar = radius * std::cos(phi);
        sPerp = radius * std::sin(phi);
      } else {
        const double a = std::sqrt(-std::log1p(-u1));
        sPar = u2 < 0.5 ? a : -a;
        sPerp = std::numeric_limits<double>::quiet_NaN();
      }
      const double wgt = v.z - r * sPar;
      if (wgt > 0 && u3 * (std::abs(v.z) + r * std::abs(sPar)) < wgt) break;
    }
    if (std::isnan(sPerp)) {
      const double uAngle = s.get1D(), uRadius = s.get1D();  // in this order (the angle's first)
      sPerp = standardNormal(uRadius, uAngle) / std::sqrt(2.0);
    }
    const double sx = ax * (cphi * sPar - sphi * sPerp), sy = ay * (sphi * sPar + cphi * sPerp);
    return normalize(Vec3{-sx, -sy, 1.0});
  };
  // GGX in closed form (Dupuy & Benyoub 2023, "Sampling Visible GGX Normals with Spherical Caps",
  // Listing 3): stretched to α = 1 the microflakes are the upper unit hemisphere, whose mirror
  // reflects light arriving along −v uniformly into the cap o_z ≥ −v_z; the visible normal is
  // the half vector of v and a uniform direction of that cap. The cap argument holds for v below
  // the horizon too (the cap shrinks). Two numbers and no rejection, where the slope-space route
  // spent four Gaussian deviates on s⊥ alone.
  auto ggx = [&](double ax, double ay) -> std::optional<Vec3> {
    const Vec3& vStd = from.vStretched;
    const double phi = 2 * kPi * s.get1D();
    const double z = (1 - s.get1D()) * (1 + vStd.z) - vStd.z;
    const double sinTheta = safeSqrt(1 - z * z);
    const Vec3 h = Vec3{sinTheta * std::cos(phi), sinTheta * std::sin(phi), z} + vStd;
    const Vec3 m{ax * h.x, ay * h.y, std::max(0.0, h.z)};
    const double len = length(m);
    if (!(len > 0)) return std::nullopt;  // v straight down: no flake is visible (σ = 0)
    return m / len;
  };
  return std::visit(
      Overloaded{[&](const BeckmannNdf& n) { return beckmann(n.alphaX, n.alphaY); },
                 [&](const GgxNdf& n) { return ggx(n.alphaX, n.alphaY); },
                 [&](const VonMisesFisherNdf& n) -> std::optional<Vec3> {
                   // Constant NDF: ⟨v,m⟩ on the hemisphere around v (cosine-weighted).
                   auto cosineAboutV = [&] {
                     const double u1 = s.get1D(), u2 = s.get1D();
                     const double rr = std::sqrt(u1), phi = 2 * kPi * u2;
                     Vec3 t, b;
                     frame(v, &t, &b);
                     return normalize(t * (rr * std::cos(phi)) + b * (rr * std::sin(phi)) + v * safeSqrt(1 - u1));
                   };
                   if (n.kappa == 0) return cosineAboutV();
                   if (n.kappa < kCosineProposalKappa) {
                     // Nearly constant: propose ⟨v,m⟩ and accept with exp(κ(m_z − 1)) ≤ 1, the ratio of
                     // the target ⟨v,m⟩ exp(κ m_z) to the proposal; acceptance >= exp(−2κ), about
                     // 1 − κ on average, where the vMF proposal below keeps only ~1/4.
                     for (int tries = 0; tries < kMaxRejections; ++tries) {
                       const Vec3 m = cosineAboutV();
                       if (s.get1D() < std::exp(n.kappa * (m.z - 1))) return m;
                     }
                     return std::nullopt;
                   }
                   // Propose from the vMF density on the sphere (exact inversion of m_z), accept with ⟨v,m⟩.
                   for (int tries = 0; tries < kMaxRejections; ++tries) {
                     const double u1 = s.get1D(), u2 = s.get1D(), u3 = s.get1D();
                     const double mz = std::clamp(1 + std::log1p(-u1 * -std::expm1(-2 * n.kappa)) / n.kappa, -1.0, 1.0);
                     const double sr = safeSqrt(1 - mz * mz), phi = 2 * kPi * u2;
                     const Vec3 m{sr * std::cos(phi), sr * std::sin(phi), mz};
                     const double c = dot(v, m);
                     if (c > 0 && u3 < c) return m;
                   }
                   return std::nullopt;
                 },
                 [&](const TabulatedNdf& t) -> std::optional<Vec3> {
                   // Propose m_z from the piecewise-linear density (exact inversion of the quadratic CDF
                   // inside an interval), φ uniform; accept with ⟨v,m⟩.
                   for (int tries = 0; tries < kMaxRejections; ++tries) {
                     const double u1 = s.get1D(), u2 = s.get1D(), u3 = s.get1D(), u4 = s.get1D();
                     const size_t i =
                         std::min(tabCdf_.size() - 2,
                                  size_t(std::upper_bound(tabCdf_.begin(), tabCdf_.end(), u1) - tabCdf_.begin()) - 1);
                     const double a = t.cosTheta[i], w = t.cosTheta[i + 1] - a, da = t.value[i], db = t.value[i + 1];
                     // Density ∝ da + (db − da) x on x ∈ [0, 1]: solve (db − da) x²/2 + da x = u (da + db)/2.
                     double x;
                     if (std::abs(db - da) < 1e-12 * std::max(da, db)) {
                       x = u2;
                     } else {
                       const double disc = da * da + u2 * (db * db - da * da);
                       x = (std::sqrt(std::max(0.0, disc)) - da) / (db - da);
                     }
                     const double mz = std::clamp(a + w * std::clamp(x, 0.0, 1.0), -1.0, 1.0);
                     const double sr = safeSqrt(1 - mz * mz), phi = 2 * kPi * u3;
                     const Vec3 m{sr * std::cos(phi), sr * std::sin(phi), mz};
                     const double c = dot(v, m);
                     if (c > 0 && u4 < c) return m;
                   }
                   return std::nullopt;
                 }},
      ndf_);
}

}  // namespace mbsdf
