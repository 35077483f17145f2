#include "geometry/embree_scene.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace mbsdf {
namespace {
RTCRayHit makeRayHit(const Vec3& o, const Vec3& d, float tnear, float tfar) {
  RTCRayHit rh;
  rh.ray.org_x = float(o.x);
  rh.ray.org_y = float(o.y);
  rh.ray.org_z = float(o.z);
  rh.ray.dir_x = float(d.x);
  rh.ray.dir_y = float(d.y);
  rh.ray.dir_z = float(d.z);
  rh.ray.tnear = tnear;
  rh.ray.tfar = tfar;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0.f;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

void embreeError(void*, RTCError code, const char* str) {
  throw std::runtime_error(std::string("Embree error ") + std::to_string(int(code)) + ": " + (str ? str : ""));
}
}  // namespace

EmbreeDevicePtr makeEmbreeDevice(const char* config) {
  RTCDevice d = rtcNewDevice(config);
  if (!d)
    throw std::runtime_error("Embree: cannot create device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) +
                             ")");
  rtcSetDeviceErrorFunction(d, embreeError, nullptr);
  return EmbreeDevicePtr(d);
}

PeriodicScene::PeriodicScene(const Microgeometry& g, int maxWraps)
    : device_(makeEmbreeDevice()), sizeX_(g.sizeX), sizeY_(g.sizeY), periodic_(g.periodic), maxWraps_(maxWraps) {
  double zmin = g.zMin(), zmax = g.zMax();
  double extent = std::max({g.sizeX, g.sizeY, zmax - zmin});
  // The float ulp of a coordinate of size extent/2 is ~6e-8 extent/2; the offset is ~8 ulps.
  eps_ = 2.5e-7 * extent;
  double pad = 1e-3 * extent + 0.01 * (zmax - zmin);
  zLo_ = zmin - pad;
  zHi_ = zmax + pad;
  // No triangle reaches outside [zGeoLo_, zGeoHi_], even as Embree's float copy (two float ulps of
  // the largest |z|): a ray that crosses one of these planes outward has met everything it can.
  const double margin = std::ldexp(std::max(std::abs(zmin), std::abs(zmax)), -22);
  zGeoLo_ = std::max(zLo_, zmin - margin);
  zGeoHi_ = std::min(zHi_, zmax + margin);
  scene_.reset(rtcNewScene(device_.get()));
  rtcSetSceneFlags(scene_.get(), RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene_.get(), RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                         3 * sizeof(float), g.vertices.size()));
  for (size_t i = 0; i < g.vertices.size(); ++i) {
    vb[3 * i] = float(g.vertices[i].x);
    vb[3 * i + 1] = float(g.vertices[i].y);
    vb[3 * i + 2] = float(g.vertices[i].z);
  }
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                            3 * sizeof(unsigned), g.triangles.size()));
  for (size_t t = 0; t < g.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) ib[3 * t + k] = g.triangles[t][k];
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_.get(), geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_.get());
  vertices_ = g.vertices;
  triangles_ = g.triangles;
  normals_.resize(g.triangles.size());
  double zw = 0, w = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    Vec3 n = g.triangleNormal(t);
    if (n.z > 0) {
      const auto& tri = g.triangles[t];
      zw += n.z * (g.vertices[tri[0]].z + g.vertices[tri[1]].z + g.vertices[tri[2]].z) / 3;
      w += n.z;
    }
    double l = length(n);
    normals_[t] = l > 0 ? n / l : Vec3(0, 0, 1);
  }
  zMean_ = w > 0 ? zw / w : 0.5 * (zmin + zmax);
}

bool PeriodicScene::intersectRaw(const Vec3& o, const Vec3& d, double tfar, double* t) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh = makeRayHit(o, d, 0.f, float(tfar));
  rtcIntersect1(scene_.get(), &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  *t = rh.ray.tfar;
  return true;
}

