// Exports one BSDF slice (a model = sum of components) as a float EXR on the paper's disk
// projection (x = sin θ cos φ, y = sin θ sin φ; Falster et al. 2020, Sec. 6) and as CSV per exit bin.
#pragma once
#include <string>
#include <vector>

#include "core/colour.h"
#include "io/bsdf_file.h"
#include "io/png_image.h"

namespace mbsdf {

struct SliceRequest {
  double theta_deg = 0, phi_deg = 0;
  std::string model = "GM";            // GS | GM | WS | WM | a component name
  bool transmission = false;           // lower hemisphere of exit directions
  bool both = false;                   // reflection (left) and transmission (right) side by side
  int size = 256;                      // image height; width = size (2 size with `both`)
  std::string style = "true";          // PNG: "true" colour (CIE 1931 -> sRGB) or "false" colour (log2 scale)
  double exposure = 1.0;               // true colour: multiplies the linear sRGB values
  double log2Min = -10, log2Max = 10;  // false colour: the range of log2(f) (paper Fig. 5: −10 … 10)
};

// Throws InputError naming --log2-min/--log2-max when a false-colour request has no range.
void checkFalseColourRange(const SliceRequest& req);

// Sum of the model's components that the file holds (missing ones are an error); with stdError, its
// per-bin standard error (left empty where the file keeps errors per slice only).
std::vector<double> modelSlice(const BsdfFileReader& file, const std::string& model, int incidence,
                               std::vector<double>* stdError = nullptr);

// The models among GS, GM, WS, WM whose components the file holds, in that order.
std::vector<std::string> availableModels(const BsdfFileReader& file);

// Writes by extension, on the paper's disk projection (x = sin θ cos φ, y = sin θ sin φ, +y up):
//  .exr: float channels "<λ>nm" per wavelength, "mean" (over λ), "R", "G", "B" (linear sRGB of the
//        spectrum through the CIE 1931 matching functions) and "Y" (these four only when a
//        wavelength is visible);
//  .png: true colour (sRGB, gamma-encoded, × exposure; visible wavelengths needed) or false colour:
//        log2 of the spectral mean on [log2Min, log2Max] with its scale along the bottom (the paper's
//        Fig. 5 scale; colour_bar.h: ticks at decades of f, their values and the unit 1/sr);
//  .csv: one row per exit bin: f and its standard error per wavelength, then (when a wavelength
//        is visible) X, Y, Z and linear sRGB of the spectrum, and the standard errors of X, Y, Z
//        (Σ_λ w_λ se_λ: an upper bound whatever the correlation between wavelengths).
// A table stored in colour (storage profile) has its channels where the wavelengths were: "stored.X"
// … in the EXR, f_X … in the CSV; its false colour shows log2 Y.
// Returns the incidence index used.
int exportSlice(const BsdfFileReader& file, const SliceRequest& req, const std::string& outPath);

// The PNG picture of a slice (the .png branch of exportSlice) for incidence index `inc`.
RgbImage renderSliceImage(const BsdfFileReader& file, const SliceRequest& req, int inc);

// The false-colour map (viridis) at t in [0, 1], and the sRGB transfer function.
Colour3 falseColour(double t);
double srgbEncode(double linear);

}  // namespace mbsdf
