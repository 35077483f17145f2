// The effects planner's result as a value (effects_planner.h makes it from physics and pilots): the
// components to compute, one decision per effect with its reason and the figures it rests on, the
// pilots run and what they cost, and what else the run changes (wavelengths, the wave estimator,
// the wave term's transmitted bins). Its JSON form is what the output file records (attribute
// `effects_plan`), `plan --json` and `info --json` print, and every rank receives from rank 0.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scattering/components.h"
#include "scattering/wave_estimator_kind.h"

namespace mbsdf {

// What a decision is about: a component (coherent, multiple, incoherent = diffraction, lost), the
// wave estimator, the BTDF, the wavelengths computed, the incidences the renderer looks up.
enum class Effect { Coherent, Multiple, Incoherent, Estimator, Lost, Btdf, Wavelengths, Incidence };
std::string effectName(Effect e);
std::optional<Effect> effectFromName(const std::string& name);

struct EffectDecision {
  Effect effect = Effect::Coherent;
  bool on = false;
  std::string reason;
  // The figures the decision rests on, named as in the JSON (pilot_energy, pilot_upper,
  // kirchhoff_estimate, single_bounce_below_deg, candidates, …; docs/estimators.md): they differ
  // from effect to effect, so they stay a JSON object.
  nlohmann::json evidence = nlohmann::json::object();
};

// The pilots' work against [effects] pilot_budget, in tiles' work (effects_planner.h).
struct PilotBudgetUse {
  double fraction = 0;    // [effects] pilot_budget
  int computedTiles = 0;  // the job's tiles after the symmetry reduction
  double tiles = 0;       // fraction × computedTiles
  double pathTilesSpent = 0, waveTilesSpent = 0;
};

struct EffectsPlan {
  ComponentSet components;
  std::vector<EffectDecision> decisions;
  double tolerance = 0, coherenceLength_um = 0;
  std::string coherenceSource;
  std::optional<double> sourceAngularDiameter_deg;
  std::vector<int> pilots, pilotsPlanned;     // incidence indices run, and those planned before the budget
  std::optional<PilotBudgetUse> pilotBudget;  // (none in files written before the budget existed)
  uint64_t pilotPaths = 0;
  // Whether the geometric pilots traced their incidences as the job does (its exact directions or
  // averaged over its bins, its seed): each is then the first pilotPaths paths of that tile, which
  // the run keeps instead of tracing them again (tile_computer.h). False in older files.
  bool pilotTilesKept = false;
  double pilotSeconds = 0;
  // What the run changes besides its components.
  std::optional<bool> waveTransmission;          // false: the wave term skips the transmitted bins
  std::optional<std::vector<double>> lambda_nm;  // the wavelengths computed (colour = "rgb")
  std::optional<WaveEstimatorKind> waveEstimator;

  // The decision on e, or null.
  const EffectDecision* find(Effect e) const;
  nlohmann::json toJson() const;
  // Throws std::invalid_argument naming what is missing or malformed.
  static EffectsPlan fromJson(const nlohmann::json& j);
};

// A decision from its JSON form {"effect", "on", "reason", figures…}.
EffectDecision effectDecisionFromJson(const nlohmann::json& d);

}  // namespace mbsdf
