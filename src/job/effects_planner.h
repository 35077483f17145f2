// The effects planner behind `components = "auto"`: which components a scene calls for, decided
// from physics and short pilot runs, never from the geometry's name. Each decision carries its
// reason and the pilot figure it rests on:
//  - coherent: always (the geometric single scattering every model starts from).
//  - multiple: on when the pilot's multiply scattered energy Σ f·Ω⊥ (+ 3 standard errors) of any
//    pilot slice and wavelength exceeds [scene] tolerance: leaving it out changes that slice by
//    exactly that energy.
//  - incoherent (diffraction): from the pilot's WS − GS difference at the renderer's angular
//    resolution ([scene] angular_resolution_deg: bins pooled into cells of that size, default the
//    job's bins) and the coherence, L1 = Σ_cells |Σ_b∈cell (f_ws − f_coherent) Ω⊥|, less the expected
//    L1 of pure noise √(2/π) Σ_cells s_cell, ± 2 standard deviations √Σ s_cell² (s_cell² =
//    Σ_b∈cell (s_b Ω⊥)²): off when the upper estimate is below [scene] tolerance, on
//    when the lower one is above. When the pilot cannot decide (Monte Carlo noise straddles the
//    tolerance, as for rough surfaces with the `area` estimator) and the features are much larger
//    than λ (correlation length √2 σ_h/slope >= 5 λ), a Kirchhoff-theory estimate decides: the
//    specular spike 2 e^{−g}, g = (4π σ_h cos θi / λ)² the Rayleigh roughness, plus the blur of
//    the geometric lobe (width 2 × rms slope) by the window's diffraction (sd λ/(2√2 π σ_w)),
//    (blur/lobe)², at the job's most grazing incidence and longest wavelength. Otherwise
//    diffraction stays on (the safe side). An "off" from the pilots is verified on every tile
//    (tile_computer.h): a tile a pilot ran as the job does has its figure, any other computes its
//    wave term and keeps it when its upper estimate exceeds the tolerance.
//  - lost: only on request (a diagnostic, not part of any model).
//  - BTDF: a conductor transmits nothing; a dielectric's transmission is traced with its
//    reflection.
//  - wavelengths: whether paths are shared by all wavelengths (only Fresnel depends on λ).
// Pilots: the job's own incidences (its exact directions, or its bins), every one when the job has
// at most kMaxPilots, else a spread (pilotIncidences). Where the geometry alone proves that no path
// meets the surface twice (singleBounceLimit_deg), `multiple` is decided without pilots there. The
// pilots' work is bounded by [effects] pilot_budget, a fraction of the job's own tiles; a decision
// the budget leaves without enough pilots keeps the effect on and says so. The wave pilot uses the
// job's estimator, or the deterministic `exact` one (no sampling noise) in the grating-order regime
// when facets × orders (π sizeX sizeY / λ²) stays below 2e5.

#pragma once
#include <nlohmann/json.hpp>

#include <map>
#include <optional>

#include "core/direction_grid.h"
#include "job/effects_plan.h"
#include "job/job.h"
#include "scattering/kirchhoff_ensemble.h"
#include "scattering/tile_result.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

struct EffectsPilotOptions {
  uint64_t paths = 20000;        // per pilot slice (at most the job's paths_per_slice)
  int waveSamplesPerBin = 1024;  // per exit bin (at least the job's wave_samples_per_bin)
};

// The cells of `resolution_deg` the renderer resolves: for each bin of the grid its cell index
// (bins of zero projected solid angle: −1). Cells are rings of that width in the angle from the
// normal on each side (about a cap of radius resolution/2), cut into sectors of about that width;
// 0 keeps the bins.
std::vector<int> resolutionCells(const DirectionGrid& grid, double resolution_deg);

// The upper estimate beyond noise of a slice's diffraction, as the planner's pilots measure it: the
// largest over λ of L1 − floor + 2 sd of its `incoherent` component (WS − GS) pooled into the
// renderer's cells (resolutionCells), L1 = Σ_cells |Σ_b∈cell f Ω⊥|, floor = √(2/π) Σ_cells s_cell.
// 0 when the slice has no `incoherent`.
double diffractionUpperBound(const TileResult& r, const DirectionGrid& grid, const std::vector<int>& cellOf);

