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
    walk_ = std::make_unique<MicroflakeWalk>(*flakes_, job.material, job.lambda_um(), grid, s);
  } else {
    scene_ = std::make_unique<PeriodicScene>(job.geometry);
    PathTracerSettings s;
    s.paths = paths;
    s.maxDepth = job.maxDepth;
    s.seed = job.seed;
    s.tallyGeoMasked = job.components.has(Component::Lost);
    tracer_ = std::make_unique<PathTracer>(*scene_, job.material, job.lambda_um(), grid, s);
  }
}

TileResult GeometricTransport::run(int tile, int incidenceIndex, int incidenceBin, std::optional<Vec3> exactDirection,
                                   const std::function<void(uint64_t)>& progress, uint64_t firstPath) const {
  if (walk_) return walk_->run(tile, incidenceIndex, incidenceBin, exactDirection, progress, firstPath);
  return tracer_->run(tile, incidenceIndex, incidenceBin, exactDirection, progress, firstPath);
}

std::string GeometricTransport::describe() const {
  if (flakes_) return "microflake random walk, " + flakes_->describe();
  return "path tracer through the explicit microgeometry";
}

WaveSettings waveSettingsOf(const Job& job) {
  WaveSettings ws;
  ws.estimator = job.resolvedWaveEstimator();
  ws.samplesPerBin = int(job.waveSamplesPerBin);
  ws.pointsPerDirection = int(job.wavePointsPerDirection);
  ws.incidenceDirections = int(job.waveIncidenceDirections);
  ws.seed = job.seed;
  ws.computeMasked = job.components.has(Component::Lost);
  ws.visibilityTable = job.visibilityTableResolution();
  return ws;
}

std::unique_ptr<WaveEstimator> makeJobWaveEstimator(const Job& job, const DirectionGrid& grid, const PeriodicScene& scene,
                                                    const WaveSettings& settings) {
  return makeWaveEstimator(WaveContext{job.geometry, scene, job.material, job.lambda_um(), grid,
                                       CoherenceWindow::fromCoherenceLength(job.scene.coherenceLength_um, job.geometry.sizeX,
                                                                            job.geometry.sizeY, job.geometry.periodic),
                                       settings});
}

}  // namespace mbsdf
