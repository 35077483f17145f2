// A validated job (docs/job-reference.md). Building it reads every key through ParamDict, checks
// ranges and files, builds the microgeometry and finally reports unused keys; any problem is an
// InputError naming file, line and key, raised before any output file is touched.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "core/storage_profile.h"
#include "core/file_digest.h"
#include "geometry/microgeometry.h"
#include "job/geometry_factory.h"
#include "microflake/microflake_walk.h"
#include "scattering/wave_estimator.h"
#include "optics/material.h"
#include "scattering/components.h"
#include "scattering/wave_estimator_kind.h"

namespace mbsdf {

struct SceneNeeds {
  double coherenceLength_um = 50.0;
  // Where δc came from: "coherence_length_um", or a disk source (`light = "sun"` or
  // `source_angular_diameter_deg`) through van Cittert–Zernike (coherence_window.h).
  std::string coherenceSource = "coherence_length_um";
  double sourceAngularDiameter_deg = 0;
  std::vector<std::string> needs{"brdf", "btdf"};
  double tolerance = 0.01;
  // Largest incidence angle from the normal (on the light's side) the renderer looks up: with
  // incidence = "all" the bins beyond it are not computed.
  double incidenceMax_deg = 90.0;
  // The angular detail the renderer resolves; the diffraction decision compares WS and GS pooled
  // into cells of this size (0: the job's bins).
  double angularResolution_deg = 0.0;
  // Spectral: the renderer integrates the spectrum; Rgb: it is fed colour (with components =
  // "auto" the planner may compute fewer wavelengths, effects_planner.h).
  enum class Colour { Spectral, Rgb };
  Colour colour = Colour::Spectral;
};

// [geometry] kind = "statistical": a surface known only by its NDF, simulated by the microflake
// volume model (docs/physics.md §9).
struct StatisticalSurface {
  Ndf ndf = BeckmannNdf{};
  FlakeKind flakes = FlakeKind::Specular;
  double flakeAlbedo = 1.0;
};

struct Job {
  std::string file;  // job file path ("" for a string)
  std::string text;  // the full job text (stored in the output for provenance)
  std::vector<InputFile> inputFiles;
  std::string geometryKind;
  Microgeometry geometry;                         // empty for a statistical surface
  SurfaceClosure closure;                         // holes and cracks of the explicit geometry
  std::optional<TopographyReport> topography;     // set for a heightfield: what was meshed, and how
  std::optional<StatisticalSurface> statistical;  // set for kind = "statistical"
  Material material;
  std::string materialName;
  std::vector<double> lambda_nm;
  DirectionGrid::Layout gridLayout;
  std::vector<IncidenceDirection> incidence;
  bool exactIncidence = false;  // [directions] incidence_sampling = "exact": collimated beams
  bool incidenceAll =
      false;  // [directions] incidence = "all": every bin on the incident side(s) (within scene.incidence_max_deg)
  // [directions] symmetry: an isotropic surface has one incidence azimuth per θ ring computed and
  // the other slices of the ring rotated from it; a surface invariant under rotation by 2π/n
  // (rotationOrder = n >= 2, e.g. a square lattice: 4) one n-th of each ring (symmetry.h).
  // symmetryReason says why or why not.
  bool isotropic = false;
  int rotationOrder = 1;
  bool mirrorSymmetric = false;  // invariant under y -> −y
  bool symmetryReduced() const { return isotropic || rotationOrder > 1 || mirrorSymmetric; }
  std::string symmetryReason;
  ComponentSet components;
  std::vector<std::string> requestedComponents;
  bool reciprocity = true;  // [effects] reciprocity: halve the wave term when the job allows it
  // [effects] pilot_budget: the effects planner's pilots cost at most this fraction of the job's
  // computed tiles, counted in tiles' work (paths, wave samples), never in seconds (the decisions
  // must not depend on the machine). Where the budget cuts a decision short, the effect is kept.
  double pilotBudget = 0.5;
  // components = "auto": the effects planner (effects_planner.h) chooses `components` from pilots
  // before the run; effectsPlan is its decisions as JSON (recorded in the output file).
  bool autoComponents = false;
  std::string effectsPlan;
  // Components the effects planner skipped that every tile verifies on itself: `multiple`, whose
  // energy on the tile a few thousand full-depth paths bound (+ 3 standard errors); `incoherent`
  // (diffraction), confirmed by the pilot that ran a tile as the job does, elsewhere by the tile's
  // own wave term. Past the tolerance the tile computes it after all. They are in `components` (the
  // file holds them: zeros where the skip was confirmed without computing them) but not in what a
  // tile computes first.
  ComponentSet guarded;
  // False when the planner found that the renderer needs no BTDF of this dielectric: the wave term
  // skips the transmitted exit bins, which keep geometric optics (incoherent = 0 there).
  bool waveTransmission = true;
  SceneNeeds scene;
  uint64_t pathsPerSlice = 1000000;
  // [sampling] path_allocation: the same paths for every slice, or (with pairs stored once) the
  // paths that give every slice's folded tables about the error of the slice that gains least from
  // the fold, pathsPerSlice being that slice's (scattering/path_allocation.h).
  enum class PathAllocation { Uniform, EqualError };
  PathAllocation pathAllocation = PathAllocation::Uniform;
  // Per incidence index, its slice's paths under EqualError; empty: pathsPerSlice everywhere.
  std::vector<uint64_t> slicePaths;
  uint64_t pathsFor(int incidence) const { return slicePaths.empty() ? pathsPerSlice : slicePaths[size_t(incidence)]; }
  // "N paths per slice", or the allocation's range and mean (for the log and `plan`).
  std::string describePaths() const;
  // The mean of the slices' paths: paths_per_slice, or the allocation's mean.
  double meanSlicePaths() const;
  // The paths per slice path_allocation = "equal-error" gives this job's incidences.
  std::vector<uint64_t> equalErrorSlicePaths() const;
  // Progressive sampling: rounds of pathsPerSlice paths until the slice's estimated relative error
  // (geometric components) is at most targetRelError (0: off) or maxPathsPerSlice is spent.
  double targetRelError = 0;
  uint64_t maxPathsPerSlice = 0;
  int maxDepth = 100;
  uint64_t seed = 1;
  std::optional<WaveEstimatorKind> waveEstimator;  // none: "auto", resolved by resolvedWaveEstimator()
  // Why the effects planner set waveEstimator (applyEffectsPlan); none: the job named it or none.
  std::optional<std::string> waveEstimatorPlanned;
  int64_t waveSamplesPerBin = 256;
  int64_t wavePointsPerDirection = 64;
  int64_t waveIncidenceDirections = 4;
  // The same at the incidence bins that reach normal incidence or the horizon.
  int64_t wavePoleHorizonIncidenceDirections = 4;
  int64_t waveSubdirections = kDefaultSubdirections;  // exact, fft: sub-directions per axis of an incidence bin
  // [sampling] visibility_table: the `exact` estimator's shared visibility table
  // (scattering/visibility_table.h); see visibilityTableResolution().
  enum class VisibilityTableMode { Auto, On, Off };
  VisibilityTableMode visibilityTable = VisibilityTableMode::Auto;
  // [sampling] single_scattering: how the `coherent` component is computed where no path of depth
  // >= 2 is wanted (scattering/single_scattering.h); see GeometricTransport.
  enum class SingleScatteringMode { Auto, Paths, Facets };
  SingleScatteringMode singleScattering = SingleScatteringMode::Auto;
  std::string outputPath = "out.h5";
  bool previews = false;
  StorageProfile storage;  // [output] profile, values, errors