TraceResult PeriodicScene::trace(Vec3 o, const Vec3& d, int ignorePrim) const {
  // The slab a ray is followed through ends at the geometry's own z bounds: a ray leaving it by
  // the top or bottom escapes there, without further queries of empty periodic copies (the last
  // ray of every path, and many wraps for rays near the horizon).
  const double lo[3] = {-sizeX_ / 2, -sizeY_ / 2, zGeoLo_}, hi[3] = {sizeX_ / 2, sizeY_ / 2, zGeoHi_};
  const double size[2] = {sizeX_, sizeY_};
  const double inf = std::numeric_limits<double>::infinity();
  TraceResult r;
  for (int wrap = 0; wrap <= maxWraps_; ++wrap) {
    // Distance to the side of the slab the ray leaves by (a finite patch: unbounded query).
    double tExit = inf;
    int face = 2;
    if (periodic_) {
      // Above (below) every triangle and not moving towards them: the ray has met all it can,
      // however close to the horizon it travels (the wrap limit would otherwise end it).
      if (d.z >= 0 && o.z >= zGeoHi_) {
        r.kind = TraceResult::Kind::EscapedUp;
        return r;
      }
      if (d.z <= 0 && o.z <= zGeoLo_) {
        r.kind = TraceResult::Kind::EscapedDown;
        return r;
      }
      for (int a = 0; a < 3; ++a) {
        double t = inf;
        if (d[a] > 0)
          t = (hi[a] - o[a]) / d[a];
        else if (d[a] < 0)
          t = (lo[a] - o[a]) / d[a];
        if (t < tExit) {
          tExit = t;
          face = a;
        }
      }
      tExit = std::max(tExit, 0.0);
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    float tnear = 0.f;
    for (int retry = 0; retry < 4; ++retry) {
      rh = makeRayHit(o, d, tnear, tExit == inf ? std::numeric_limits<float>::infinity() : float(tExit + eps_));
      rtcIntersect1(scene_.get(), &ctx, &rh);
      // Only the first segment after a hit can meet the triangle it leaves (a flat triangle
      // cannot be crossed twice by one straight segment; after a wrap it is another copy).
      if (wrap > 0 || rh.hit.geomID == RTC_INVALID_GEOMETRY_ID || int(rh.hit.primID) != ignorePrim) break;
      tnear = std::nextafter(rh.ray.tfar, std::numeric_limits<float>::infinity());
    }
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID && !(wrap == 0 && int(rh.hit.primID) == ignorePrim)) {
      r.kind = TraceResult::Kind::Hit;
      r.t = rh.ray.tfar;
      // Rebuild the point on the double-precision triangle (o was re-based by whole periods at
      // each wrap, so it is in the patch's own coordinates).
      const auto& tri = triangles_[rh.hit.primID];
      double u = rh.hit.u, v = rh.hit.v;
      r.p = vertices_[tri[0]] * (1 - u - v) + vertices_[tri[1]] * u + vertices_[tri[2]] * v;
      r.n = normals_[rh.hit.primID];
      r.prim = rh.hit.primID;
      return r;
    }
    if (!periodic_) {
      // Left the finite patch: up, down, or exactly sideways.
      r.kind = d.z > 0 ? TraceResult::Kind::EscapedUp
                       : (d.z < 0 ? TraceResult::Kind::EscapedDown : TraceResult::Kind::EscapedSide);
      return r;
    }
    if (face == 2) {
      r.kind = d.z > 0 ? TraceResult::Kind::EscapedUp : TraceResult::Kind::EscapedDown;
      return r;
    }
    // Re-enter from the opposite side at the same height with the same direction.
    o = o + d * tExit;
    o[face] = d[face] > 0 ? lo[face] : hi[face];
    int other = 1 - face;
    if (o[other] < lo[other]) o[other] += size[other];
    if (o[other] > hi[other]) o[other] -= size[other];
  }
  r.kind = TraceResult::Kind::TooManyWraps;
  return r;
}

}  // namespace mbsdf
