#include "scattering/flat_interface.h"

#include <cmath>

#include "scattering/lobe_shares.h"

namespace mbsdf {

namespace {

// Adds energy E of a beam along direction cosines (cx, cy) on the side zs (+1 above the surface),
// spread into a Gaussian spot of standard deviation sd (0: none), to the cells: by the spot's shares
// of the bins in closed form where the grid has them (gaussianLobeShares), else by stratified points.
void addSpot(const DirectionGrid& grid, double cx, double cy, double sd, double zs, double E,
             const std::vector<int>& cellOf, std::vector<double>& cells) {
  auto add = [&](int b, double e) {
    if (b >= 0 && cellOf[size_t(b)] >= 0) cells[size_t(cellOf[size_t(b)])] += e;
  };
  std::vector<std::pair<int, double>> shares;
  if (sd > 0 && gaussianLobeShares(grid, cx, cy, sd, zs > 0, &shares)) {
    for (const auto& [b, share] : shares) add(b, E * share);
    return;
  }
  static const std::vector<std::pair<double, double>> strata = gaussianStrata(32, 16), centre{{0.0, 0.0}};
  const std::vector<std::pair<double, double>>& spots = sd > 0 ? strata : centre;
  for (const auto& [dx, dy] : spots) {
    const double x = cx + sd * dx, y = cy + sd * dy, r2 = x * x + y * y;
    if (r2 < 1) add(grid.binOf({x, y, zs * std::sqrt(1 - r2)}), E / double(spots.size()));
  }
}

}  // namespace

EnsembleSlice flatInterfaceSlice(const DirectionGrid& grid, const std::vector<std::pair<Vec3, double>>& wis,
                                 double lambda_um, const FlatInterfaceMedia& media, double windowSigma_um,
                                 const std::vector<int>& cellOf, int nCells) {
  EnsembleSlice out;
  out.coherent.assign(size_t(nCells), 0.0);
  out.diffuse.assign(size_t(nCells), 0.0);
  out.geometric.assign(size_t(nCells), 0.0);
  const double k0 = 2 * kPi / lambda_um;
  // The window's spot in a medium of index n (coherence_window.h).
  auto spread = [&](double n) { return windowSigma_um > 0 ? 1.0 / (std::sqrt(2.0) * windowSigma_um * n * k0) : 0.0; };
  for (const auto& [wi, weight] : wis) {
    const double zs = wi.z >= 0 ? 1.0 : -1.0, cosI = std::abs(wi.z);
    const double R = media.reflectance(cosI);
    // Reflected: ω_xy = −ωi_xy on the incident side; transmitted: n_o ω_xy = −n_i ωi_xy beyond
    // (Snell), none past the critical angle (R = 1 there).
    addSpot(grid, -wi.x, -wi.y, spread(media.nIncident), zs, weight * R, cellOf, out.coherent);
    addSpot(grid, -wi.x, -wi.y, 0.0, zs, weight * R, cellOf, out.geometric);
    if (!media.nBeyond) continue;
    const double ratio = media.nIncident / *media.nBeyond;
    const double tx = -ratio * wi.x, ty = -ratio * wi.y;
    if (tx * tx + ty * ty >= 1 || R >= 1) continue;
    addSpot(grid, tx, ty, spread(*media.nBeyond), -zs, weight * (1 - R), cellOf, out.coherent);
    addSpot(grid, tx, ty, 0.0, -zs, weight * (1 - R), cellOf, out.geometric);
  }
  return out;
}

}  // namespace mbsdf
