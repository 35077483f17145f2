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
// The light a colour is seen under: the equal-energy spectrum E (the tables' own colour, as the paper
// renders), or CIE D65 (daylight, for colour differences as colour science states them).
enum class Illuminant { E, D65 };

// Integral of the colour-matching functions (times the illuminant's relative power for D65) over
// [a, b] nm (trapezoids on the 5 nm tables).
Colour3 cieXyzIntegral(double a_nm, double b_nm, Illuminant illuminant = Illuminant::E);
// The white point of an illuminant, Y = 1.
Colour3 whitePoint(Illuminant illuminant);

// XYZ of a spectrum given at sample wavelengths: each sample stands for its band (Voronoi cell of
// the samples, the outer cells as wide as their inner half), Y normalised so that a spectrum of 1
// everywhere gives Y = 1. Under D65 the spectrum is a reflectance lit by D65: a spectrum of 1 gives
// D65's white point.
class SpectrumToColour {
 public:
  explicit SpectrumToColour(std::vector<double> lambda_nm, Illuminant illuminant = Illuminant::E);
  // The conversion of values already in colour channels: each channel's contribution to XYZ (a
  // table stored in XYZ: the unit vectors; in linear sRGB: the columns of linearSrgbToXyz).
  static SpectrumToColour fromChannels(std::vector<Colour3> xyzPerChannel);
  Colour3 xyz(const double* values) const;
  Colour3 linearSrgb(const double* values) const;
  Colour3 cieRgb(const double* values) const;
  const std::vector<Colour3>& weights() const { return w_; }
  // Each sample's share of linear sRGB (linearSrgb is linear: the sum of these times the values).
  std::vector<Colour3> linearSrgbPerSample() const;

 private:
  SpectrumToColour() = default;
  std::vector<double> lambda_;
  std::vector<Colour3> w_;  // per sample: band integral of x̄, ȳ, z̄ divided by Σ band ∫ȳ
};

Colour3 xyzToLinearSrgb(const Colour3& xyz);  // with E -> D65 Bradford adaptation
Colour3 linearSrgbToXyz(const Colour3& rgb);  // its inverse
Colour3 xyzToCieRgb(const Colour3& xyz);
// XYZ seen under E to the corresponding colour under D65 (Bradford), for tables stored in colour.
Colour3 adaptXyzEToD65(const Colour3& xyz);

}  // namespace mbsdf
