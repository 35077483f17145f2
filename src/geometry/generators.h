// Procedural microgeometry (docs/job-reference.md "[geometry]"). All lengths in µm, all patches centred and
// periodic unless said otherwise. Each generator documents its shape; parameters come from the job
// file's [geometry] table (docs/job-reference.md).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "geometry/microgeometry.h"

namespace mbsdf {

// A flat interface z = 0 (two triangles, or a grid when ground noise needs vertices).
Microgeometry makeFlat(double sizeX, double sizeY, double resolution_um);

// 1D profiles z(x) extruded along y. The patch must hold a whole number of periods.
// Sine: z = amplitude sin(2π x / period).
Microgeometry makeSineGrating(double sizeX, double sizeY, double period, double amplitude, int samplesPerPeriod,
                              double resolution_um);
// Binary (rectangular) grating: ridges of height `depth` and width duty·period with vertical walls.
Microgeometry makeBinaryGrating(double sizeX, double sizeY, double period, double depth, double duty,
                                double resolution_um);
// Ridged: triangular (V-groove) profile with apex angle `apexDeg` at the ridges and valleys,
// depth = period / (2 tan(apex/2)). apexDeg = 90 gives the 90° V-groove.
Microgeometry makeRidged(double sizeX, double sizeY, double period, double apexDeg, double resolution_um);

// Heightfields on an n x n grid.
Microgeometry makeGaussian(double sizeX, double sizeY, double rms, double corr, int nx, int ny, uint64_t seed);
// Sparse-convolution noise (the paper's NOISE): bumps of radius feature_radius_um scattered at
// density_per_um2, scaled to height rms_um, sampled on texels[0] x texels[1].
struct NoiseShape {
  std::array<double, 2> size_um;
  double rms_um, feature_radius_um, density_per_um2;
  std::array<int, 2> texels;
  uint64_t seed;
};
Microgeometry makeNoise(const NoiseShape& shape);

// Lattice of half-ellipsoids (radii rx, ry in the plane, height rz) on the plane z = 0, one per
// cell of size spacing_um (hemispheres: rx = ry = rz; axicon: 0.4, 0.45, 0.3 µm in the
// paper's Fig. 12). Watertight: the dome bases share their vertices with the ground.
struct DomeLatticeShape {
  std::array<double, 2> size_um, spacing_um;
  std::array<double, 3> radii_um;  // rx, ry in the plane, rz the height
  double resolution_um;
};
Microgeometry makeDomeLattice(const DomeLatticeShape& shape);

// Mushrooms, one per square cell of side spacing_um: a cylindrical stem carrying a cap with a flat
// underside (cap_radius_um > stem_radius_um) and a dome of height cap_height_um. The cap overhangs: not a heightfield.
struct OverhangShape {
  std::array<double, 2> size_um;
  double spacing_um, stem_radius_um, stem_height_um, cap_radius_um, cap_height_um, resolution_um;
};
Microgeometry makeOverhang(const OverhangShape& shape);

// Ground noise: displaces every vertex in z by a periodic Gaussian random field of the given rms
// and correlation length (both µm).
void addGroundNoise(Microgeometry& g, double rms, double corr, uint64_t seed);

// Grid size for a heightfield with texel <= target (power-of-two friendly, clamped).
int gridSizeFor(double size, double texel, int maxN = 2048);

}  // namespace mbsdf
