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
// Speed: the paths of a batch (runPaths) advance together, one ray each per round, and each round's
// rays are traced in the order of their origins (geometry/ray_order.h), so that the rays a thread
// traces in a row meet the same part of Embree's tree while it is in the cache, as packets of 16
// neighbours; a path's state moves with its ray.
//
// Determinism: path j of tile t uses Sampler(seed, t, j, group), whatever the order its rays are
// traced in; the paths' tallies are made in path order in fixed chunks merged in chunk order, so
// results do not depend on the thread count.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "core/direction_grid.h"
#include "core/spare_pool.h"
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
  // Rays go to Embree as packets of 16 neighbours in origin order (false: one by one; the
  // benchmark compares the two). Either way each ray gets the same hit.
  bool packets = true;
};

class PathTracer : public GeometricEstimator {
 public:
  PathTracer(const PeriodicScene& scene, const Material& material, std::vector<double> lambda_um,
             const DirectionGrid& grid, PathTracerSettings settings);
  ~PathTracer() override;

  // Traces the paths of one tile (geometric_estimator.h; paths 0: the settings' count);
  // `progress(pathsDone)` is called from the calling thread between batches.
  using GeometricEstimator::run;
  TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const override;
  bool deterministic() const override { return false; }
  void reserveBuffers() const override;
  // Whether each round's rays are traced in the order of their origins (scenes of 4096 triangles
  // or more), or in their paths' order.
  bool ordersByOrigin() const { return orderByOrigin_; }

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
  // A path's state between rays: its next ray, the triangle that ray leaves, its medium, depth,
  // place in its batch and where its random numbers stand. One cache line: a wavefront holds a few
  // hundred thousand and moves them, each round, into the order their rays are traced in. What
  // the state does not hold is the path's context (PathContext): its sampler's seed, tile, index
  // and stream, its weights and its geo_masked bin, by its place in the batch.
  struct alignas(64) PathState {
    Vec3 o, d;
    int32_t lastPrim = -1;   // the triangle the next ray leaves
    uint32_t depth = 0;      // surfaces met so far (every ray before the last met one)
    uint32_t nextBlock = 0;  // its sampler's position (Sampler::resume)
    uint32_t path : 24 = 0;  // its place in the batch of paths advanced together
    uint32_t secondLeft : 1 = 0;
    uint32_t inUpper : 1 = 1;
  };
  static_assert(sizeof(PathState) == 64);
  static constexpr uint64_t kMaxBatchPaths = uint64_t(1) << 24;  // PathState::path
  // How an ended path ended, and what it leaves for its tallies (commit).
  struct PathEnd {
    enum class Kind : uint8_t { Exited, Truncated, Leaked, Missed };
    int32_t rays = 0;  // rays traced
    int32_t exitBin = -1;
    Kind kind = Kind::Exited;
    bool coherent = false;  // exited after one hit
  };
  static_assert(sizeof(PathEnd) == 12);
  // What the paths of a batch share, and what each keeps by its place in the batch.
  struct PathContext {
    int tile = 0, group = 0;
    uint64_t firstPath = 0;     // the tile's index of the batch's path 0
    double* weights = nullptr;  // per path: weightsPerPath weights (PathState::path's row)
    size_t weightsPerPath = 0;
    int32_t* geoMaskedBins = nullptr;  // per path, when geo_masked is tallied: the bin it tallied, or -1
    double* weightsOf(uint32_t path) const { return weights + size_t(path) * weightsPerPath; }
  };
  // The weights a path of the group carries: one per wavelength (w[0, nl)), then, when geo_masked
  // is tallied, those when its direction was tallied (w[nl, 2 nl)).
  size_t weightsPerPath(int group) const { return (settings_.tallyGeoMasked ? 2 : 1) * groups_[size_t(group)].size(); }
  // The random numbers of the tile's path `path` in a wavelength group, whatever order its rays
  // are traced in.
  Sampler pathSampler(int tile, uint64_t path, int group) const {
    return Sampler(settings_.seed, uint32_t(tile), path, uint32_t(group));
  }
  // The first state of the tile's path `path`; w: its weightsPerPath weights; wi, if asked, its
  // incidence. The caller sets its place in the batch.
  PathState startPath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group, double* w,
                      Vec3* wi = nullptr) const;
  // The path meets the result of its ray: true when it goes on (its next ray set), false when it
  // has ended (how, in `ended`).
  bool step(PathState& st, const TraceResult& tr, const PathContext& ctx, PathEnd& ended, PathRecord* rec) const;
  // The ended path's tallies; w: its weights; geoMaskedBin: the bin its geo_masked copy went to, or -1.
  void commit(const PathEnd& e, const double* w, int geoMaskedBin, int group, PathChunk& out) const;
  // One path, its first ray traced alone (replay).
  void tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group, PathChunk& out,
                 PathRecord* rec) const;
  // The buffers of a batch of paths advanced together, kept from batch to batch and run to run.
  struct Wavefront;
  // wf's buffers grown to hold a batch of `count` paths (of weightsPerPath weights each).
  void fit(Wavefront& wf, uint64_t count, size_t weightsPerPath) const;
  // The tallies of the request's paths (runPaths).
  PathTallyPlan tallyPlan(const TileRequest& request) const;
  // Paths firstPath … firstPath + count − 1 advanced together, one ray each per round, each round's
  // rays traced in the order of their origins (a wavefront; geometry/ray_order.h): the same
  // results as tracePath one by one. Path firstPath + i is tallied into chunks[i / kPathChunk].
  void traceBatch(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t firstPath, uint64_t count,
                  int group, std::span<PathChunk> chunks, Wavefront& wf) const;
  // One round of the wavefront: traces its rays in origin order and steps their paths; the paths
  // that go on are its next rays.
  void traceRound(const PathContext& ctx, bool firstRays, Wavefront& wf) const;

  const PeriodicScene& scene_;
  const Material& material_;
  bool conductor_, perfectConductor_;  // material_'s kind, asked once rather than at every hit
  std::vector<double> lambda_um_;
  std::vector<Complex> ior_;                    // lower-medium index per wavelength
  std::vector<ConductorFresnelTable> fresnel_;  // conductor: per wavelength
  std::vector<std::vector<int>> groups_;        // wavelengths that share one path
  const DirectionGrid& grid_;
  PathTracerSettings settings_;
  static constexpr size_t kOrderByOriginMinTriangles = 4096;
  bool orderByOrigin_;  // each round's rays traced in the order of their origins
  mutable SparePool<std::unique_ptr<Wavefront>> spareWavefronts_;  // buffers of finished runs, for the next
};

}  // namespace mbsdf
