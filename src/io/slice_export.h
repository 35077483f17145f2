// Exports one BSDF slice (a model = sum of components) as a float EXR on the paper's disk
// projection (x = sin θ cos φ, y = sin θ sin φ; paper Sec. 6) and as CSV per exit bin.
#pragma once
#include <string>
#include <vector>

#include "io/bsdf_file.h"

namespace mbsdf {

struct SliceRequest {
  double theta_deg = 0, phi_deg = 0;
  std::string model = "GM";  // GS | GM | WS | WM | a component name
  bool transmission = false; // lower hemisphere of exit directions
  int size = 256;            // EXR width = height
};

// Sum of the model's components that the file holds (missing ones are an error).
std::vector<double> modelSlice(const BsdfFileReader& file, const std::string& model, int incidence,
                               std::vector<double>* stdError = nullptr);

// Writes by extension: .exr (disk projection, one channel per wavelength "<λ>nm" plus "mean"),
// .csv (one row per exit bin). Returns the incidence index used.
int exportSlice(const BsdfFileReader& file, const SliceRequest& req, const std::string& outPath);

}  // namespace mbsdf
