#include "job/effects_plan.h"

#include <stdexcept>

namespace mbsdf {
namespace {

constexpr std::pair<Effect, const char*> kEffectNames[] = {
    {Effect::Coherent, "coherent"},       {Effect::Multiple, "multiple"},  {Effect::Incoherent, "incoherent"},
    {Effect::Estimator, "estimator"},     {Effect::Lost, "lost"},          {Effect::Btdf, "btdf"},
    {Effect::Wavelengths, "wavelengths"}, {Effect::Incidence, "incidence"}};

template <typename T>
T required(const nlohmann::json& j, const char* key) {
  if (!j.contains(key)) throw std::invalid_argument(std::string("effects plan: no \"") + key + "\"");
  try {
    return j.at(key).get<T>();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("effects plan: \"") + key + "\": " + e.what());
  }
}

}  // namespace

std::string effectName(Effect e) {
  for (const auto& [effect, name] : kEffectNames)
    if (effect == e) return name;
  throw std::logic_error("effectName: unknown effect");
}

std::optional<Effect> effectFromName(const std::string& name) {
  for (const auto& [effect, n] : kEffectNames)
    if (name == n) return effect;
  return std::nullopt;
}

EffectDecision effectDecisionFromJson(const nlohmann::json& d) {
  EffectDecision out;
  const std::string name = required<std::string>(d, "effect");
  const std::optional<Effect> e = effectFromName(name);
  if (!e) throw std::invalid_argument("effects plan: unknown effect \"" + name + "\"");
  out.effect = *e;
  out.on = required<bool>(d, "on");
  out.reason = required<std::string>(d, "reason");
  for (const auto& [key, value] : d.items())
    if (key != "effect" && key != "on" && key != "reason") out.evidence[key] = value;
  return out;
}

const EffectDecision* EffectsPlan::find(Effect e) const {
  for (const auto& d : decisions)
    if (d.effect == e) return &d;
  return nullptr;
}

nlohmann::json EffectsPlan::toJson() const {
  nlohmann::json j;
  std::vector<std::string> names;
  for (Component c : components.list()) names.push_back(componentName(c));
  j["components"] = names;
  nlohmann::json ds = nlohmann::json::array();
  for (const auto& d : decisions) {
    nlohmann::json x = d.evidence;
    x["effect"] = effectName(d.effect);
    x["on"] = d.on;
    x["reason"] = d.reason;
    ds.push_back(x);
  }
  j["decisions"] = ds;
  j["tolerance"] = tolerance;
  j["coherence_length_um"] = coherenceLength_um;
  j["coherence_source"] = coherenceSource;
  if (sourceAngularDiameter_deg) j["source_angular_diameter_deg"] = *sourceAngularDiameter_deg;
  j["pilots"] = pilots;
  j["pilots_planned"] = pilotsPlanned;
  if (pilotBudget)
    j["pilot_budget"] = {{"fraction", pilotBudget->fraction},
                         {"computed_tiles", pilotBudget->computedTiles},
                         {"tiles", pilotBudget->tiles},
                         {"path_tiles_spent", pilotBudget->pathTilesSpent},
                         {"wave_tiles_spent", pilotBudget->waveTilesSpent}};
  j["pilot_paths"] = pilotPaths;
  j["pilot_tiles_kept"] = pilotTilesKept;
  j["pilot_seconds"] = pilotSeconds;
  if (waveTransmission) j["wave_transmission"] = *waveTransmission;
  if (lambda_nm) j["lambda_nm"] = *lambda_nm;
  if (waveEstimator) j["wave_estimator"] = waveEstimatorName(*waveEstimator);
  return j;
}

EffectsPlan EffectsPlan::fromJson(const nlohmann::json& j) {
  if (!j.is_object()) throw std::invalid_argument("effects plan: not a JSON object");
  EffectsPlan p;
  for (const auto& n : required<std::vector<std::string>>(j, "components")) {
    const std::optional<Component> c = componentFromName(n);
    if (!c) throw std::invalid_argument("effects plan: unknown component \"" + n + "\"");
    p.components.add(*c);
  }
  if (!j.contains("decisions") || !j["decisions"].is_array())
    throw std::invalid_argument("effects plan: no \"decisions\" array");
  for (const auto& d : j["decisions"]) p.decisions.push_back(effectDecisionFromJson(d));
  p.tolerance = required<double>(j, "tolerance");
  p.coherenceLength_um = required<double>(j, "coherence_length_um");
  p.coherenceSource = required<std::string>(j, "coherence_source");
  if (j.contains("source_angular_diameter_deg"))
    p.sourceAngularDiameter_deg = required<double>(j, "source_angular_diameter_deg");
  p.pilots = required<std::vector<int>>(j, "pilots");
  // Files written before the pilot budget existed have none of these three.
  p.pilotsPlanned = j.contains("pilots_planned") ? required<std::vector<int>>(j, "pilots_planned") : p.pilots;
  if (j.contains("pilot_budget")) {
    const nlohmann::json b = required<nlohmann::json>(j, "pilot_budget");
    p.pilotBudget = PilotBudgetUse{required<double>(b, "fraction"), required<int>(b, "computed_tiles"),
                                   required<double>(b, "tiles"), required<double>(b, "path_tiles_spent"),
                                   required<double>(b, "wave_tiles_spent")};
  }
  if (j.contains("pilot_paths")) p.pilotPaths = required<uint64_t>(j, "pilot_paths");
  if (j.contains("pilot_tiles_kept")) p.pilotTilesKept = required<bool>(j, "pilot_tiles_kept");
  p.pilotSeconds = required<double>(j, "pilot_seconds");
  if (j.contains("wave_transmission")) p.waveTransmission = required<bool>(j, "wave_transmission");
  if (j.contains("lambda_nm")) p.lambda_nm = required<std::vector<double>>(j, "lambda_nm");
  if (j.contains("wave_estimator")) p.waveEstimator = waveEstimatorKind(required<std::string>(j, "wave_estimator"));
  return p;
}

}  // namespace mbsdf
