// What fabrication does to a designed surface, as operators on its height map, so that a designed
// structure and its produced variant come from one job ([geometry.defects]). The surface is first
// sampled on a grid of `texel_um` (a heightfield's own grid when it has one; otherwise vertical rays
// through the Embree scene, which needs a surface that is a height function: no overhangs), then,
// in the order a process applies them:
//   depth_scale      z → z_min + s (z − z_min): an etch or deposition depth error (0.95 = −5 %);
//   lateral roughness  the surface displaced in x and y by a smooth random field (rms, correlation),
//                    z'(x) = z(x + u(x)): line-edge roughness of lithography, wavy edges;
//   sidewall angle   walls no steeper than the angle from horizontal: the morphological opening by a
//                    cone of that slope (Serra 1982; ISO 16610-41's morphological filters), which
//                    keeps a ridge's base and narrows its top — an etched wall's taper;
//   edge radius      convex edges rounded by the opening with a ball of that radius, concave corners
//                    by the closing (ISO 16610-41's "closing/opening envelope" with a disk, in 3-D):
//                    what a tool's or a resist's finite resolution leaves.
// Added ground noise is [geometry] ground_noise_rms_nm, applied after these.
#pragma once
#include <cstdint>
#include <string>

#include "geometry/microgeometry.h"
#include "geometry/topography.h"

namespace mbsdf {

struct FabricationDefects {
  double texel_um = 0;  // the raster; 0: the heightfield's own grid, else required
  double depthScale = 1;
  double lateralRms_um = 0, lateralCorrelation_um = 0.5;
  double sidewallAngle_deg = 90;  // 90: walls as designed
  double edgeRadius_um = 0;
  uint64_t seed = 1;
  bool any() const { return depthScale != 1 || lateralRms_um > 0 || sidewallAngle_deg < 90 || edgeRadius_um > 0; }
  std::string describe() const;
};

// The height map of `g` on a grid of `texel_um` (nodes at −size/2 + i·texel, as heightfieldMesh lays
// them out), or g's own grid when it is a heightfield and texel_um is 0. Throws InputError (naming
// `where`) for a surface that is not a height function or a raster too fine.
Topography rasteriseHeights(const Microgeometry& g, double texel_um, const std::string& where);

// The operators, in the order above, on a periodic grid.
void applyFabricationDefects(Topography& t, const FabricationDefects& d, const std::string& where);

// The pieces, for tests: grey-scale morphology on a periodic grid.
// Opening and closing by a ball of radius r (structuring function √(r² − d²) − r).
void openWithBall(Topography& t, double radius_um);
void closeWithBall(Topography& t, double radius_um);
// Opening by a cone of slope s: the largest surface below the original whose every convex part is a
// union of cones of slope s (walls at most atan(s) from horizontal).
void openWithCone(Topography& t, double slope);

}  // namespace mbsdf