  // The cell the periodic patch repeats, nx x ny times (geometry/lattice_cell.h; 1 x 1 when it does
  // not, or when the job has no windowed wave term to use it for): its order lobes are 2π/L_cell
  // apart, which decides the grating-order regime.
  int cellNx = 1, cellNy = 1;
  double cellSizeX() const { return geometry.sizeX / cellNx; }
  double cellSizeY() const { return geometry.sizeY / cellNy; }
  double facetsPerCell() const { return double(geometry.triangles.size()) / (cellNx * cellNy); }
  bool needsWave() const { return components.has(Component::Incoherent) || components.has(Component::Lost); }
  // "auto": `orders` for a periodic patch under a coherence window wider than about one period of
  // its cell (2πσ/L_cell >= 4: neighbouring order lobes are >= 5.7 standard deviations apart), or
  // `exact` there when it costs no more (8 x the cell's facets <= wave_samples_per_bin); `fft` for a periodic
  // heightfield under a narrower window on a disk grid without the lost component; otherwise `area`.
  WaveEstimatorKind resolvedWaveEstimator() const;
  // Why the wave estimator is the one it is, for the log.
  std::string waveEstimatorChoice() const;
  // The estimator the job's keys give when it names none, and why.
  WaveEstimatorKind staticWaveEstimator() const;
  std::string staticWaveEstimatorReason() const;
  // Why the wave term's stored standard errors are not vouched for, where they are not: `paper`'s
  // bias estimate. None for deterministic estimators, and for `area` and `orders`, whose errors are
  // measured against `exact` (docs/physics.md §5).
  std::optional<std::string> waveErrorsCaveat() const;
  // The propagating orders of the lattice cell a direction bin holds at the shortest wavelength.
  double exactOrdersPerBin() const;
  // Why the wave term of this job is not halved by reciprocity (docs/physics.md §8), or "" when it is:
  // it needs incidence = "all" with bin-averaged incidence (the bin-to-bin table is then exactly
  // reciprocal), the incoherent component without `lost` (the masked power is not reciprocal) and
  // an estimator whose cost is per exit bin (area, paper).
  std::string reciprocityOffReason() const;
  // Directions per axis of `exact`'s shared visibility table, or 0 for none. "auto" builds it when
  // it pays: its 4 (M+1)² rays per facet and hemisphere, cast once per rank, against the 4 rays per
  // facet and order direction it saves in every tile (tiles x incidence nodes x orders, the orders
  // π A_cell / λ² per wavelength), and when it fits in 1 GB. M = 128 (0.9° apart at the zenith).
  int visibilityTableResolution() const;
  // The deterministic wave estimators' incidence directions per tile (the nodes of both rules) over
  // incidence bin `bin`, at its rule (wave_incidence_directions, or _pole_horizon at the bins that
  // reach normal incidence or the horizon) raised by `extraOrders`; and their mean over the job's
  // incidences.
  int incidenceRuleNodesAt(const DirectionGrid& grid, int bin, int extraOrders = 0) const;
  double meanIncidenceRuleNodes(const DirectionGrid& grid, int extraOrders = 0) const;
  bool halvesWaveByReciprocity() const { return reciprocityOffReason().empty(); }
  // Sphere bin of each incidence direction, in incidence order.
  std::vector<int> incidenceBins() const {
    std::vector<int> v;
    for (const auto& i : incidence) v.push_back(i.bin);
    return v;
  }
  double meanLambda_um() const {
    double s = 0;
    for (double l : lambda_nm) s += l * 1e-3;
    return lambda_nm.empty() ? 0.0 : s / double(lambda_nm.size());
  }
  std::vector<double> lambda_um() const {
    std::vector<double> v;
    for (double l : lambda_nm) v.push_back(l * 1e-3);
    return v;
  }
};

// Parse and validate a job file. Relative file names in it are relative to the job file.
Job loadJob(const std::string& path);
Job loadJobFromString(const std::string& text, const std::string& sourceName, const std::string& baseDir);
// The [material] section of a job's text alone (a stored table's `job_text`, whose geometry files
// may no longer exist): what an exporter needs to place a refracted direction.
Material loadMaterialFromString(const std::string& text, const std::string& sourceName);

}  // namespace mbsdf
