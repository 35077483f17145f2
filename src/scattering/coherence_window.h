// The coherence window of PHYSICS.md §5 (paper Sec. 4): a Gaussian on the amplitude,
// w(x) = exp(−|x_xy − c|² / (2σ²)), σ = δc / 6 for a coherence length δc (sunlight: 50 µm), centred
// on the patch. On a periodic patch the integral runs over the tiled copies within ±4σ of the
// centre; the copy sum is separable in x and y and is evaluated per point as
//   C(x, q) = Σ_a Σ_b w(x + s_ab) e^{i q·s_ab},  s_ab = (a Lx, b Ly).
// W2 = ∫ w² dA_xy over the same copies normalises the power (PHYSICS.md §5). Without a window
// (σ <= 0), w = 1 over exactly one copy and W2 = Lx Ly.
#pragma once
#include "optics/fresnel.h"

namespace mbsdf {

class CoherenceWindow {
 public:
  CoherenceWindow(double sigma_um, double sizeX, double sizeY, bool periodic);
  static CoherenceWindow fromCoherenceLength(double coherenceLength_um, double sizeX, double sizeY, bool periodic) {
    return CoherenceWindow(coherenceLength_um > 0 ? coherenceLength_um / 6.0 : 0.0, sizeX, sizeY, periodic);
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

 private:
  Complex axisFactor(double x, double q, double L, int K) const;
  double sigma_, sizeX_, sizeY_, w2_;
  int kx_ = 0, ky_ = 0;
};

}  // namespace mbsdf
