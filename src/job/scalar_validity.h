// Where the scalar model can be trusted, judged from the geometry, the material and the incidence
// before anything runs. The rigorous validation (docs/validation.md, `scripts/validate-fdtd`: Meep
// FDTD against the `exact` estimator, both polarisations averaged) measured the largest error of a
// diffraction order's efficiency on binary gratings per material class (glass n = 1.5 lit from the
// air or from inside; aluminium), incidence angle, period/λ and depth/λ, for WS (single scattering)
// and WM (with geometric multiple scattering). A periodic patch is placed on that map at every
// incidence of the job and its shortest and longest wavelengths: between validated cases the figure
// is interpolated (linear in angle and depth, in log period); past them on their safe side (longer
// periods, shallower ridges) the nearest stands in; past the largest validated angle, below the
// shortest period or above the deepest ridge nothing does and the model's error there is unknown.
// Smooth profiles usually do better than binary ones. The computed energy balance
// (/stats/energy_balance) is the estimate for the job's own structure; this is the one a user sees
// before paying for it.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace mbsdf {

struct Job;

enum class ValidityMaterial { Dielectric, Conductor };
enum class ValiditySide { Outside, Inside };  // lit from the upper medium, or from inside a dielectric
enum class ScalarModel { Ws, Wm };            // single scattering; with geometric multiple scattering

// One validated binary grating: the largest |Δ| of any order's efficiency (FDTD − scalar model),
// either side of the surface, for WS and for WM.
struct ValidatedCase {
  ValidityMaterial material;
  ValiditySide side;
  double theta_deg, periodOverLambda, depthOverLambda;
  double maxDeltaWs, maxDeltaWm;
};
// Generated from docs/validation/fdtd.json by `scripts/validate-fdtd --emit-map` (a test holds the
// two together).
const std::vector<ValidatedCase>& validatedCases();

struct ScalarValidity {
  bool applies = false;  // a periodic patch under a coherence window (diffraction orders)
  // Where the job sits worst: the incidence, side, wavelength ratios and the map's figure there
  // (empty outside the validated cases).
  ValidityMaterial material = ValidityMaterial::Dielectric;
  ValiditySide side = ValiditySide::Outside;
  double theta_deg = 0, periodOverLambda = 0, heightOverLambda = 0;
  ScalarModel model = ScalarModel::Ws;  // WM where the job computes multiple scattering
  std::optional<double> maxOrderError;
  std::optional<double> singleScatteringError;  // WS's figure at the same place (for WM: what interreflection adds)
  std::string note;                             // one line for plan and the run log
  bool beyondTolerance = false;
};

ScalarValidity scalarValidity(const Job& job);
// "scalar model: …" where the map's figure is beyond the tolerance or the job lies outside the map:
// the run's first and closing warnings, `check`, and the output's root attribute `scalar_model`.
std::optional<std::string> scalarModelCaveat(const Job& job);

// The map's figure at one (material, side, θ, period/λ, depth/λ); empty where the validated cases
// do not reach.
std::optional<double> validatedError(ValidityMaterial material, ValiditySide side, double theta_deg,
                                     double periodOverLambda, double depthOverLambda, ScalarModel model);

nlohmann::json toJson(const ScalarValidity& v);

}  // namespace mbsdf
