#include "geometry/surface_sampler.h"

#include <algorithm>
#include <cmath>

namespace mbsdf {

SurfaceSampler::SurfaceSampler(const Microgeometry& g) : g_(g) {
  cdf_.reserve(g.triangles.size());
  normals_.reserve(g.triangles.size());
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    Vec3 n = g.triangleNormal(t);
    double a = 0.5 * length(n);
    total_ += a;
    cdf_.push_back(total_);
    normals_.push_back(a > 0 ? n / (2 * a) : Vec3(0, 0, 1));
  }
}

SurfaceSample SurfaceSampler::sample(double u1, double u2, double u3) const {
  double target = u1 * total_;
  size_t t = size_t(std::upper_bound(cdf_.begin(), cdf_.end(), target) - cdf_.begin());
  t = std::min(t, cdf_.size() - 1);
  // Uniform point in the triangle (square-root parametrisation).
  double su = std::sqrt(u2);
  double b0 = 1 - su, b1 = u3 * su;
  const auto& tri = g_.triangles[t];
  Vec3 x = g_.vertices[tri[0]] * b0 + g_.vertices[tri[1]] * b1 + g_.vertices[tri[2]] * (1 - b0 - b1);
  return {x, normals_[t], unsigned(t)};
}

}  // namespace mbsdf
