// The random walk in the homogeneous microflake volume (docs/physics.md §9; Dupuy et al. 2016, Eqs. 4–11 and
// Sec. 3; the dielectric continuation follows Heitz, Hanika, d'Eon & Dachsbacher 2016,
// "Multiple-scattering microfacet BSDFs with the Smith model", Sec. 5).
//
// The medium fills z ≤ 0 with density 1. A path enters at z = 0 travelling −wi, flies exponential
// free paths with the direction-dependent extinction σ(d), picks a visible normal at each
// collision and scatters on the flake:
//  - specular flakes of the job's material: conductor → mirror reflection weighted by the
//    (per-wavelength) Fresnel reflectance; dielectric → Fresnel reflection or refraction chosen by
//    Russian roulette; a refracted path continues on the other side of the surface: the frame is
//    point-reflected (d → −d) and the depth maps by the flipped height distribution,
//    z → log(1 − e^z) (heights are symmetric, so C1(−h) = 1 − C1(h) with z = log C1(h), seed
//    Eq. 13). Escaping from the lower side is transmission.
//  - diffuse flakes: Lambertian reflection about the flake normal.
// Paths whose weights all fall below 1/4 continue by Russian roulette.
// Every scattering is also weighted by `flakeAlbedo` (1 by default; a < 1 gives the albedo of
// Chandrasekhar's medium with the constant NDF).
// Components: depth 1 → `coherent` (single scattering), depth ≥ 2 → `multiple`, as for explicit
// geometry. Estimator and determinism: the same chunked tallies as the explicit path tracer
// (path j of tile t uses Sampler(seed, t, j, group)).
#pragma once
#include <functional>
#include <optional>
#include <vector>

#include "core/direction_grid.h"
#include "microflake/ndf.h"
#include "optics/fresnel_table.h"
#include "optics/material.h"
#include "scattering/geometric_estimator.h"
#include "scattering/path_tally.h"
#include "scattering/tile_result.h"

namespace mbsdf {

enum class FlakeKind { Specular, Diffuse };

struct MicroflakeSettings {
  uint64_t paths = 100000;  // per wavelength group
  int maxDepth = 100;
  uint64_t seed = 1;
  FlakeKind flakes = FlakeKind::Specular;
  double flakeAlbedo = 1.0;
};

class MicroflakeWalk : public GeometricEstimator {
 public:
  MicroflakeWalk(const MicroflakeDistribution& dist, const Material& material, std::vector<double> lambda_um,
                 const DirectionGrid& grid, MicroflakeSettings settings);

  // Same contract as PathTracer::run.
  using GeometricEstimator::run;
  TileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress) const override;
  bool deterministic() const override { return false; }

  struct PathRecord {
    Vec3 wi, wo;
    int exitBin = -1;
    int depth = 0;
    std::vector<double> weight;
  };
  PathRecord replay(int tile, int incidenceBin, uint64_t path, int group = 0,
                    std::optional<Vec3> exactDirection = std::nullopt) const;

 private:
  // What every path of a collimated incidence shares: its first flight's extinction and what its
  // first collision's visible normal needs of the incidence, computed once per tile instead of
  // once per path (the same values, so the same paths).
  struct FirstCollision {
    double sigma = 0;
    MicroflakeDistribution::VisibleFrom visible;
  };
  std::optional<FirstCollision> firstCollision(const std::optional<Vec3>& exact) const;
  void walk(int tile, int incidenceBin, const std::optional<Vec3>& exact, const FirstCollision* first, uint64_t path,
            int group, PathChunk& out, PathRecord* rec) const;
  const MicroflakeDistribution& dist_;
  const Material& material_;
  std::vector<double> lambda_um_;
  std::vector<Complex> ior_;
  std::vector<ConductorFresnelTable> fresnel_;  // conductor: per wavelength
  std::vector<std::vector<int>> groups_;
  const DirectionGrid& grid_;
  MicroflakeSettings settings_;
};

}  // namespace mbsdf
