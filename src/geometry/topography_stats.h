// Areal texture parameters of a height map (ISO 25178-2), computed on the grid the program meshes
// (after conditioning, periodic as the patch repeats), and what they mean for the simulation.
//   Sq, Sa, Ssk, Sku: rms, mean absolute, skewness, kurtosis of the heights about their mean;
//   Sdq: rms slope, from the slopes of the mesh's own triangles (forward differences), which is
//     what the path tracer sees;
//   Sal: autocorrelation length, the shortest lag at which the (circular) autocorrelation falls to
//     0.2 (ISO 25178-2's s = 0.2), by FFT;
//   slope angles: the distribution of the triangles' inclinations (percentiles);
//   seam: the rms height step across the patch's wrap (last column to first, last row to first)
//     over the rms step between neighbouring texels inside: 1 for a periodic surface, much more where
//     a measured patch's opposite edges do not meet.
#pragma once
#include <string>

#include "geometry/topography.h"

namespace mbsdf {

struct TopographyStats {
  int nx = 0, ny = 0;
  double dx_um = 0, dy_um = 0;
  double Sq_um = 0, Sa_um = 0, Sz_um = 0, Ssk = 0, Sku = 0;
  double Sdq = 0;
  double Sal_um = 0;
  double slope_deg[4] = {0, 0, 0, 0};  // median, 90th, 99th percentile and maximum of the triangles' inclinations
  double seamRatioX = 1, seamRatioY = 1;
  // Multi-line text for `check`, with what the grid resolves at the job's shortest wavelength.
  std::string describe(double lambdaMin_um) const;
  // Whether the seam is a feature the user should hear about: steps across the wrap over 3x the
  // inside ones.
  bool seamStands() const { return seamRatioX > 3 || seamRatioY > 3; }
};

// Sal needs two FFTs of the grid; a job's loading skips it (withSal = false), `check` computes it.
TopographyStats topographyStats(const Topography& t, bool withSal = true);

}  // namespace mbsdf