// Pilot incidence indices (distinct), in the order pilots run (a budget keeps the first ones): the
// most grazing incidence of the job, the one closest to normal, the median in θ, then each time the
// direction farthest (in angle) from those already picked, so that azimuths are covered as well as
// polar angles; every incidence when the job has at most kMaxPilots. Only incidences whose tiles the
// job computes are candidates (a symmetric job's ring representatives). Used by the effects planner
// and by `plan`'s cost pilot.
constexpr int kMaxPilots = 6;
std::vector<int> pilotIncidences(const Job& job);

// The largest polar angle of incidence (degrees) below which no path meets the surface twice, from
// the geometry alone, or none. A periodic closed patch whose facets all face up is a graph over its
// footprint; with its steepest facet slope angle θs, light reflected from any facet leaves at
// θo <= θi + 2θs, i.e. at an elevation above θs when θi < 90° − 3θs, and a ray rising (or, refracted
// into a dielectric, falling) more steeply than any facet never meets the surface again (the
// surface rises at most tan θs per unit of horizontal distance). Refraction into the dielectric
// (index n, its smallest real part over the job's wavelengths) leaves the facet within
// asin(sin(θi + θs)/n) of its inward normal, which adds sin(θi + θs) < n cos 2θs. Light from inside a
// dielectric has no such bound (it can leave along the surface).
std::optional<double> singleBounceLimit_deg(const Job& job);
// The steepest facet's slope angle (degrees) of such a graph, or none.
std::optional<double> steepestFacet_deg(const Job& job);
// Whether incidence t lies wholly below that limit (every direction of its bin, or its exact
// direction), so that its `multiple` is zero by the geometry.
bool scattersOnce(const Job& job, const DirectionGrid& grid, int t, const std::optional<double>& limit_deg);

// The Kirchhoff ensemble (scattering/kirchhoff_ensemble.h) of a random rough surface, from which the
// diffraction decision is taken before any pilot: a generated Gaussian surface or a flat with
// ground noise, of a conductor lit from above, whose patch holds at least 100 correlation areas
// (σ_h and the rms slope measured on the mesh); none elsewhere.
std::optional<KirchhoffEnsemble> jobEnsemble(const Job& job);
// Its slice at incidence i as the job samples it (averaged over the bin with an 8 x 8 rule, or
// along the exact direction), at lambda_nm, pooled into the cells of cellOf (resolutionCells).
EnsembleSlice ensembleSlice(const Job& job, const KirchhoffEnsemble& ensemble, const DirectionGrid& grid, int i,
                            double lambda_nm, const std::vector<int>& cellOf);
// A flat interface (scattering/flat_interface.h), from which the diffraction decision is taken in
// closed form before any pilot: a closed periodic patch under a coherence window whose vertices all lie in one plane,
// of a conductor lit from above or a dielectric of real index at the job's wavelengths lit from either side, whatever
// the geometry's kind. Its slice at incidence i as the job samples it, at lambda_nm, pooled into the cells of cellOf.
bool jobFlatInterface(const Job& job);
EnsembleSlice flatInterfaceSliceOf(const Job& job, const DirectionGrid& grid, int i, double lambda_nm,
                                   const std::vector<int>& cellOf);

// What the pilots computed that the run can keep (TileComputer): the geometric pilots' tiles, which
// are the first plan.pilotPaths paths of those tiles, and the wave terms of the diffraction pilots
// that ran along a job's own collimated direction, with the settings they ran with (the run keeps
// one only where those are the job's own: the same estimator, samples and seed).
struct PilotResults {
  std::map<int, TileResult> tiles;          // incidence → the geometric pilot's result
  std::map<int, WaveTileResult> waveTerms;  // incidence → the diffraction pilot's wave term
  WaveSettings waveSettings;                // what the wave terms were computed with
};

// The decisions (effects_plan.h); given `kept`, the pilots' results the run may keep.
EffectsPlan planEffects(const Job& job, const EffectsPilotOptions& options = {}, PilotResults* kept = nullptr);
// Sets job.components, its guarded components, wavelengths, wave estimator and job.effectsPlan
// (the plan's JSON) from a plan (the same on every rank).
void applyEffectsPlan(Job& job, const EffectsPlan& plan);
// One line per decision: "multiple     on   reason", after the tolerance, pilots and budget.
std::string formatEffects(const EffectsPlan& plan);

}  // namespace mbsdf
