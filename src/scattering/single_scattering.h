// Geometric single scattering (the `coherent` component, docs/physics.md §3–4: paths of depth 1, the
// paper's GS, Sec. 3.2 Eq. 9 with one bounce) as a deterministic sum over the facets, for jobs that
// need no path of depth ≥ 2 (neither `multiple` nor `lost`'s geo_masked tally). Where nothing
// scatters twice the path tracer spends its rays on what a sum gives exactly: facet t, lit from
// ωi over the fraction L_t of its area and seen from its mirror direction r_t = reflect(ωi, n_t)
// over the fraction V_t of the lit part, sends
//     P_t = A_t (ωi·n_t) F(ωi·n_t) L_t V_t / (A cos θi)
// of the incident power into r_t (and, for a dielectric, A_t (ωi·n_t) (1 − F) L_t V'_t / (A cos θi)
// into the refracted direction), A the footprint of the periodic patch. f_b = Σ_t P_t / Ω⊥(b), the
// same estimand as the path tracer's depth-1 tally (its expectation), without sampling noise.
//
// Visibility: on a periodic heightfield whose facets' slopes are at most s, a ray leaving a point of
// the surface at an elevation with tan > s stays above it (the surface rises at most s per unit of
// horizontal distance), so L_t = V_t = 1 for every such direction with no ray cast; other
// (facet, direction) pairs — any pair on a mesh that is not a heightfield — take L_t V_t from rays
// at the facet's four first-level points (as `exact` tests them), splitting the facet into four
// where they disagree, kVisibilityDepth levels deep; the leaves whose points still disagree are the
// visibility's error bound (their area times the largest deviation of their point fraction).
//
// Incidence bin: an S × S midpoint rule in the bin's cosine-weighted sample space (the path
// tracer's incidence density), S = 32 like the wave estimators' sub-direction binning, so WS − GS
// compares like with like. Error per bin (the stored standard error, an error bound on the safe
// side): the visibility bound plus |B_S − B_{S/2}| (the coarser rule's error). A collimated beam
// has only the visibility term.
//
// Facets of one orientation (a grating's texels, a V-groove's faces) are one term where no ray is
// needed. Cost: (S² + S²/4) × orientations pairs per set of directions (one for all wavelengths
// unless the index disperses) plus the rays of the pairs that need visibility; `cost()` counts
// them for a tile without tracing, so the caller can pick the cheaper of this and the path tracer
// per tile (`cheaperThan`) (deterministically: the counts depend only on the geometry and the incidence bin).
// Tests: tests/scattering/single_scattering_test.cpp (Fresnel, the V-groove's tan θ, the path
// tracer's depth-1 tally on five surfaces).
#pragma once
#include <limits>
#include <optional>
#include <vector>

#include "core/direction_grid.h"
#include "geometry/embree_scene.h"
#include "geometry/microgeometry.h"
#include "optics/fresnel_table.h"
#include "optics/material.h"
#include "scattering/geometric_estimator.h"
#include "scattering/tile_result.h"

namespace mbsdf {

class FacetSingleScattering : public GeometricEstimator {
 public:
  static constexpr int kSubdirections = 32;   // S
  static constexpr int kVisibilityDepth = 5;  // splitting levels of a partly visible facet

  FacetSingleScattering(const Microgeometry& g, const PeriodicScene& scene, const Material& material,
                        std::vector<double> lambda_um, const DirectionGrid& grid);

  // Facet-direction pairs that cost one ray: measured by `microbsdf_bench
  // --benchmark_filter='FacetSum|GratingPath'` (bench/bench_path_tracer.cpp: 4.0 on the Al grating;
  // a pair is a reflection, a bin lookup and a Fresnel factor per wavelength, a ray an Embree
  // traversal of the periodic scene with the path tracer's bookkeeping).
  static constexpr double kPairsPerRay = 4.0;

  struct Cost {
    double pairs = 0;  // facet-direction pairs summed
    double rays = 0;   // visibility rays those pairs need
  };
  // What run() will do for this tile, counted without tracing; the ray count stops once it passes
  // `stopAbove`.
  Cost cost(int incidenceBin, const std::optional<Vec3>& exactDirection,
            double stopAbove = std::numeric_limits<double>::infinity()) const;
  // Whether the tile's counted work, pairs / kPairsPerRay + rays, is at most `rays` ray casts.
  bool cheaperThan(int incidenceBin, const std::optional<Vec3>& exactDirection, double rays) const;
  // The tile's single scattering (geometric_estimator.h; paths are not asked for: it has none).
  using GeometricEstimator::run;
  TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const override;
  bool deterministic() const override { return true; }

  // The steepest facet slope |∇h| of a periodic heightfield (directions above it need no ray); none
  // for another mesh.
  std::optional<double> maxSlope() const { return slope_.maxSlope; }

 private:
  struct Rule {
    std::vector<DirectionSample> wi;  // sub-directions, weight includes 1/count
  };
  Rule rule(int incidenceBin, const std::optional<Vec3>& exactDirection, int s) const;
  double pairs(bool collimated) const;
  // Σ_t P_t / Ω⊥ into `out` (nLambda × nBins) for a rule, the visibility's error bound into
  // `uncertain`; counts rays.
  void sum(const Rule& r, std::vector<double>& out, std::vector<double>& uncertain, uint64_t* rays) const;

  const Microgeometry& g_;
  const PeriodicScene& scene_;
  const Material& material_;
  std::vector<double> lambda_um_;
  std::vector<Complex> ior_;
  const DirectionGrid& grid_;
  struct Plane {
    Vec3 n;  // unit, into the upper medium
    double area;
    size_t first, count;  // its facets: planeFacets_[first … first + count)
  };
  std::vector<Plane> planes_;           // the facets grouped by orientation
  std::vector<uint32_t> planeFacets_;   // every plane's facets, plane after plane, in mesh order
  std::vector<double> planeFacetArea_;  // and their areas
  size_t facets_ = 0;
  double footprint_;
  SlopeBound slope_;
  std::vector<ConductorFresnelTable> fresnel_;  // conductor: per wavelength
};

}  // namespace mbsdf
