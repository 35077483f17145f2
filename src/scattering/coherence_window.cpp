#include "scattering/coherence_window.h"

#include <cmath>

#include "core/vecmath.h"

namespace mbsdf {

CoherenceWindow::CoherenceWindow(double sigma_um, double sizeX, double sizeY, bool periodic)
    : sigma_(sigma_um), sizeX_(sizeX), sizeY_(sizeY) {
  if (sigma_ <= 0) {
    w2_ = sizeX * sizeY;
    return;
  }
  if (periodic) {
    // Copies a with |a L| <= 4σ + L/2 cover ±4σ around the centre.
    kx_ = std::max(0, int(std::ceil(4 * sigma_ / sizeX - 0.5)));
    ky_ = std::max(0, int(std::ceil(4 * sigma_ / sizeY - 0.5)));
  }
  // ∫ over [−(K+½)L, (K+½)L] of exp(−u²/σ²) du = σ √π erf((K+½)L/σ), per axis.
  auto axis = [&](double L, int K) { return sigma_ * std::sqrt(kPi) * std::erf((K + 0.5) * L / sigma_); };
  w2_ = axis(sizeX, kx_) * axis(sizeY, ky_);
}

double CoherenceWindow::amplitude(double x, double y) const {
  if (sigma_ <= 0) return 1.0;
  return std::exp(-(x * x + y * y) / (2 * sigma_ * sigma_));
}

Complex CoherenceWindow::axisFactor(double x, double q, double L, int K) const {
  // Σ_a exp(−(x + aL)²/(2σ²)) e^{i q a L}; the phase steps by e^{i q L} (one sincos per axis).
  const double inv2s2 = 1.0 / (2 * sigma_ * sigma_);
  const Complex step = std::polar(1.0, q * L);
  Complex phase = std::polar(1.0, -q * L * K), sum = 0;
  for (int a = -K; a <= K; ++a) {
    double u = x + a * L;
    sum += std::exp(-u * u * inv2s2) * phase;
    phase *= step;
  }
  return sum;
}

Complex CoherenceWindow::copyFactor(double x, double y, double qx, double qy) const {
  if (sigma_ <= 0) return 1.0;
  return axisFactor(x, qx, sizeX_, kx_) * axisFactor(y, qy, sizeY_, ky_);
}

}  // namespace mbsdf
