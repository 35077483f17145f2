// Microflake normal distributions for statistically described surfaces (docs/physics.md §9).
// Sources: Dupuy, Heitz & d'Eon 2016 (Additional Progress Towards the Unification of Microfacet and Microflake
// Theories, EGSR), Heitz 2014 ("Understanding the masking-shadowing function in microfacet-based BRDFs": Λ, G2) and
// Heitz & d'Eon 2014
// ("Importance sampling microfacet-based BSDFs using the distribution of visible normals").
//
// A closed set of value types:
//  - BeckmannNdf, GgxNdf: heightfield NDFs (zero below the horizon), anisotropic (αx, αy),
//    normalised by ∫ D(m) ⟨m, z⟩ dm = 1 (Dupuy et al. 2016, Eq. 17).
//  - VonMisesFisherNdf: the full-sphere family D ∝ exp(κ m·z) of Dupuy et al. 2016, Sec. 4.3, with the same
//    normalisation (Eq. 17). κ → ∞ is a flat mirror, large κ is Beckmann-like with α² ≈ 2/κ and
//    κ = 0 is the constant NDF D = 1/π (σ = 1, isotropic phase function with mirror flakes:
//    Chandrasekhar's medium).
//
// The medium (density 1, z ≤ 0) has the extinction σ(d) = ∫ ⟨−d, m⟩ D(m) dm for travel direction d
// (Dupuy et al. 2016, Eq. 4); for heightfield NDFs σ = Λ(d) d_z upward and (1 + Λ(−d)) |d_z| downward (Eqs. 18–19),
// in closed form; for the vMF family from a numeric table. Collisions pick a visible normal with
// density ⟨−d, m⟩ D(m) / σ(d) (Eq. 6), sampled exactly: GGX in closed form by spherical caps (Dupuy &
// Benyoub 2023), Beckmann by slope-space rejection, the sphere family by a vMF proposal with
// rejection; the rejections have bounded expected cost because the rare directions with small σ
// are also rarely collided with.
#pragma once
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "core/rng.h"
#include "core/vecmath.h"

namespace mbsdf {

struct BeckmannNdf {
  double alphaX = 0.3, alphaY = 0.3;
};
struct GgxNdf {
  double alphaX = 0.3, alphaY = 0.3;
};
struct VonMisesFisherNdf {
  double kappa = 0.0;
};
// Any isotropic NDF given as a table D(cos θm), piecewise linear in cos θm on [−1, 1] (values
// outside the table are 0), e.g. a measured distribution; normalised here by Eq. 17. The general
// path: σ(ω) by numeric quadrature into a table, visible normals by exact sampling of the
// piecewise-linear density in cos θm and rejection with ⟨v, m⟩.
struct TabulatedNdf {
  std::vector<double> cosTheta;  // strictly increasing, in [−1, 1]
  std::vector<double> value;     // D >= 0 (any scale)
};
using Ndf = std::variant<BeckmannNdf, GgxNdf, VonMisesFisherNdf, TabulatedNdf>;

// Beckmann and GGX are heightfield NDFs (zero below the horizon, Smith Λ in closed form).
inline bool isHeightfieldNdf(const Ndf& ndf) {
  return std::holds_alternative<BeckmannNdf>(ndf) || std::holds_alternative<GgxNdf>(ndf);
}

// Checks a table (throws std::invalid_argument) and scales it so that ∫ D ⟨m,z⟩ dm = 1 (Eq. 17).
void normaliseNdfTable(TabulatedNdf& t);

class MicroflakeDistribution {
 public:
  explicit MicroflakeDistribution(Ndf ndf);

  const Ndf& ndf() const { return ndf_; }
  bool isHeightfield() const { return isHeightfieldNdf(ndf_); }
  std::string describe() const;

  // D(m) for a unit normal m (1/sr).
  double D(const Vec3& m) const;
  // Smith Λ for a direction above the horizon (heightfield NDFs only).
  double lambda(const Vec3& w) const;
  // Smith masking G1 = 1 / (1 + Λ(w)) (Dupuy et al. 2016, Eq. 20).
  double G1(const Vec3& w) const { return 1.0 / (1.0 + lambda(w)); }
  // Height-correlated masking–shadowing G2 = 1 / (1 + Λ(wi) + Λ(wo)) (heightfield NDFs).
  double G2(const Vec3& wi, const Vec3& wo) const { return 1.0 / (1.0 + lambda(wi) + lambda(wo)); }
  // Extinction coefficient σ(d) for travel direction d (unit).
  double sigma(const Vec3& d) const;
  // Free path along d for a uniform number u (Dupuy et al. 2016, Eq. 10); +inf when σ(d) = 0.
  double freePath(const Vec3& d, double u) const { return freePathAt(sigma(d), u); }
  // The same where σ(d) is known (the walk's first flight, along the incidence for every path).
  static double freePathAt(double sigma, double u);
  // A cheap upper bound on σ(d) for an upward flight (d_z > 0), with which the walk decides most
  // escapes without σ itself: GGX q²/(4 d_z) (no square roots); a steep flight through a smooth
  // Beckmann medium 2e-20 d_z (σ costs an exponential and an erfc there). Negative when there is none.
  double upwardSigmaBound(const Vec3& d) const;
  // Whether upwardSigmaBound can give one (GGX, Beckmann): the walk asks it only then.
  bool hasUpwardSigmaBound() const {
    return std::holds_alternative<GgxNdf>(ndf_) || std::holds_alternative<BeckmannNdf>(ndf_);
  }
  // A normal with density ⟨v, m⟩ D(m) / σ(−v) (Dupuy et al. 2016, Eq. 6 with v = −d, the direction the light
  // came from). Empty only if the rejection loop hits its cap (reported as truncated).
  std::optional<Vec3> sampleVisible(const Vec3& v, Sampler& s) const { return sampleVisible(visibleFrom(v), s); }
  // What sampling a visible normal computes from v alone, before it draws a number: prepared once
  // where many samples share v (the walk's first collision, whose v is the incidence), with the
  // same values, so the samples are the same to the bit.
  struct VisibleFrom {
    Vec3 v;
    double r = 0, cosPhi = 1, sinPhi = 0, pFirst = 1;  // Beckmann: the stretched v on +x, the envelope's mixture
    Vec3 vStretched;                                   // GGX: v stretched to α = 1
  };
  VisibleFrom visibleFrom(const Vec3& v) const;
  std::optional<Vec3> sampleVisible(const VisibleFrom& from, Sampler& s) const;

 private:
  double sigmaUpHeightfield(const Vec3& d) const;  // Λ(d) d_z for d_z >= 0
  double sigmaTable(double mu) const;
  double tabulatedD(double mz) const;
  Ndf ndf_;
  double vmfNorm_ = 0;              // C in D = C exp(κ (m_z − 1))
  std::vector<double> sigmaTable_;  // σ(μ) on a uniform grid of μ = d_z in [−1, 1] (vMF, tabulated)
  std::vector<double> tabCdf_;      // tabulated: CDF of 2π D(m_z) over the table's intervals
};

// Standard normal variates from two uniforms (Box–Muller).
double standardNormal(double u1, double u2);

}  // namespace mbsdf
