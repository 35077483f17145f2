// The result of one tile (one incidence bin x a block of wavelengths): bin-averaged BSDF values and
// their standard errors per component, plus the energy bookkeeping that docs/physics.md §4 asks for
// (truncated, leaked, missed paths). Serialised to doubles for MPI.
#pragma once
#include <array>
#include <limits>
#include <cstdint>
#include <vector>

#include "scattering/components.h"

namespace mbsdf {

class DirectionGrid;

struct TileResult {
  int tile = 0;
  int incidenceIndex = 0;  // index into the job's incidence list
  int incidenceBin = 0;    // sphere bin of the incidence direction
  int nLambda = 0, nBins = 0;
  // value[c] and stderr[c] hold nLambda * nBins entries (lambda-major) when component c was
  // computed, else are empty. Units: 1/sr (bin-averaged BSDF, docs/physics.md §3).
  std::array<std::vector<double>, kComponentCount> value, stdError;
  // Per wavelength, as fractions of the incident power.
  std::vector<double> truncated;  // paths cut at max depth (or wrapping forever)
  std::vector<double> leaked;     // paths that crossed the surface where it has holes or wrong winding
  std::vector<double> missed;     // primary rays that met no geometry (finite patches, holes)
  // Per-path moments of the energy a path-traced component carries out of each hemisphere (empty for
  // components not traced by paths): 2 sides (upper, lower) x 2 moments (mean w, mean w²) x nLambda,
  // at (side * 2 + moment) * nLambda + lambda. A path ends in one exit event, so the events of
  // different components and sides of one path exclude each other: the energy of any set S of them
  // has the per-path variance Σ_S m2 − (Σ_S m1)², and its standard error over N paths the square
  // root of that over N − 1 (the covariance across bins included, unlike a per-bin sum).
  std::array<std::vector<double>, kComponentCount> pathMoments;
  uint64_t samples = 0;  // paths per wavelength
  // Progressive sampling ([sampling] target_rel_error): rounds of paths run, and why it stopped.
  enum class SamplingStop : int { FixedBudget = 0, TargetReached = 1, BudgetExhausted = 2 };
  int rounds = 1;
  SamplingStop samplingStop = SamplingStop::FixedBudget;
  uint64_t waveSamples = 0;  // Kirchhoff samples (point x direction) per wavelength, 0 without a wave term
  // A `multiple` the effects planner skipped, verified on this tile (Job::guarded): the bound on its
  // energy (largest over λ of energy + 3 standard errors; NaN when not verified) and whether it
  // exceeded the tolerance, so that the tile computed it after all.
  double multipleCheck = std::numeric_limits<double>::quiet_NaN();
  bool multipleReenabled = false;
  // Diffraction the effects planner skipped, verified on this tile: the upper estimate beyond noise
  // of the slice's WS − GS difference at the renderer's resolution (largest over λ; from the pilot
  // that covered this incidence, or from the wave term the tile computed; NaN when not verified) and
  // whether it exceeded the tolerance, so that the slice holds its diffraction after all.
  double diffractionCheck = std::numeric_limits<double>::quiet_NaN();
  bool diffractionReenabled = false;
  uint64_t rays = 0;  // ray casts through the scene (for speed figures)
  double seconds = 0;

  double& at(Component c, int lambda, int bin) { return value[int(c)][size_t(lambda) * nBins + bin]; }
  double at(Component c, int lambda, int bin) const { return value[int(c)][size_t(lambda) * nBins + bin]; }
  bool has(Component c) const { return !value[int(c)].empty(); }

  // Pools another run of the same Monte Carlo estimator over disjoint paths (the path tracer or the
  // microflake walk) into this one: the result is the estimator over all samples (means weighted by
  // sample counts, per-path variances recombined), for the components `more` has.
  void poolPaths(const TileResult& more);

  // The standard error of the energy (Σ f Ω⊥) of the path-traced components in `comps` leaving by
  // `side` (0 upper, 1 lower, -1 both) per wavelength (see pathMoments); empty if one of them has no
  // moments.
  std::vector<double> pathEnergyStdError(const std::vector<Component>& comps, int side) const;

  std::vector<double> serialize() const;
  static TileResult deserialize(const std::vector<double>& buf);
};

// The energy balance of a tile per wavelength: Σ over `model`'s components and both hemispheres of
// f Ω⊥, plus the truncated, leaked and missed fractions, minus 1 — for a lossless material the
// model's energy error; for an absorbing one only an excess over 1 is an error (a deficit is
// absorption), so the rest is reported as 0.
std::vector<double> energyBalance(const TileResult& r, const DirectionGrid& grid, const std::vector<Component>& model,
                                  bool lossless);

// The standard error of Σ f Ω⊥ of component c over one hemisphere (side 0 upper, 1 lower), per
// wavelength: from the per-path energies where the component is path-traced (TileResult::pathMoments:
// the covariance of the bins included); else the facet sum's bounds summed, or a wave estimator's
// per-bin errors in quadrature.
std::vector<double> energyStdError(const TileResult& r, Component c, int side, const DirectionGrid& grid);

// The standard error of energyBalance per wavelength, formed as the stored
// /stats/energy_balance_stderr is: the path-traced components' energy from the per-path energies
// (their bins and hemispheres covary), every other component's per hemisphere in quadrature.
std::vector<double> energyBalanceStdError(const TileResult& r, const DirectionGrid& grid,
                                          const std::vector<Component>& model);

// The estimated relative error of a slice of the table Σ_c∈comps f_c, per wavelength:
// √(Σ_b Σ_c (σ_c,b Ω⊥_b)²) / Σ_b |Σ_c f_c,b| Ω⊥_b — the expected L2 distance of the slice from its
// expectation against its mass. The components a path tracer tallies exclude each other in a path,
// so their errors add in quadrature; a component that carries little energy adds little error, so a
// rare multiple bounce does not dominate the table's error. For one path-traced component it bounds
// the error of the hemispherical integral from above (its bins are negatively correlated).
std::vector<double> relativeError(const TileResult& r, const std::vector<Component>& comps, const DirectionGrid& grid);

// The parts of a slice's expected relative L1 distance from its expectation, per wavelength:
// `deviation` = Σ_b E|f̂_b − f_b| Ω⊥_b and `mass` = Σ_b |f_b| Ω⊥_b, so deviation / mass is the
// measure the accuracy study holds tables to against a reference (Σ|f − f_ref| Ω⊥ / Σ|f_ref| Ω⊥).
// `errorFactor` turns a bin's error into E|f̂ − f|: √(2/π) for a Monte Carlo standard error (the
// mean absolute deviation of a normal error), 1 for a deterministic rule's error estimate. Bins
// not computed (NaN) are skipped. Unlike relativeError's quadrature sum, which shrinks as 1/√bins
// for spread-out tables, this grows with the per-bin noise: with B equally filled bins of relative
// error r it is about 0.8 r, where relativeError gives r/√B.
inline constexpr double kMeanAbsPerSigma = 0.79788456080286536;  // √(2/π)
struct SliceL1 {
  std::vector<double> deviation, mass;
};
SliceL1 sliceL1(const std::vector<double>& f, const std::vector<double>& err, int nLambda, const DirectionGrid& grid,
                double errorFactor);

}  // namespace mbsdf
