#include "scattering/kirchhoff_ensemble.h"

#include <algorithm>
#include <cmath>

namespace mbsdf {

double EnsembleSlice::l1() const {
  double s = 0;
  for (size_t c = 0; c < geometric.size(); ++c) s += std::abs(coherent[c] + diffuse[c] - geometric[c]);
  return s;
}

double EnsembleSlice::upperBound() const {
  double s = 0;
  for (size_t c = 0; c < geometric.size(); ++c) s += std::abs(coherent[c] - geometric[c]) + diffuse[c];
  return s;
}

double kirchhoffDiffuseSeries(double g, double X) {
  if (g <= 0) return 0.0;
  // Past g = 1e4 the series is its geometric-optics limit to O(1/g).
  if (g > 1e4) return std::exp(-X / g);
  // The terms g^m / (m! m) e^{−X/m} e^{−g} peak near m = g (a Poisson weight of width √g, moved up
  // by e^{−X/m} in the lobe's tails): summed outward from the largest until they fall below 1e-16
  // of the sum.
  const double lnG = std::log(g);
  auto term = [&](double m) { return std::exp(-g + m * lnG - std::lgamma(m + 1) - std::log(m) - X / m); };
  double peak = std::max(1.0, std::round(g));
  for (double next = peak + 1; term(next) > term(peak); next += 1) peak = next;
  double sum = term(peak);
  for (double m = peak + 1;; m += 1) {
    const double t = term(m);
    sum += t;
    if (t < 1e-16 * sum) break;
  }
  for (double m = peak - 1; m >= 1; m -= 1) {
    const double t = term(m);
    sum += t;
    if (t < 1e-16 * sum) break;
  }
  return g * sum;
}

std::vector<std::pair<double, double>> gaussianStrata(int nRadius, int nAngle) {
  std::vector<std::pair<double, double>> s;
  for (int i = 0; i < nRadius; ++i) {
    const double r = std::sqrt(-2.0 * std::log(1.0 - (i + 0.5) / nRadius));
    for (int j = 0; j < nAngle; ++j) {
      const double a = 2 * kPi * (j + 0.5 + 0.5 * (i % 2)) / nAngle;
      s.emplace_back(r * std::cos(a), r * std::sin(a));
    }
  }
  return s;
}

namespace {

// Smith's masking for the Beckmann NDF of width α (Walter et al. 2007, Eq. 27, exact Λ).
double smithG1(double cosTheta, double alpha) {
  if (cosTheta >= 1.0 || alpha <= 0) return 1.0;
  const double sinTheta = std::sqrt(std::max(0.0, 1.0 - cosTheta * cosTheta));
  const double a = cosTheta / (alpha * sinTheta);
  const double lambda = 0.5 * (std::erf(a) - 1.0) + std::exp(-a * a) / (2.0 * a * std::sqrt(kPi));
  return 1.0 / (1.0 + lambda);
}

// An isotropic Gaussian of slopes, P22 = exp(−|s|²/a²) / (π a²), restricted to rmin <= |s| < rmax:
// the radius of the stratum at quantile u of that ring, and the restricted density.
struct SlopeRegion {
  double a, rmin, rmax;
  double cdf(double r) const { return r >= 1e300 ? 1.0 : 1.0 - std::exp(-r * r / (a * a)); }
  double radius(double u) const {
    const double f = cdf(rmin) + u * (cdf(rmax) - cdf(rmin));
    return a * std::sqrt(-std::log(1.0 - f));
  }
  double density(double r) const { return std::exp(-r * r / (a * a)) / (kPi * a * a) / (cdf(rmax) - cdf(rmin)); }
};

}  // namespace

KirchhoffEnsemble::KirchhoffEnsemble(double sigma_um, double alpha, double windowSigma_um)
    : sigma_(sigma_um), alpha_(alpha), windowSigma_(windowSigma_um) {}

EnsembleSlice KirchhoffEnsemble::slice(const DirectionGrid& grid, const std::vector<std::pair<Vec3, double>>& wis,
                                       double lambda_um, double n, const std::function<double(double)>& reflectance,
                                       const std::vector<int>& cellOf, int nCells) const {
  EnsembleSlice out;
  out.coherent.assign(size_t(nCells), 0.0);
  out.diffuse.assign(size_t(nCells), 0.0);
  out.geometric.assign(size_t(nCells), 0.0);
  auto cell = [&](const Vec3& wo) { return cellOf[size_t(grid.binOf(wo))]; };
  const double k = 2 * kPi * n / lambda_um;
  const double ell = alpha_ > 0 ? 2 * sigma_ / alpha_ : 0.0;
  const double blur = windowSigma_ > 0 ? 1.0 / (std::sqrt(2.0) * windowSigma_ * k) : 0.0;
  static const std::vector<std::pair<double, double>> blurStrata = gaussianStrata(32, 16), noBlur{{0.0, 0.0}};
  // Slope strata per axis and region: about 32 768 slopes per incidence, shared by its directions.
  const int strata = std::max(12, int(std::lround(std::sqrt(16384.0 / double(std::max<size_t>(1, wis.size()))))));
  for (const auto& [wi, weight] : wis) {
    const double cosI = wi.z;
    const Vec3 mirror{-wi.x, -wi.y, wi.z};
    // Coherent: e^{−g} of the specular reflection, spread by the window's diffraction; directions
    // beyond the horizon are evanescent (lost).
    const double gSpec = std::pow(2 * k * sigma_ * cosI, 2);
    const double coherent = weight * std::exp(-gSpec) * reflectance(cosI);
    const std::vector<std::pair<double, double>>& spots = blur > 0 ? blurStrata : noBlur;
    for (const auto& [dx, dy] : spots) {
      const double x = mirror.x + blur * dx, y = mirror.y + blur * dy;
      if (x * x + y * y >= 1) continue;
      if (const int c = cell({x, y, std::sqrt(1 - x * x - y * y)}); c >= 0)
        out.coherent[size_t(c)] += coherent / double(spots.size());
    }
    if (alpha_ <= 0) {  // a flat mirror: geometric optics is the specular direction itself
      if (const int c = cell(mirror); c >= 0) out.geometric[size_t(c)] += weight * reflectance(cosI);
      continue;
    }
    // Diffuse and geometric optics, by stratified slopes over two regions of the slope plane: the
    // NDF's core (|slope| < 2.5 α) from the NDF itself, the rest from a Gaussian widened to the
    // series' broadest terms (m up to g + 4√g + 4 widens the lobe by √(m/g); small g, a smooth
    // surface's halo, is much wider than the NDF). A partition, not a mixture: a deterministic
    // mixture of proposals this different loses the mass where the wide one has no stratum.
    const double widen = std::sqrt(std::max(1.0, (gSpec + 4 * std::sqrt(gSpec) + 4) / std::max(gSpec, 1e-12)));
    const double core = 2.5 * alpha_;
    const double g1i = smithG1(cosI, alpha_);
    for (const SlopeRegion& region :
         {SlopeRegion{alpha_, 0.0, core}, SlopeRegion{std::min(alpha_ * widen, std::max(alpha_, 4.0)), core, 1e300}}) {
      for (int i = 0; i < strata; ++i)
        for (int j = 0; j < strata; ++j) {
          const double r = region.radius((i + 0.5) / strata);
          const double phi = 2 * kPi * (j + 0.5) / strata;
          const Vec3 h = normalize(Vec3{-r * std::cos(phi), -r * std::sin(phi), 1.0});
          const double wiDotH = dot(wi, h);
          if (wiDotH <= 0) continue;
          const Vec3 wo = 2 * wiDotH * h - wi;
          if (wo.z <= 0) continue;
          const int c = cell(wo);
          if (c < 0) continue;
          // f cos θo / pdf(ωo), pdf(ωo) = pdf(h) / (4 ωi·h), pdf(h) = P22(slope) / cos³ θh, with the
          // NDF's D = P22 / cos⁴ θh written out once for both tables.
          const double common = weight * reflectance(wiDotH) * g1i * smithG1(wo.z, alpha_) * wiDotH /
                                (cosI * region.density(r) * strata * strata * kPi * alpha_ * alpha_ * h.z);
          const double vx = wi.x + wo.x, vy = wi.y + wo.y, vz = cosI + wo.z;
          const double g = std::pow(sigma_ * k * vz, 2), X = k * k * (vx * vx + vy * vy) * ell * ell / 4;
          out.geometric[size_t(c)] += common * std::exp(-r * r / (alpha_ * alpha_));
          out.diffuse[size_t(c)] += common * kirchhoffDiffuseSeries(g, X);
        }
    }
  }
  return out;
}

}  // namespace mbsdf
