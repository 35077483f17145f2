// Spectral -> colour (docs/physics.md §7): CIE 1931 2° XYZ, linear sRGB (D65, with Bradford adaptation
// from the equal-energy white E so that an equal-energy spectrum is neutral grey), and the paper's
// normalised CIE RGB (CIE 1931 RGB primaries, white E = (1, 1, 1)).
#pragma once
#include <array>
#include <vector>

namespace mbsdf {

using Colour3 = std::array<double, 3>;

// Colour-matching functions at a wavelength (nm), linearly interpolated; 0 outside 360–830 nm.
Colour3 cieXyzBar(double lambda_nm);
// Integral of the colour-matching functions over [a, b] nm (trapezoid on the 5 nm table).
Colour3 cieXyzIntegral(double a_nm, double b_nm);

// XYZ of a spectrum given at sample wavelengths: each sample stands for its band (Voronoi cell of
// the samples, the outer cells as wide as their inner half), Y normalised so that a spectrum of 1
// everywhere gives Y = 1.
class SpectrumToColour {
 public:
  explicit SpectrumToColour(std::vector<double> lambda_nm);
  // The conversion of values already in colour channels: each channel's contribution to XYZ (a
  // table stored in XYZ: the unit vectors; in linear sRGB: the columns of linearSrgbToXyz).
  static SpectrumToColour fromChannels(std::vector<Colour3> xyzPerChannel);
  Colour3 xyz(const double* values) const;
  Colour3 linearSrgb(const double* values) const;
  Colour3 cieRgb(const double* values) const;
  const std::vector<Colour3>& weights() const { return w_; }

 private:
  SpectrumToColour() = default;
  std::vector<double> lambda_;
  std::vector<Colour3> w_;  // per sample: band integral of x̄, ȳ, z̄ divided by Σ band ∫ȳ
};

Colour3 xyzToLinearSrgb(const Colour3& xyz);  // with E -> D65 Bradford adaptation
Colour3 linearSrgbToXyz(const Colour3& rgb);  // its inverse
Colour3 xyzToCieRgb(const Colour3& xyz);

}  // namespace mbsdf
