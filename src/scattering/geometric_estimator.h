// What every geometric-optics estimator of a tile shares: the explicit path tracer
// (scattering/path_tracer.h), the microflake random walk of a statistical surface
// (microflake/microflake_walk.h) and the deterministic facet sum of single scattering
// (scattering/single_scattering.h). Each turns one tile request into a TileResult with `coherent`
// (single scattering) and, for the path estimators, `multiple`; the job's transport
// (job/transport.h) picks one per tile, and the run, `plan` and the effects planner's pilots ask
// through it alike.
#pragma once
#include <cstdint>
#include <functional>
#include <optional>

#include "core/vecmath.h"
#include "scattering/tile_request.h"
#include "scattering/tile_result.h"

namespace mbsdf {

class GeometricEstimator {
 public:
  virtual ~GeometricEstimator() = default;
  // `progress(done)` is called from the calling thread between batches (may be empty, may throw to
  // abandon the tile).
  virtual TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const = 0;
  // Whether a result carries no sampling noise (more rounds would add nothing).
  virtual bool deterministic() const = 0;
  // Makes, and touches, the working buffers a tile of the estimator's own path count will use,
  // so that the first tile does not fault their pages in (`run` does this while MPI starts).
  virtual void reserveBuffers() const {}

  // The same request in positional form.
  TileResult run(int tile, int incidenceIndex, int incidenceBin, std::optional<Vec3> exactDirection = std::nullopt,
                 const std::function<void(uint64_t)>& progress = {}, uint64_t firstPath = 0, uint64_t paths = 0) const {
    return run(TileRequest{tile, incidenceIndex, incidenceBin, exactDirection, firstPath, paths}, progress);
  }
};

}  // namespace mbsdf
