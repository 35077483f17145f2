#include "geometry/surface_sampler.h"

#include <algorithm>
#include <cmath>

namespace mbsdf {

namespace {
uint64_t spreadBits(uint64_t v) {  // 21 bits -> every third bit
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}
}  // namespace

SurfaceSampler::SurfaceSampler(const Microgeometry& g) : g_(g) {
  const size_t nt = g.triangles.size();
  double zmin = g.zMin(), zspan = std::max(g.zMax() - zmin, 1e-12);
  std::vector<std::pair<uint64_t, unsigned>> keys(nt);
  for (size_t t = 0; t < nt; ++t) {
    const auto& tri = g.triangles[t];
    Vec3 c = (g.vertices[tri[0]] + g.vertices[tri[1]] + g.vertices[tri[2]]) / 3.0;
    auto q = [](double u) { return uint64_t(std::clamp(u, 0.0, 1.0) * double((1 << 21) - 1)); };
    uint64_t code = spreadBits(q(c.x / g.sizeX + 0.5)) | spreadBits(q(c.y / g.sizeY + 0.5)) << 1 |
                    spreadBits(q((c.z - zmin) / zspan)) << 2;
    keys[t] = {code, unsigned(t)};
  }
  std::sort(keys.begin(), keys.end());
  cdf_.reserve(nt);
  normals_.reserve(nt);
  order_.reserve(nt);
  for (auto [code, t] : keys) {
    order_.push_back(t);
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
  const unsigned prim = order_[t];
  // Uniform point in the triangle (square-root parametrisation).
  double su = std::sqrt(u2);
  double b0 = 1 - su, b1 = u3 * su;
  const auto& tri = g_.triangles[prim];
  Vec3 x = g_.vertices[tri[0]] * b0 + g_.vertices[tri[1]] * b1 + g_.vertices[tri[2]] * (1 - b0 - b1);
  return {x, normals_[t], prim};
}

}  // namespace mbsdf
