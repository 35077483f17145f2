// Procedural microgeometry (docs/job-reference.md "[geometry]"). All lengths in µm, all patches centred and
// periodic unless said otherwise. Each generator documents its shape; parameters come from the job
// file's [geometry] table (docs/job-reference.md).
#pragma once
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
Microgeometry makeNoise(double sizeX, double sizeY, double rms, double radius, double density, int nx, int ny,
                        uint64_t seed);

// Lattice of half-ellipsoids (radii rx, ry in the plane, height rz) on the plane z = 0, one per
// cell of size spacingX x spacingY (hemispheres: rx = ry = rz; axicon: 0.4, 0.45, 0.3 µm in the
// paper's Fig. 12). Watertight: the dome bases share their vertices with the ground.
Microgeometry makeDomeLattice(double sizeX, double sizeY, double spacingX, double spacingY, double rx, double ry,
                              double rz, double resolution_um);

// Mushrooms: a cylindrical stem (radius stemR, height stemH) carrying a cap with a flat underside
// (radius capR > stemR) and a dome of height capH. The cap overhangs: not a heightfield.
Microgeometry makeOverhang(double sizeX, double sizeY, double spacing, double stemR, double stemH, double capR,
                           double capH, double resolution_um);

// Ground noise: displaces every vertex in z by a periodic Gaussian random field of the given rms
// and correlation length (both µm).
void addGroundNoise(Microgeometry& g, double rms, double corr, uint64_t seed);

// Grid size for a heightfield with texel <= target (power-of-two friendly, clamped).
int gridSizeFor(double size, double texel, int maxN = 2048);

}  // namespace mbsdf
