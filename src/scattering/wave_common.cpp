#include "scattering/wave_common.h"

#include <cmath>

#include "core/quadrature.h"

namespace mbsdf {
int incidenceRuleOrder(int directions) {
  return std::max(2, int(std::ceil(std::sqrt(double(std::max(1, directions))))));
}
int incidenceDirectionsOf(const WaveSettings& ws, const DirectionGrid& grid, int bin) {
  return ws.poleHorizonIncidenceDirections > 0 && grid.atPoleOrHorizon(bin) ? ws.poleHorizonIncidenceDirections
                                                                            : ws.incidenceDirections;
}
}  // namespace mbsdf

namespace mbsdf::wave {

Media::Media(const WaveContext& ctx)
    : nUpper_(ctx.material.outsideIor),
      conductor_(ctx.material.isConductor()),
      perfect_(ctx.material.isPerfectConductor()) {
  for (double l : ctx.lambda_um) lower_.push_back(perfect_ ? Complex(0, 0) : ctx.material.ior(l));
}

FresnelAmplitudes Media::fresnel(int l, double cosLocal, bool fromAbove) const {
  if (perfect_) return perfectConductorAmplitudes();
  if (fromAbove) return fresnelAmplitudes(cosLocal, nUpper_, lower_[l]);
  return fresnelAmplitudes(cosLocal, lower_[l].real(), Complex(nUpper_, 0));
}

bool escapes(const PeriodicScene& scene, const Vec3& x, const Vec3& side, const Vec3& d, unsigned prim, bool up) {
  return scene.escapes(x + side * scene.rayEpsilon(), d, int(prim), up);
}

std::vector<int> exitBins(const DirectionGrid& grid, bool fromAbove, bool dielectric, bool masked,
                          const std::vector<uint8_t>& mask) {
  std::vector<int> bins;
  for (int b = 0; b < grid.binCount(); ++b) {
    if (grid.projectedSolidAngle(b) <= 0 || (!mask.empty() && !mask[size_t(b)])) continue;
    bool reflection = grid.isUpper(b) == fromAbove;
    if (reflection || dielectric || masked) bins.push_back(b);
  }
  return bins;
}

std::vector<IncidenceNode> incidenceRule(const DirectionGrid& grid, int incidenceBin,
                                         const std::optional<Vec3>& exactDirection, int directions) {
  if (exactDirection) return {{normalize(*exactDirection), 1.0, true}};
  const int n = incidenceRuleOrder(directions);
  std::vector<IncidenceNode> nodes;
  for (int rule = n; rule >= n - 1; --rule) {
    const QuadratureRule q = gaussLegendre(rule, 0.0, 1.0);
    for (int i = 0; i < rule; ++i)
      for (int j = 0; j < rule; ++j)
        nodes.push_back({grid.sampleCosine(incidenceBin, q.x[size_t(i)], q.x[size_t(j)]).w,
                         q.w[size_t(i)] * q.w[size_t(j)], rule == n});
  }
  return nodes;
}

}  // namespace mbsdf::wave
