// One tile of a table as an estimator sees it: the same request goes to the geometric estimators
// (scattering/geometric_estimator.h) and to the wave estimators (scattering/wave_estimator.h), built
// once from the job by tileRequestOf (job/transport.h), so the run, `plan` and the effects planner's
// pilots ask every estimator for a tile alike.
#pragma once
#include <cstdint>
#include <optional>

#include "core/vecmath.h"

namespace mbsdf {

struct TileRequest {
  int tile = 0;            // the samplers' key (results depend on it, never on the rank or thread)
  int incidenceIndex = 0;  // recorded in the result
  int incidenceBin = 0;
  // A collimated beam from this direction (pointing away from the surface), or none: averaged over
  // the incidence bin with density ∝ cos θ.
  std::optional<Vec3> exactDirection;
  // Paths firstPath … firstPath + paths − 1 (paths 0: the estimator's own count), so that a tile
  // traced in rounds holds the paths of one run; a deterministic estimator ignores both.
  uint64_t firstPath = 0, paths = 0;
};

}  // namespace mbsdf
