// `microbsdf compare-smith`: how far the Smith microflake model is from explicit geometry with the
// same NDF (docs/physics.md §9, last item). Builds a periodic Gaussian heightfield whose facet
// slope distribution is the Beckmann NDF of roughness α (Gaussian correlation, heights rescaled so
// the measured rms facet slope is exactly α), traces it with the explicit path tracer and runs the
// microflake walk with Beckmann(α), both with the same material, wavelength, grid and collimated
// incidence, and reports per component the albedo and the lobe L1 distance Σ_b |Δf| Ω⊥.
#pragma once
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace mbsdf {

struct CompareSmithOptions {
  double alpha = 0.3;
  std::string material = "Al";
  double lambda_nm = 550;
  std::vector<double> theta_deg = {0, 30, 60, 80};
  uint64_t paths = 200000;
  double correlation_um = 1.0;  // ℓ of the Gaussian correlation exp(−r²/ℓ²)
  double size_um = 32.0;        // patch side (periodic)
  double texel_um = 0.125;      // heightfield spacing
  int nTheta = 18, nPhi = 36;   // tabulation grid
  uint64_t seed = 1;
};

// Runs the comparison; the JSON holds the measured mesh roughness, and per incidence angle and
// component the two albedos with standard errors, the L1 distance, and the plane-of-incidence lobes.
nlohmann::json compareSmith(const CompareSmithOptions& options);
std::string formatCompareSmith(const nlohmann::json& result);

}  // namespace mbsdf
