#include "scattering/coherence_window.h"

#include <cmath>

// libcerf's Faddeeva function w(x + iy), real and imaginary parts (cerf.h declares them too, but
// includes the C <complex.h>, whose macro I breaks C++ sources compiled in the same unit).
extern "C" {
double re_w_of_z(double x, double y);
double im_w_of_z(double x, double y);
}

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

// ∫_{−a}^{a} e^{−u²/(2σ²)} e^{iqu} du, a = (K+½)L, = σ√(2π) e^{−y²} Re erf(b + iy) with
// b = a/(σ√2), y = qσ/√2 (completing the square). erf(b + iy) grows as e^{y²}: written with the
// Faddeeva function w(z) = e^{−z²} erfc(−iz) (Poppe & Wijers 1990; libcerf) as
//   e^{−y²} erf(b + iy) = e^{−y²} − e^{−b²} e^{−2iby} w(−y + ib),
// where w is bounded in the upper half-plane, so nothing overflows at large q.
double CoherenceWindow::axisIntegral(double q, double L, int K) const {
  if (sigma_ <= 0) return std::abs(q * L) < 1e-8 ? L * (1 - q * q * L * L / 24) : 2 * std::sin(0.5 * q * L) / q;
  const double a = (K + 0.5) * L, b = a / (sigma_ * std::sqrt(2.0)), y = q * sigma_ / std::sqrt(2.0);
  const double wr = re_w_of_z(-y, b), wi = im_w_of_z(-y, b);
  // Re[e^{−2iby} (wr + i wi)] = cos(2by) wr + sin(2by) wi.
  const double tail = std::exp(-b * b) * (std::cos(2 * b * y) * wr + std::sin(2 * b * y) * wi);
  return sigma_ * std::sqrt(2 * kPi) * (std::exp(-y * y) - tail);
}

double CoherenceWindow::planeIntegral(double qx, double qy) const {
  return axisIntegral(qx, sizeX_, kx_) * axisIntegral(qy, sizeY_, ky_);
}

Complex CoherenceWindow::copyFactor(double x, double y, double qx, double qy) const {
  if (sigma_ <= 0) return 1.0;
  return axisFactor(x, qx, sizeX_, kx_) * axisFactor(y, qy, sizeY_, ky_);
}

}  // namespace mbsdf
