// Image-based lighting for the material preview: an equirectangular (latitude–longitude) map of
// radiance in linear sRGB, z up. Pixel (column c, row r) of a W × H map covers the azimuths
// φ ∈ [c, c + 1)·2π/W (from +x towards +y) and the polar angles θ ∈ [r, r + 1)·π/H from +z, and its
// radiance is constant there. Sampling picks a pixel with probability ∝ (its luminance + a floor)
// × its solid angle, then a direction uniformly in solid angle within it (the piecewise-constant 2D
// distribution of Pharr, Jakob & Humphreys 2016, pbrt-v3 §13.6.7 and §14.2.4, here with exact pixel
// solid angles so that a constant pixel is sampled with zero variance).
#pragma once
#include <string>
#include <vector>

#include "core/colour.h"
#include "core/vecmath.h"

namespace mbsdf {

class Environment {
 public:
  // rgb: width × height × 3 linear sRGB radiances, row 0 at the zenith; finite and >= 0
  // (std::invalid_argument otherwise, naming `what`).
  Environment(int width, int height, std::vector<float> rgb, std::string what);
  // The built-in environments, lit from the side of a preview camera at φ = −90° (render/preview.h):
  // "studio" (a grey room lit by three soft boxes: a key light of radiance 12 centred at θ = 40°,
  // φ = 235°, front left; a fill of 3 at θ = 60°, φ = 320°, front right; a strip of 5 overhead
  // along φ = 120°) and "sky" (a blue sky brightening towards the horizon, a sun of radiance 2000
  // and 2.5° radius at θ = 35°, φ = 240°, a grey-brown ground). InputError for another name.
  static Environment builtIn(const std::string& name, int width = 1024);
  // An equirectangular EXR with channels R, G, B (or one channel, grey). InputError naming the file.
  static Environment fromExr(const std::string& path);

  Colour3 radiance(const Vec3& w) const;
  struct Sample {
    Vec3 w;      // unit direction towards the light
    Colour3 L;   // radiance along it
    double pdf;  // per unit solid angle
  };
  Sample sample(double u1, double u2) const;
  double pdf(const Vec3& w) const;
  // The pixel a direction falls in (column, row).
  std::pair<int, int> pixelOf(const Vec3& w) const;
  // The direction at the centre of pixel (column, row) in solid angle.
  Vec3 pixelCentre(int column, int row) const;
  int width() const { return width_; }
  int height() const { return height_; }
  const std::string& name() const { return name_; }

 private:
  int width_, height_;
  std::vector<float> rgb_;
  std::string name_;
  std::vector<double> rowCdf_;     // H + 1 entries, rowCdf_[H] = 1
  std::vector<double> pixelCdf_;   // per row W + 1 entries, normalised within the row
  std::vector<double> pixelProb_;  // W × H: probability of each pixel
  std::vector<double> cosEdge_;    // H + 1: cos θ of the row edges
  double rowSolidAngle(int r) const { return (cosEdge_[r] - cosEdge_[r + 1]) * 2 * kPi / width_; }
};

}  // namespace mbsdf
