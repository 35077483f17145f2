// The geometric-optics transport of a job: the explicit path tracer through the microgeometry
// (docs/physics.md §4), or the microflake random walk for a statistical surface (§9). Both produce the
// same TileResult (coherent = single scattering, multiple = the rest), so the runner, the planner
// and the comparison tool treat them alike. Owns what each needs (Embree scene or NDF tables).
//
// Where the job wants no path of depth >= 2 (neither `multiple` nor `lost`) on explicit periodic
// geometry, a tile's `coherent` may instead come from the deterministic facet sum
// (scattering/single_scattering.h): [sampling] single_scattering = "facets" always, "auto" per tile
// where its counted work (FacetSingleScattering::cheaperThan) is below the path tracer's 2 rays x
// the slice's paths x wavelength groups (a path of depth 1 casts two) — so the choice depends only
// on the job and the tile, never on timing.
#pragma once
#include <functional>
#include <memory>
#include <optional>

#include "core/direction_grid.h"
#include "geometry/embree_scene.h"
#include "job/job.h"
#include "microflake/microflake_walk.h"
#include "scattering/geometric_estimator.h"
#include "scattering/path_tracer.h"
#include "scattering/single_scattering.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

class GeometricTransport : public GeometricEstimator {
 public:
  // `paths` per wavelength group (the job's paths_per_slice, or a pilot budget).
  GeometricTransport(const Job& job, const DirectionGrid& grid, uint64_t paths);
  // The tile from the estimator that computes it (estimatorFor).
  using GeometricEstimator::run;
  TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const override;
  // Whether every tile comes from the facet sum.
  bool deterministic() const override;
  void reserveBuffers() const override;
  // The path tracer or the microflake walk, or for a tile the facet sum computes, that: a
  // deterministic estimator has nothing to add in later rounds (progressive sampling asks with
  // firstPath > 0), so those always go to the paths.
  const GeometricEstimator& estimatorFor(const TileRequest& request) const;
  // The Embree scene of explicit geometry (null for a statistical surface).
  const PeriodicScene* scene() const { return scene_.get(); }
  std::string describe() const;
  // Whether the job lets any tile's single scattering come from the facet sum.
  bool mayUseFacetSum() const { return facets_ != nullptr; }
  // Whether tile `incidenceBin` / `exactDirection` is computed by the facet sum (no paths), against
  // the path tracer at `paths` (0: the job's paths_per_slice).
  bool facetSum(int incidenceBin, const std::optional<Vec3>& exactDirection, uint64_t paths = 0) const;

 private:
  std::unique_ptr<PeriodicScene> scene_;
  std::unique_ptr<MicroflakeDistribution> flakes_;
  std::unique_ptr<GeometricEstimator> paths_;  // the path tracer, or the microflake walk
  std::unique_ptr<FacetSingleScattering> facets_;
  Job::SingleScatteringMode singleScattering_ = Job::SingleScatteringMode::Auto;
  uint64_t pathsPerSlice_ = 0;  // the job's paths_per_slice
  double raysPerPath_ = 0;      // the path tracer's rays per path (2 x wavelength groups) at depth 1
};

// Tile t (an index into job.incidence) as the job samples it: along its exact direction when the
// job's incidence is collimated (`incidence_sampling = "exact"`), else averaged over its bin.
TileRequest tileRequestOf(const Job& job, int t);

// The job's wave-optics settings ([sampling] estimator, samples, points, incidence directions,
// seed; masked sums when `lost` is a component), for the run and, adjusted, for the pilots.
WaveSettings waveSettingsOf(const Job& job);
// `ws` with one Gauss–Legendre node order more over the incidence bin than the job's rule. A
// deterministic estimator's error estimate over an incidence bin is |Q_n − Q_{n−1}| per bin against
// the next coarser rule; at this finer rule it is |Q_{n+1} − Q_n|, the distance of the job's own
// table from the finer rule's: the pilots' measure of what the job's rule leaves.
WaveSettings withFinerIncidenceRule(const Job& job, WaveSettings ws);
// The job's wave estimator on `scene` with `settings` and the coherence window of [scene].
std::unique_ptr<WaveEstimator> makeJobWaveEstimator(const Job& job, const DirectionGrid& grid,
                                                    const PeriodicScene& scene, const WaveSettings& settings);

}  // namespace mbsdf
