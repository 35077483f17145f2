// The `exact` wave estimator's order amplitude (orders_estimator.h): Ĥ_G summed over the facets of
// one cell, Ĥ_G = Σ_T V_T g_T ∫_T e^{i q·x} dA, with the phase integrated in closed form over each
// flat facet (triangle_fourier.h, docs/physics.md §5) and g_T constant on it. Visibility (shadowing
// towards ωi, masking towards the order direction ω_G) is decided at the centroid and three inset
// points of each facet; a facet whose points disagree is split into four, down to 4^3 pieces, whose
// centroid then decides. Deterministic: facets are visited in index order.
#pragma once
#include <atomic>
#include <cstdint>
#include <vector>

#include "core/vecmath.h"
#include "geometry/lattice_cell.h"
#include "geometry/microgeometry.h"
#include "optics/fresnel.h"
#include "scattering/wave_common.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
class VisibilityTable;
}

namespace mbsdf::wave {

// An order as the facet sum needs it: its wavelength index, direction and side.
struct OrderDirection {
  int lambda;
  Vec3 wo;
  bool transmission;
};

// What every order and wavelength of one incidence direction shares, found once per direction:
//  lit      shadowing of the first-level points of every facet towards ωi (by triangle; bit k: point
//           k is lit; 0 for a facet facing away), the shared visibility table (visibility_table.h)
//           answering where it can;
//  m        each lit facet's unit normal towards the incident medium, by slot;
//  fresnel  the Fresnel amplitudes of each lit facet at its local cosine m·ωi, [λ · facets + slot]:
//           the forward integrand's only costly part that does not depend on the order (reflection
//           and transmission into the denser medium; the reverse path's depends on ω_G).
// Only the facets of `cell` (one cell of a patch that repeats it) are visited; `table` may be null.
// Rays cast are added to *rays.
struct IncidenceFacets {
  std::vector<uint8_t> lit;
  std::vector<Vec3> m;
  std::vector<FresnelAmplitudes> fresnel;
};
IncidenceFacets incidenceFacets(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                                const SlopeBound& slope, const Vec3& wi, bool fromAbove, const Media& media,
                                uint64_t* rays);

// Shadowing towards ωi of the points below the first level of every facet of the cell (the
// centroid and inset points of its sub-elements down to kExactMaxDepth: 16 + 64 + 256), found on
// first use by any order and kept for the others of the same incidence direction: 0 unknown, 1 lit,
// 2 shadowed. Orders run in parallel; two threads may cast the same ray and store the same answer.
constexpr int kExactMaxDepth = 3;
constexpr int kExactSubPoints = 16 + 64 + 256;
struct ShadowCache {
  explicit ShadowCache(size_t facets) : state(facets * kExactSubPoints) {}
  std::vector<std::atomic<uint8_t>> state;
};

// Ĥ_G for one order: H[0..1] += visible s, p; H[2..3] += masked s, p (only with `masked`). `facets`:
// incidenceFacets for this ωi (deeper points cast their own shadow rays). The order lies on the
// reciprocal lattice of `cell`, so the patch's sum is nx ny times the cell's (lattice_cell.h).
void exactAmplitude(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                    const SlopeBound& slope, const OrderDirection& ord, const Vec3& wi, bool fromAbove,
                    const Media& media, bool masked, const IncidenceFacets& facets, ShadowCache& shadow, Complex* H,
                    uint64_t* rays);

}  // namespace mbsdf::wave
