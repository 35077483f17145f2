// The share of a grating order's lobe in each bin of a direction grid, integrated, not sampled.
//
// Under a Gaussian coherence window an order's far field is a Gaussian spot in the plane of
// direction cosines (x, y) = (sin θ cos φ, sin θ sin φ), isotropic with standard deviation
// sd = 1/(√2 σ n_o k0): |ŵ|² of the window's transform around the order (orders_estimator.h,
// docs/physics.md §5). A bin's share of the spot is the spot's integral over the bin's region of
// that plane. Sampling the spot at points quantises each share to the points' weight (a
// 16 x 16 pattern puts up to 1/32 of the spot on the wrong side of an edge through it, and an
// incidence bin's M x M sub-directions leave an error of order 1/M per bin); these shares have no
// such step.
//
// A disk grid's pixels are squares of that plane, and an isotropic Gaussian's share of one is a
// product of two normal distribution functions. A theta-phi grid's bins are rectangles in polar
// coordinates (r, φ): along each ray from the origin the spot's integral over a ring is closed
// (normal distribution functions and exponentials), and the remaining integral over φ, smooth
// within each sector, is taken by rules that integrate the spot's Gaussian profile across the rays
// exactly. Neither
// approximates an edge, and the pole and the horizon need no special case. A disk grid's pixels
// cut by the rim of the unit disk are not squares: there the caller samples the spot instead.
#pragma once
#include <utility>
#include <vector>

#include "core/direction_grid.h"

namespace mbsdf {

// Half width of the window of bins examined (units of sd); the outermost bins take the spot's tails
// beyond it, so the shares add up to the spot's part inside the unit disk.
inline constexpr double kLobeWindow = 5.0;

// Appends to `out` (cleared first) each bin of hemisphere `upper` that the spot N((cx, cy), sd² I)
// reaches within kLobeWindow sd, with its share. The shares add up to 1 less the part beyond the
// horizon (|(x, y)| > 1, evanescent), to within the spot's tails beyond the window. A bin may be
// listed twice (a spot around the pole of a theta-phi grid). False, with `out` empty, for a disk
// grid's spot within kLobeWindow sd of the rim, a centre outside the unit disk, or sd <= 0.
bool gaussianLobeShares(const DirectionGrid& grid, double cx, double cy, double sd, bool upper,
                        std::vector<std::pair<int, double>>* out);

}  // namespace mbsdf
