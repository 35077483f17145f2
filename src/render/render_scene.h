// The preview's object in Embree 3 (RAII through geometry/embree_scene.h): closest hits and
// shadow rays, hit points rebuilt in double from Embree's barycentrics, the shading normal
// interpolated from the mesh's vertex normals and the geometric normal turned to its side.
#pragma once
#include <optional>

#include "geometry/embree_scene.h"
#include "render/shapes.h"

namespace mbsdf {

struct SurfaceHit {
  Vec3 p;        // on the triangle's plane, in double
  Vec3 ng;       // unit geometric normal, on the side of ns
  Vec3 ns;       // unit shading normal (interpolated), out of the object
  double t = 0;  // distance along the unit ray
};

class RenderScene {
 public:
  explicit RenderScene(RenderMesh mesh);
  RenderScene(const RenderScene&) = delete;
  RenderScene& operator=(const RenderScene&) = delete;
  std::optional<SurfaceHit> intersect(const Vec3& o, const Vec3& d) const;
  // Whether anything lies along o + t d, t > 0.
  bool occluded(const Vec3& o, const Vec3& d) const;
  // A ray origin at a hit, moved off the surface to the side of direction d by a few float ulps of
  // the scene's extent, clear of Embree's float rounding.
  Vec3 offset(const SurfaceHit& h, const Vec3& d) const;

 private:
  EmbreeDevicePtr device_;
  EmbreeScenePtr scene_;
  RenderMesh mesh_;
  double eps_ = 0;
};

}  // namespace mbsdf
