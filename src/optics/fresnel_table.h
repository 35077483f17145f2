// A conductor's unpolarised Fresnel reflectance F(cos θ) for one wavelength, tabulated on
// kIntervals equal intervals of cos θ in [0, 1] and interpolated linearly. The complex square root
// and division of each exact evaluation (optics/fresnel.h) were a fifth of a conductor's random
// walk and a tenth of its path tracing. Linear interpolation is off by at most h²/8 max|F''| with
// h = 1/kIntervals: below 1e-6 for the built-in metals over the visible (tested against the exact
// formula in sweeps over cos θ). Dielectrics are not tabulated: their critical angle has an
// infinite slope.
#pragma once
#include <algorithm>
#include <vector>

#include "optics/fresnel.h"
#include "optics/material.h"

namespace mbsdf {

class ConductorFresnelTable {
 public:
  static constexpr int kIntervals = 4096;
  ConductorFresnelTable(double n1, Complex n2);
  // cosTheta_i in [0, 1]; anything else (a rounding past 1, or a NaN) is clamped into it, so that
  // the index can never leave the table.
  double operator()(double cosTheta_i) const {
    const double x = (cosTheta_i > 0 ? std::min(cosTheta_i, 1.0) : 0.0) * kIntervals;
    const int i = std::min(int(x), kIntervals - 1);
    return f_[size_t(i)] + (x - i) * (f_[size_t(i) + 1] - f_[size_t(i)]);
  }

 private:
  std::vector<double> f_;
};

// One table per wavelength for a conductor that is not perfect (ior: the lower medium's index per
// wavelength); empty otherwise (perfect conductors reflect 1, dielectrics are evaluated exactly).
std::vector<ConductorFresnelTable> conductorFresnelTables(const Material& material, const std::vector<Complex>& ior);

}  // namespace mbsdf
