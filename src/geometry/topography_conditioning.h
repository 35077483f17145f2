// What a measured height map needs before it is a periodic microgeometry, in the order metrology
// software applies it (ISO 25178-2: the F-operator, form removal, comes before any analysis):
//   1. crop: a window of the grid (texels);
//   2. level: the least-squares plane or polynomial of the measured points removed (the sample's tilt
//      on the stage and its form), fitted on the valid points only;
//   3. fill: each point the instrument did not measure gets the harmonic (Laplace) interpolation of
//      its measured surroundings — the smoothest surface through the hole's rim, which adds no slope
//      the rim does not have (as Gwyddion's "Laplace" data interpolation does);
//   4. edges: the program repeats the patch in x and y (periodic boundary, docs/physics.md §4). A
//      measured patch is not periodic: its opposite edges meet at a step. `wrap` keeps it (the step
//      is a ridge of the surface, scattering like one); `mirror` reflects the patch into a 2(nx−1) x
//      2(ny−1) one that is continuous at every edge (but mirror-symmetric: its diffraction has the
//      doubled period's finer orders); `window` blends a border of the patch towards its mean height
//      with a cosine (Tukey) taper, continuous too, but the border's heights are no longer measured.
#pragma once
#include <array>
#include <optional>
#include <string>

#include "geometry/topography.h"

namespace mbsdf {

enum class Levelling { None, Plane, Polynomial };
enum class EdgeTreatment { Wrap, Mirror, Window };

struct TopographyConditioning {
  std::optional<std::array<int, 4>> crop;  // first column, first row, columns, rows
  Levelling level = Levelling::None;
  int levelOrder = 1;  // total degree of the polynomial (Plane: 1)
  EdgeTreatment edges = EdgeTreatment::Wrap;
  double windowFraction = 0.1;  // window: the tapered border's width on each side, as a fraction
};

struct ConditioningReport {
  size_t filled = 0;  // points the instrument did not measure, filled by step 3
  double filledFraction = 0;
  int fillSweeps = 0;          // relaxation sweeps it took
  double removedTilt_deg = 0;  // the plane part of what step 2 removed
  double removedForm_um = 0;   // rms of the removed polynomial over the grid
  int nx = 0, ny = 0;          // the grid meshed, after step 4
  std::string describe() const;
};

// Throws InputError (naming `where`) on a crop outside the grid or a grid with no measured point.
Topography conditionTopography(Topography t, const TopographyConditioning& c, const std::string& where,
                               ConditioningReport* report);

// The pieces, for tests.
void fillInvalidPoints(Topography& t, ConditioningReport* report);
void removePolynomial(Topography& t, int order, ConditioningReport* report);

Levelling parseLevelling(const std::string& s, const std::string& where);
EdgeTreatment parseEdgeTreatment(const std::string& s, const std::string& where);
std::string toString(Levelling l);
std::string toString(EdgeTreatment e);

}  // namespace mbsdf
