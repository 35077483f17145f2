#include "scattering/mean_plane_control.h"

#include <cmath>

namespace mbsdf {

namespace {
constexpr size_t kMaxHeights = 256;
}

MeanPlaneControl::MeanPlaneControl(const Microgeometry& g) {
  const SurfaceClosure closure = surfaceClosureOf(g);
  usable_ = std::abs(closure.uncoveredFraction) < 1e-6 && (!g.periodic || closure.openEdges == 0);
  // Overhangs: a downward facet's Z is noise that X, dark there under light from above, does not
  // cancel; the control is kept to surfaces with no facet facing down.
  for (size_t t = 0; t < g.triangles.size() && usable_; ++t) {
    const Vec3 n = g.triangleNormal(t);
    if (n.z < -1e-9 * length(n)) usable_ = false;
  }
  if (!usable_) return;
  const size_t n = g.triangles.size(), stride = std::max<size_t>(1, (n + kMaxHeights - 1) / kMaxHeights);
  double total = 0;
  for (size_t t = 0; t < n; t += stride) {
    const auto& tri = g.triangles[t];
    const double w = 0.5 * g.triangleNormal(t).z;  // signed projected area
    if (w == 0) continue;
    z_.push_back((g.vertices[tri[0]].z + g.vertices[tri[1]].z + g.vertices[tri[2]].z) / 3);
    weight_.push_back(w);
    total += w;
  }
  if (!(total > 0)) {
    usable_ = false;
    return;
  }
  for (double& w : weight_) w /= total;
}

std::complex<double> MeanPlaneControl::coefficient(double qz) const {
  if (!usable_) return 0.0;
  double re = 0, im = 0;
  for (size_t i = 0; i < z_.size(); ++i) {
    re += weight_[i] * std::cos(qz * z_[i]);
    im += weight_[i] * std::sin(qz * z_[i]);
  }
  return {re, im};
}

}  // namespace mbsdf
