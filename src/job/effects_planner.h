// The effects planner behind `components = "auto"`: which components a scene calls for, decided
// from physics and short pilot runs, never from the geometry's name (issue "simulate only the
// effects a scene calls for"). Each decision carries its reason and the pilot figure it rests on:
//  - coherent: always (the geometric single scattering every model starts from).
//  - multiple: on when the pilot's multiply scattered energy Σ f·Ω⊥ (+ 3 standard errors) of any
//    pilot slice and wavelength exceeds [scene] tolerance: leaving it out changes that slice by
//    exactly that energy.
//  - incoherent (diffraction): from the pilot's WS − GS difference at the job's grid and coherence,
//    L1 = Σ_b |f_ws − f_coherent| Ω⊥, less the expected L1 of pure noise √(2/π) Σ_b s_b Ω⊥, ± 2
//    standard deviations √Σ_b (s_b Ω⊥)²: off when the upper estimate is below [scene] tolerance, on
//    when the lower one is above. When the pilot cannot decide (Monte Carlo noise straddles the
//    tolerance, as for rough surfaces with the `area` estimator) and the features are much larger
//    than λ (correlation length √2 σ_h/slope >= 5 λ), a Kirchhoff-theory estimate decides: the
//    specular spike 2 e^{−g}, g = (4π σ_h cos θi / λ)² the Rayleigh roughness, plus the blur of
//    the geometric lobe (width 2 × rms slope) by the window's diffraction (sd λ/(2√2 π σ_w)),
//    (blur/lobe)². Otherwise diffraction stays on (the safe side).
//  - lost: only on request (a diagnostic, not part of any model).
//  - BTDF: a conductor transmits nothing; a dielectric's transmission is traced with its
//    reflection.
//  - wavelengths: whether paths are shared by all wavelengths (only Fresnel depends on λ).
// Pilots: collimated beams through the bin centres of the job's incidence directions closest to
// normal, the median and the most grazing one.

#pragma once
#include <nlohmann/json.hpp>

#include "job/job.h"

namespace mbsdf {

struct EffectsPilotOptions {
  uint64_t paths = 20000;        // per pilot slice (at most the job's paths_per_slice)
  int waveSamplesPerBin = 1024;  // per exit bin (at least the job's wave_samples_per_bin)
};

// Pilot incidence indices (sorted, distinct): the incidence closest to normal, the median and the
// most grazing one. Used by the effects planner and by `plan`'s cost pilot.
std::vector<int> pilotIncidences(const Job& job);

// The decisions as JSON: {"components": [...], "decisions": [{"effect", "on", "reason", ...}],
// "tolerance", "coherence_length_um", "coherence_source", "pilots", "pilot_seconds"}.
nlohmann::json planEffects(const Job& job, const EffectsPilotOptions& options = {});
// Sets job.components and job.effectsPlan from a plan (the same on every rank).
void applyEffectsPlan(Job& job, const nlohmann::json& plan);
// One line per decision: "multiple     on   reason".
std::string formatEffects(const nlohmann::json& plan);

}  // namespace mbsdf
