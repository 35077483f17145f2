// Uniform sampling of points by surface area on a microgeometry (docs/physics.md §5: "uniform area
// sampling with a shadow ray"), with the triangle chosen from the cumulative area table. The table
// follows a Morton (Z-order) curve through the triangle centroids, so that stratifying the first
// random number stratifies the points over the surface.
#pragma once
#include <vector>

#include "geometry/microgeometry.h"

namespace mbsdf {

struct SurfaceSample {
  Vec3 x;
  Vec3 n;  // unit geometric normal (into the upper medium)
  unsigned prim = 0;
};

class SurfaceSampler {
 public:
  explicit SurfaceSampler(const Microgeometry& g);
  double totalArea() const { return total_; }
  SurfaceSample sample(double u1, double u2, double u3) const;

 private:
  const Microgeometry& g_;
  std::vector<double> cdf_;
  std::vector<unsigned> order_;  // triangle index of each table entry (Morton order)
  std::vector<Vec3> normals_;
  double total_ = 0;
};

}  // namespace mbsdf
