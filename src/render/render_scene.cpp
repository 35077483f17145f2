#include "render/render_scene.h"

#include <cmath>
#include <limits>

namespace mbsdf {

RenderScene::RenderScene(RenderMesh mesh) : device_(makeEmbreeDevice()), mesh_(std::move(mesh)) {
  scene_.reset(rtcNewScene(device_.get()));
  rtcSetSceneFlags(scene_.get(), RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geom = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                         3 * sizeof(float), mesh_.positions.size()));
  double extent = 0;
  for (size_t i = 0; i < mesh_.positions.size(); ++i) {
    const Vec3& p = mesh_.positions[i];
    vb[3 * i] = float(p.x), vb[3 * i + 1] = float(p.y), vb[3 * i + 2] = float(p.z);
    extent = std::max({extent, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  }
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                            3 * sizeof(unsigned), mesh_.triangles.size()));
  for (size_t i = 0; i < mesh_.triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) ib[3 * i + size_t(k)] = mesh_.triangles[i][size_t(k)];
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_.get(), geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_.get());
  eps_ = 64 * std::numeric_limits<float>::epsilon() * std::max(extent, 1.0);
}

std::optional<SurfaceHit> RenderScene::intersect(const Vec3& o, const Vec3& d) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh{};
  rh.ray.org_x = float(o.x), rh.ray.org_y = float(o.y), rh.ray.org_z = float(o.z);
  rh.ray.dir_x = float(d.x), rh.ray.dir_y = float(d.y), rh.ray.dir_z = float(d.z);
  rh.ray.tnear = 0, rh.ray.tfar = std::numeric_limits<float>::infinity();
  rh.ray.mask = ~0u;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_.get(), &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
  const auto& tri = mesh_.triangles[rh.hit.primID];
  const double u = rh.hit.u, v = rh.hit.v, w = 1 - u - v;
  const Vec3 &a = mesh_.positions[tri[0]], &b = mesh_.positions[tri[1]], &c = mesh_.positions[tri[2]];
  SurfaceHit h;
  h.p = w * a + u * b + v * c;
  h.t = length(h.p - o);
  h.ns = w * mesh_.normals[tri[0]] + u * mesh_.normals[tri[1]] + v * mesh_.normals[tri[2]];
  h.ns = length(h.ns) > 0 ? normalize(h.ns) : Vec3{0, 0, 1};
  const Vec3 n = cross(b - a, c - a);
  h.ng = length(n) > 0 ? normalize(n) : h.ns;
  if (dot(h.ng, h.ns) < 0) h.ng = -h.ng;
  return h;
}

bool RenderScene::occluded(const Vec3& o, const Vec3& d) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r{};
  r.org_x = float(o.x), r.org_y = float(o.y), r.org_z = float(o.z);
  r.dir_x = float(d.x), r.dir_y = float(d.y), r.dir_z = float(d.z);
  r.tnear = 0, r.tfar = std::numeric_limits<float>::infinity();
  r.mask = ~0u;
  rtcOccluded1(scene_.get(), &ctx, &r);
  return r.tfar < 0;  // Embree sets tfar to −inf on a hit
}

Vec3 RenderScene::offset(const SurfaceHit& h, const Vec3& d) const {
  return h.p + (dot(d, h.ng) >= 0 ? eps_ : -eps_) * h.ng;
}

}  // namespace mbsdf
