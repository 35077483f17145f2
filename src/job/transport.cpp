#include "job/transport.h"

#include <fmt/format.h>

namespace mbsdf {

GeometricTransport::GeometricTransport(const Job& job, const DirectionGrid& grid, uint64_t paths) {
  if (job.statistical) {
    flakes_ = std::make_unique<MicroflakeDistribution>(job.statistical->ndf);
    MicroflakeSettings s;
    s.paths = paths;
    s.maxDepth = job.maxDepth;
    s.seed = job.seed;
    s.flakes = job.statistical->flakes;
    s.flakeAlbedo = job.statistical->flakeAlbedo;
    paths_ = std::make_unique<MicroflakeWalk>(*flakes_, job.material, job.lambda_um(), grid, s);
  } else {
    scene_ = std::make_unique<PeriodicScene>(job.geometry);
    PathTracerSettings s;
    s.paths = paths;
    s.maxDepth = job.maxDepth;
    s.seed = job.seed;
    s.tallyGeoMasked = job.components.has(Component::Lost);
    paths_ = std::make_unique<PathTracer>(*scene_, job.material, job.lambda_um(), grid, s);
    // The facet sum assumes every ray meets the surface; a patch with holes takes paths, which
    // count the light through them as missed.
    if (job.geometry.periodic && job.closure.closed() && job.singleScattering != Job::SingleScatteringMode::Paths &&
        !job.components.has(Component::Multiple) && !job.components.has(Component::Lost)) {
      facets_ = std::make_unique<FacetSingleScattering>(job.geometry, *scene_, job.material, job.lambda_um(), grid);
      singleScattering_ = job.singleScattering;
      const double groups = job.material.directionsIndependentOfLambda() ? 1.0 : double(job.lambda_nm.size());
      raysPerPath_ = 2.0 * groups;
      pathsPerSlice_ = job.pathsPerSlice;  // the job's, also for a pilot's transport: it chooses as the run does
    }
  }
}

bool GeometricTransport::facetSum(int incidenceBin, const std::optional<Vec3>& exactDirection, uint64_t paths) const {
  if (!facets_) return false;
  if (singleScattering_ == Job::SingleScatteringMode::Facets) return true;
  return facets_->cheaperThan(incidenceBin, exactDirection, raysPerPath_ * double(paths > 0 ? paths : pathsPerSlice_));
}

const GeometricEstimator& GeometricTransport::estimatorFor(const TileRequest& q) const {
  if (q.firstPath == 0 && facetSum(q.incidenceBin, q.exactDirection, q.paths)) return *facets_;
  return *paths_;
}

TileResult GeometricTransport::run(const TileRequest& q, const std::function<void(uint64_t)>& progress) const {
  return estimatorFor(q).run(q, progress);
}

bool GeometricTransport::deterministic() const {
  return facets_ && singleScattering_ == Job::SingleScatteringMode::Facets;
}

void GeometricTransport::reserveBuffers() const {
  if (!deterministic()) paths_->reserveBuffers();
}

std::string GeometricTransport::describe() const {
  if (flakes_) return "microflake random walk, " + flakes_->describe();
  if (facets_)
    return std::string("path tracer through the explicit microgeometry; single scattering by the facet sum ") +
           (singleScattering_ == Job::SingleScatteringMode::Facets ? "on every tile"
                                                                   : "on the tiles where it is cheaper") +
           (facets_->maxSlope()
                ? fmt::format(" (heightfield, steepest slope {:.3g}: no ray above {:.3g} deg elevation)",
                              *facets_->maxSlope(), degrees(std::atan(*facets_->maxSlope())))
                : " (visibility by rays from each facet's first-level points, split where they disagree)");
  return "path tracer through the explicit microgeometry";
}

TileRequest tileRequestOf(const Job& job, int t) {
  const IncidenceDirection& inc = job.incidence[size_t(t)];
  TileRequest q{t, t, inc.bin, std::nullopt};
  if (job.exactIncidence) q.exactDirection = sphericalDirection(radians(inc.theta_deg), radians(inc.phi_deg));
  return q;
}

WaveSettings withFinerIncidenceRule(const Job& job, WaveSettings ws) {
  const int n = incidenceRuleOrder(int(job.waveIncidenceDirections)) + 1;
  ws.incidenceDirections = std::max(ws.incidenceDirections, n * n);
  const int nEdge = incidenceRuleOrder(int(job.wavePoleHorizonIncidenceDirections)) + 1;
  ws.poleHorizonIncidenceDirections = std::max(ws.poleHorizonIncidenceDirections, nEdge * nEdge);
  return ws;
}

WaveSettings waveSettingsOf(const Job& job) {
  WaveSettings ws;
  ws.estimator = job.resolvedWaveEstimator();
  ws.samplesPerBin = int(job.waveSamplesPerBin);
  ws.pointsPerDirection = int(job.wavePointsPerDirection);
  ws.incidenceDirections = int(job.waveIncidenceDirections);
  ws.poleHorizonIncidenceDirections = int(job.wavePoleHorizonIncidenceDirections);
  ws.subdirections = int(job.waveSubdirections);
  ws.seed = job.seed;
  ws.computeMasked = job.components.has(Component::Lost);
  ws.visibilityTable = job.visibilityTableResolution();
  return ws;
}

std::unique_ptr<WaveEstimator> makeJobWaveEstimator(const Job& job, const DirectionGrid& grid,
                                                    const PeriodicScene& scene, const WaveSettings& settings) {
  return makeWaveEstimator(
      WaveContext{job.geometry, scene, job.material, job.lambda_um(), grid,
                  CoherenceWindow::fromCoherenceLength(job.scene.coherenceLength_um, job.geometry.sizeX,
                                                       job.geometry.sizeY, job.geometry.periodic),
                  settings});
}

}  // namespace mbsdf
