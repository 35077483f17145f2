// Where the scalar model can be trusted, judged from the geometry alone before anything runs: the
// rigorous validation (docs/validation.md, `scripts/validate-fdtd`: Meep FDTD against the `exact`
// estimator on binary glass gratings, both sides, both polarisations) measured the largest error of
// a diffraction order's efficiency per period/λ and depth/λ. A periodic patch is placed on that map
// on its unsafe side (the validated period at or below its own, the validated depth at or above its
// own), at the job's shortest and longest wavelengths. The map is for binary gratings at normal
// incidence; smooth profiles usually do better, oblique light worse. The computed energy balance
// (/stats/energy_balance) is the estimate for the job's own structure; this is the one a user sees
// before paying for it.
#pragma once
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace mbsdf {

struct Job;

struct ScalarValidity {
  bool applies = false;                               // a periodic patch under a coherence window (diffraction orders)
  double periodOverLambda = 0, heightOverLambda = 0;  // at the wavelength that places it worst
  std::optional<double> maxOrderError;                // the map's value; empty outside the map
  std::string note;                                   // one line for plan and the run log
  bool beyondTolerance = false;
};

ScalarValidity scalarValidity(const Job& job);

// The map itself: the largest |Δ| per validated period/λ (rows) and depth/λ (columns), taken from
// docs/validation/fdtd.json (a test holds the two together).
struct ValidityMap {
  static constexpr int kRows = 4, kCols = 4;
  double periodOverLambda[kRows];
  double depthOverLambda[kCols];
  double maxDelta[kRows][kCols];
};
const ValidityMap& validityMap();
nlohmann::json toJson(const ScalarValidity& v);

}  // namespace mbsdf
