// The coherence window of docs/physics.md §5 (Falster et al. 2020, Sec. 4): a Gaussian on the amplitude,
// w(x) = exp(−|x_xy − c|² / (2σ²)), σ = δc / 6 for a coherence length δc (sunlight: 50 µm), centred
// on the patch. On a periodic patch the integral runs over the tiled copies within ±4σ of the
// centre; the copy sum is separable in x and y and is evaluated per point as
//   C(x, q) = Σ_a Σ_b w(x + s_ab) e^{i q·s_ab},  s_ab = (a Lx, b Ly).
// W2 = ∫ w² dA_xy over the same copies normalises the power (docs/physics.md §5). Without a window
// (σ <= 0), w = 1 over exactly one copy and W2 = Lx Ly.
#pragma once
#include <algorithm>
#include <cmath>

#include "core/vecmath.h"
#include "optics/fresnel.h"

namespace mbsdf {

// The coherence length of light from a uniform disk source (van Cittert–Zernike): the complex degree
// of coherence between two points a distance d apart is γ(d) = 2 J1(v)/v, v = π θ d / λ̄, for a
// source of angular diameter θ at mean wavelength λ̄ (Born & Wolf, Principles of Optics, §10.4.2).
// The window model above is coherent over a Gaussian amplitude w, whose autocorrelation gives the
// coherence function exp(−d²/(4σ²)). σ is chosen so that both have the same coherence area,
// ∫|γ|² dA = λ̄²/(π α²) (α = θ/2; Mandel & Wolf §4.4) = 2πσ², which also matches their curvature at
// d = 0 (γ ≈ 1 − v²/8): σ = √2 λ̄ / (π θ), and δc = 6σ as everywhere else (docs/physics.md §5).
// The sun (θ = 0.533°) then gives δc = 159.7 µm at 550 nm; the paper's 50 µm for sunlight is a
// literature coherence width used directly as δc (a 3x narrower window): give
// coherence_length_um = 50 to reproduce it.
inline constexpr double kSunAngularDiameter_deg = 0.533;
// The coherence length δc is 6σ of the window (docs/physics.md §5), in one place.
inline constexpr double kCoherenceLengthPerSigma = 6.0;
// The window's σ for a coherence length δc (0: no window).
inline double windowSigma(double coherenceLength_um) {
  return coherenceLength_um > 0 ? coherenceLength_um / kCoherenceLengthPerSigma : 0.0;
}
inline double coherenceLengthOfDiskSource(double angularDiameter_rad, double meanLambda_um) {
  const double sigma = std::sqrt(2.0) * meanLambda_um / (kPi * angularDiameter_rad);
  return kCoherenceLengthPerSigma * sigma;
}

// Whether the grating orders' lobes (standard deviation 1/(√2 σ n k0) in the xy plane of ωo) stay
// apart: 2πσ/L >= 4 puts neighbouring lobes >= 5.7 standard deviations apart (the `orders`
// regime); below it they overlap into speckle.
inline bool orderLobesSeparate(double sigma, double sizeX, double sizeY) {
  return sigma > 0 && 2 * kPi * sigma / std::max(sizeX, sizeY) >= 4.0;
}

class CoherenceWindow {
 public:
  CoherenceWindow(double sigma_um, double sizeX, double sizeY, bool periodic);
  static CoherenceWindow fromCoherenceLength(double coherenceLength_um, double sizeX, double sizeY, bool periodic) {
    return CoherenceWindow(windowSigma(coherenceLength_um), sizeX, sizeY, periodic);
  }
  bool active() const { return sigma_ > 0; }
  double sigma() const { return sigma_; }
  double w2() const { return w2_; }
  int copiesX() const { return kx_; }  // copies on each side of the centre copy
  int copiesY() const { return ky_; }
  // w(x) summed over the copies with their phases; (x, y) on the base patch, (qx, qy) the
  // tangential part of k1 − k2.
  Complex copyFactor(double x, double y, double qx, double qy) const;
  // The window amplitude at a point of the plane (no copies).
  double amplitude(double x, double y) const;
  // ∫ w(x) e^{i q·x} dA_xy over the plane that the copies cover ([−(K+½)L, (K+½)L] per axis;
  // the patch alone without a window): what copyFactor(x, y, q) e^{i q·x} integrates to over the
  // patch. Real, since the window and its domain are symmetric about the centre.
  double planeIntegral(double qx, double qy) const;

 private:
  Complex axisFactor(double x, double q, double L, int K) const;
  double axisIntegral(double q, double L, int K) const;
  double sigma_, sizeX_, sizeY_, w2_;
  int kx_ = 0, ky_ = 0;
};

}  // namespace mbsdf
