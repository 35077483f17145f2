// Materials of the lower medium (docs/physics.md §1, §7). A closed set of value types:
//  - Conductor: tabulated complex index (Al, Ag, Au, Cu; Palik via pbrt, see material_data.cpp),
//    a constant eta + i k, or the perfect conductor (reflectance 1, the white-furnace "mirror").
//  - Dielectric: constant real index or a Sellmeier formula (BK7 built in: Schott catalogue
//    N-BK7 coefficients, lambda in µm).
// The upper medium has the real index outsideIor.
#pragma once
#include <complex>
#include <string>
#include <variant>
#include <vector>

#include "optics/fresnel.h"

namespace mbsdf {

struct TabulatedIndex {
  std::string name;
  std::vector<double> lambda_nm, eta, k;
};
struct ConstantIndex {
  double eta = 1.5, k = 0.0;
};
struct PerfectConductor {};
struct SellmeierIndex {
  std::string name;
  double B[3], C_um2[3];
};

struct Conductor {
  std::variant<TabulatedIndex, ConstantIndex, PerfectConductor> index;
};
struct Dielectric {
  std::variant<ConstantIndex, SellmeierIndex> index;
};

struct Material {
  std::variant<Conductor, Dielectric> model;
  double outsideIor = 1.0;

  bool isConductor() const { return std::holds_alternative<Conductor>(model); }
  bool isPerfectConductor() const;
  // No absorption: a dielectric with a real index (the geometric tracer ignores any imaginary part)
  // or a perfect conductor. For these reflected + transmitted energy must be 1.
  bool lossless() const;
  // True when every wavelength follows the same path (conductors: Fresnel only changes weights;
  // dielectrics: only with a constant index).
  bool directionsIndependentOfLambda() const;
  // Wavelength range (nm) where the index is defined; [0, inf) for formulas.
  std::pair<double, double> validRange_nm() const;
  // Complex index of the lower medium at a wavelength (µm). Throws std::out_of_range outside the
  // table; the job validation checks the range first and names the key.
  Complex ior(double lambda_um) const;
  // The index at each wavelength (µm) as the estimators use it: 0 for a perfect conductor, which
  // has none.
  std::vector<Complex> iorAt(const std::vector<double>& lambda_um) const;
  std::string describe() const;
};

// Built-in materials by name: "Al", "Ag", "Au", "Cu", "mirror" (perfect conductor), "BK7".
// Returns false for an unknown name.
bool builtinMaterial(const std::string& name, Material* out);
std::vector<std::string> builtinMaterialNames();

}  // namespace mbsdf
