// Geometric-optics path tracer through the explicit microgeometry (docs/physics.md §4; Falster et al. 2020, Sec. 3.2,
// Eqs. 9–12). Estimates, for one incidence bin, the `coherent` (depth 1) and `multiple`
// (depth >= 2) components, the `geo_masked` tally used by the lost component (§4 step 6, §6), and
// the truncated energy.
//
// Sampling: the incidence direction is drawn with density ∝ cos θ inside the incidence bin (so every
// path carries weight 1 for the cosine-weighted incident power E of §3) and the entry point
// uniformly on the footprint at the top of the slab: for a periodic patch this is exactly the
// illuminated-area sampling of Falster et al. 2020, Sec. 5 (Eq. 21), with A = footprint area.
// Estimator: f(Ωo) = Σ tallies / (N Ω⊥(Ωo)).
//
// Spectral: when directions do not depend on λ (conductors, constant-index dielectrics) one path
// carries a weight per wavelength (conductor: ×F_λ; dielectric: Russian roulette with F, which is
// then the same for every λ). Otherwise each wavelength is traced on its own.
//
// Determinism: path j of tile t uses Sampler(seed, t, j, group); paths are processed in fixed
// chunks whose tallies are merged in chunk order, so results do not depend on the thread count.
#pragma once
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "core/direction_grid.h"
#include "core/rng.h"
#include "geometry/embree_scene.h"
#include "optics/fresnel_table.h"
#include "optics/material.h"
#include "scattering/components.h"
#include "scattering/geometric_estimator.h"
#include "scattering/path_tally.h"
#include "scattering/tile_result.h"

namespace mbsdf {

struct PathTracerSettings {
  uint64_t paths = 100000;  // per wavelength group
  int maxDepth = 100;
  uint64_t seed = 1;
  bool tallyGeoMasked = false;
};

class PathTracer : public GeometricEstimator {
 public:
  PathTracer(const PeriodicScene& scene, const Material& material, std::vector<double> lambda_um,
             const DirectionGrid& grid, PathTracerSettings settings);

  // Traces the paths of one tile (geometric_estimator.h; paths 0: the settings' count);
  // `progress(pathsDone)` is called from the calling thread between batches.
  using GeometricEstimator::run;
  TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const override;
  bool deterministic() const override { return false; }

  // Replays a single path (for debugging a failing sample): returns its exit bin (or -1) and depth.
  struct PathRecord {
    Vec3 wi, wo;  // incidence direction and exit direction (both pointing away from the surface)
    int exitBin = -1;
    int depth = 0;
    std::vector<double> weight;
    std::vector<Vec3> vertices;
    // Every ray the path asked the scene for, as asked: origin, direction, triangle it leaves.
    struct Ray {
      Vec3 o, d;
      int ignorePrim = -1;
    };
    std::vector<Ray> rays;
  };
  PathRecord replay(int tile, int incidenceBin, uint64_t path, int group = 0,
                    std::optional<Vec3> exactDirection = std::nullopt) const;

 private:
  // A path's state between rays: its random numbers, incidence, next ray, medium, depth, weights
  // (one per wavelength of its group, in a buffer the caller owns) and, once it has ended, how.
  struct PathState {
    explicit PathState(const Sampler& sampler) : s(sampler) {}
    Sampler s;
    DirectionSample wi;
    Vec3 o, d;
    bool inUpper = true;
    int depth = 0;
    int lastPrim = -1;  // the triangle the next ray leaves
    double* w = nullptr;
    double* wGeoMasked = nullptr;  // the weights when the geo_masked direction was tallied
    int geoMaskedBin = -1;
    enum class End { Exited, Truncated, Leaked, Missed } end = End::Exited;
    int exitBin = -1;
  };
  PathState startPath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group, double* w,
                      double* wGeoMasked) const;
  // The path meets the result of its ray: true when it goes on (its next ray set), false when it
  // has ended (how, recorded in the state).
  bool step(PathState& st, const TraceResult& tr, int group, PathRecord* rec) const;
  // The ended path's tallies.
  void commit(const PathState& st, int group, PathChunk& out) const;
  // One path, its first ray traced alone (replay).
  void tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group, PathChunk& out,
                 PathRecord* rec) const;
  // Paths firstPath … firstPath + count − 1 advanced together, one ray each per round
  // (PeriodicScene::traceMany): the same results as tracePath one by one.
  void traceRange(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t firstPath, uint64_t count,
                  int group, PathChunk& out) const;

  const PeriodicScene& scene_;
  const Material& material_;
  bool conductor_, perfectConductor_;  // material_'s kind, asked once rather than at every hit
  std::vector<double> lambda_um_;
  std::vector<Complex> ior_;                    // lower-medium index per wavelength
  std::vector<ConductorFresnelTable> fresnel_;  // conductor: per wavelength
  std::vector<std::vector<int>> groups_;        // wavelengths that share one path
  const DirectionGrid& grid_;
  PathTracerSettings settings_;
};

}  // namespace mbsdf
