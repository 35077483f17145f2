#include "geometry/embree_scene.h"

#include <algorithm>
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

// An occlusion query's context with the triangle its ray leaves, which the filter below skips
// (Embree's documented way to pass per-query data to a filter: the context first in a larger
// struct). The filter is the scene's occlusion filter, so every occlusion query of a PeriodicScene
// passes one of these.
struct SkipContext {
  RTCIntersectContext ctx;
  unsigned skipPrim;
};

void skipLeftTriangle(const RTCFilterFunctionNArguments* args) {
  const auto* c = reinterpret_cast<const SkipContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i)
    if (args->valid[i] == -1 && RTCHitN_primID(args->hit, args->N, i) == c->skipPrim) args->valid[i] = 0;
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
  slabLo_ = {-sizeX_ / 2, -sizeY_ / 2, zGeoLo_};
  slabHi_ = {sizeX_ / 2, sizeY_ / 2, zGeoHi_};
  // escapes() skips the triangle a ray leaves by a filter function: an Embree built without them
  // would count it as met, and every visibility ray as blocked.
  if (!rtcGetDeviceProperty(device_.get(), RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED))
    throw std::runtime_error(
        "Embree was built without filter functions (EMBREE_FILTER_FUNCTION), which the "
        "visibility rays need");
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
  rtcSetGeometryOccludedFilterFunction(geom, skipLeftTriangle);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_.get(), geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_.get());
  hitTriangles_.resize(g.triangles.size());
  double zw = 0, w = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    Vec3 n = g.triangleNormal(t);
    if (n.z > 0) {
      zw += n.z * (g.vertices[tri[0]].z + g.vertices[tri[1]].z + g.vertices[tri[2]].z) / 3;
      w += n.z;
    }
    double l = length(n);
    hitTriangles_[t] = {g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]], l > 0 ? n / l : Vec3(0, 0, 1)};
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

bool PeriodicScene::slabExit(const Vec3& o, const Vec3& d, double* tExit, int* face, TraceResult* r) const {
  *tExit = std::numeric_limits<double>::infinity();
  *face = 2;
  if (!periodic_) return false;  // a finite patch: one unbounded query
  // Above (below) every triangle and not moving towards them: the ray has met all it can, however
  // close to the horizon it travels (the wrap limit would otherwise end it).
  if (d.z >= 0 && o.z >= zGeoHi_) {
    r->kind = TraceResult::Kind::EscapedUp;
    return true;
  }
  if (d.z <= 0 && o.z <= zGeoLo_) {
    r->kind = TraceResult::Kind::EscapedDown;
    return true;
  }
  for (int a = 0; a < 3; ++a) {
    double t = std::numeric_limits<double>::infinity();
    if (d[a] > 0)
      t = (slabHi_[a] - o[a]) / d[a];
    else if (d[a] < 0)
      t = (slabLo_[a] - o[a]) / d[a];
    if (t < *tExit) {
      *tExit = t;
      *face = a;
    }
  }
  *tExit = std::max(*tExit, 0.0);
  return false;
}

TraceResult PeriodicScene::hitRecord(unsigned primID, float u_f, float v_f, float tfar) const {
  // Rebuild the point on the double-precision triangle (the origin was re-based by whole periods
  // at each wrap, so it is in the patch's own coordinates).
  const HitTriangle& tri = hitTriangles_[primID];
  const double u = u_f, v = v_f;
  TraceResult r;
  r.kind = TraceResult::Kind::Hit;
  r.t = tfar;
  r.p = tri.v0 * (1 - u - v) + tri.v1 * u + tri.v2 * v;
  r.n = tri.n;
  r.prim = primID;
  return r;
}

bool PeriodicScene::wrapOrEscape(Vec3* o, const Vec3& d, double tExit, int face, TraceResult* r) const {
  if (!periodic_) {
    // Left the finite patch: up, down, or exactly sideways.
    r->kind = d.z > 0 ? TraceResult::Kind::EscapedUp
                      : (d.z < 0 ? TraceResult::Kind::EscapedDown : TraceResult::Kind::EscapedSide);
    return true;
  }
  if (face == 2) {
    r->kind = d.z > 0 ? TraceResult::Kind::EscapedUp : TraceResult::Kind::EscapedDown;
    return true;
  }
  // Re-enter from the opposite side at the same height with the same direction.
  const double size[2] = {sizeX_, sizeY_};
  *o = *o + d * tExit;
  (*o)[face] = d[face] > 0 ? slabLo_[face] : slabHi_[face];
  const int other = 1 - face;
  if ((*o)[other] < slabLo_[other]) (*o)[other] += size[other];
  if ((*o)[other] > slabHi_[other]) (*o)[other] -= size[other];
  return false;
}

static float segmentEnd(double tExit, double eps) {
  return tExit == std::numeric_limits<double>::infinity() ? std::numeric_limits<float>::infinity() : float(tExit + eps);
}

TraceResult PeriodicScene::trace(Vec3 o, const Vec3& d, int ignorePrim) const {
  return traceFrom(o, d, ignorePrim, 0);
}

TraceResult PeriodicScene::traceFrom(Vec3 o, const Vec3& d, int ignorePrim, int firstWrap) const {
  // The slab a ray is followed through ends at the geometry's own z bounds: a ray leaving it by
  // the top or bottom escapes there, without further queries of empty periodic copies (the last
  // ray of every path, and many wraps for rays near the horizon).
  TraceResult r;
  for (int wrap = firstWrap; wrap <= maxWraps_; ++wrap) {
    double tExit;
    int face;
    if (slabExit(o, d, &tExit, &face, &r)) return r;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    float tnear = 0.f;
    for (int retry = 0; retry < 4; ++retry) {
      rh = makeRayHit(o, d, tnear, segmentEnd(tExit, eps_));
      rtcIntersect1(scene_.get(), &ctx, &rh);
      // Only the first segment after a hit can meet the triangle it leaves (a flat triangle
      // cannot be crossed twice by one straight segment; after a wrap it is another copy).
      if (wrap > 0 || rh.hit.geomID == RTC_INVALID_GEOMETRY_ID || int(rh.hit.primID) != ignorePrim) break;
      tnear = std::nextafter(rh.ray.tfar, std::numeric_limits<float>::infinity());
    }
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID && !(wrap == 0 && int(rh.hit.primID) == ignorePrim))
      return hitRecord(rh.hit.primID, rh.hit.u, rh.hit.v, rh.ray.tfar);
    if (wrapOrEscape(&o, d, tExit, face, &r)) return r;
  }
  r.kind = TraceResult::Kind::TooManyWraps;
  return r;
}

bool PeriodicScene::escapes(Vec3 o, const Vec3& d, int ignorePrim, bool up) const {
  return escapesFrom(o, d, ignorePrim, up, 0);
}

bool PeriodicScene::escapesFrom(Vec3 o, const Vec3& d, int ignorePrim, bool up, int firstWrap) const {
  // The same segments as traceFrom(); each asks only whether something is met on it.
  TraceResult r;
  for (int wrap = firstWrap; wrap <= maxWraps_; ++wrap) {
    double tExit;
    int face;
    if (slabExit(o, d, &tExit, &face, &r)) return escapedAs(r.kind, up);
    SkipContext c;
    rtcInitIntersectContext(&c.ctx);
    // Only the first segment can meet the triangle it leaves (after a wrap it is another copy).
    c.skipPrim = wrap == 0 && ignorePrim >= 0 ? unsigned(ignorePrim) : RTC_INVALID_GEOMETRY_ID;
    RTCRay ray = makeRayHit(o, d, 0.f, segmentEnd(tExit, eps_)).ray;
    rtcOccluded1(scene_.get(), &c.ctx, &ray);
    if (ray.tfar < 0) return false;  // Embree marks a met triangle with tfar = -inf
    if (wrapOrEscape(&o, d, tExit, face, &r)) return escapedAs(r.kind, up);
  }
  return false;  // the wrap limit: counted as blocked, as trace() reports it
}

void PeriodicScene::escapesMany(std::span<const Vec3> o, const Vec3& d, int ignorePrim, bool up,
                                std::span<uint8_t> out) const {
  constexpr size_t K = 16;
  SkipContext c;
  rtcInitIntersectContext(&c.ctx);
  c.skipPrim = ignorePrim >= 0 ? unsigned(ignorePrim) : RTC_INVALID_GEOMETRY_ID;
  for (size_t p0 = 0; p0 < o.size(); p0 += K) {
    alignas(64) RTCRay16 ray;
    alignas(64) int valid[K];
    double tExit[K];
    int face[K];
    bool any = false;
    for (size_t k = 0; k < K; ++k) {
      valid[k] = 0;
      const size_t i = p0 + k;
      if (i >= o.size()) continue;
      TraceResult r;
      if (slabExit(o[i], d, &tExit[k], &face[k], &r)) {
        out[i] = escapedAs(r.kind, up);
        continue;
      }
      valid[k] = -1;
      any = true;
      ray.org_x[k] = float(o[i].x);
      ray.org_y[k] = float(o[i].y);
      ray.org_z[k] = float(o[i].z);
      ray.dir_x[k] = float(d.x);
      ray.dir_y[k] = float(d.y);
      ray.dir_z[k] = float(d.z);
      ray.tnear[k] = 0.f;
      ray.tfar[k] = segmentEnd(tExit[k], eps_);
      ray.mask[k] = 0xFFFFFFFFu;
      ray.flags[k] = 0;
      ray.time[k] = 0.f;
      ray.id[k] = 0;
    }
    if (!any) continue;
    rtcOccluded16(valid, scene_.get(), &c.ctx, &ray);
    for (size_t k = 0; k < K && p0 + k < o.size(); ++k) {
      if (!valid[k]) continue;
      const size_t i = p0 + k;
      if (ray.tfar[k] < 0) {
        out[i] = 0;
        continue;
      }
      Vec3 oi = o[i];
      TraceResult r;
      out[i] = wrapOrEscape(&oi, d, tExit[k], face[k], &r) ? escapedAs(r.kind, up) : escapesFrom(oi, d, -1, up, 1);
    }
  }
}

void PeriodicScene::traceMany(std::span<const Vec3> o, std::span<const Vec3> d, std::span<const int> ignorePrim,
                              TraceMode mode, std::span<TraceResult> out) const {
  const size_t n = o.size();
  auto leaves = [&](size_t i) { return ignorePrim.empty() ? -1 : ignorePrim[i]; };
  // Each ray's first segment (wrap 0): where it ends, and what Embree met on it.
  struct Segment {
    double tExit = 0;
    int face = 2;
    bool asked = false;
    unsigned primID = RTC_INVALID_GEOMETRY_ID;
    float u = 0, v = 0, tfar = 0;
  };
  thread_local std::vector<Segment> segments;
  segments.assign(n, Segment{});
  // The record of each hit is prefetched as Embree returns it, so that its memory latency overlaps
  // the next rays' traversal instead of stalling each ray in turn; the records are read after all
  // rays have been asked.
  auto met = [&](size_t i, unsigned primID, float u, float v, float tfar) {
    Segment& sg = segments[i];
    sg.primID = primID;
    sg.u = u;
    sg.v = v;
    sg.tfar = tfar;
    __builtin_prefetch(&hitTriangles_[primID]);
    __builtin_prefetch(reinterpret_cast<const char*>(&hitTriangles_[primID]) + 64);
  };
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (mode == TraceMode::Single) {
    for (size_t i = 0; i < n; ++i) {
      Segment& sg = segments[i];
      if (slabExit(o[i], d[i], &sg.tExit, &sg.face, &out[i])) continue;
      sg.asked = true;
      RTCRayHit rh = makeRayHit(o[i], d[i], 0.f, segmentEnd(sg.tExit, eps_));
      rtcIntersect1(scene_.get(), &ctx, &rh);
      if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) met(i, rh.hit.primID, rh.hit.u, rh.hit.v, rh.ray.tfar);
    }
  } else {
    // Packets of 16 rays in the order given: rays ordered by origin (geometry/ray_order.h) share
    // the tree's nodes down to its leaves when they are near-parallel.
    constexpr size_t K = 16;
    for (size_t p0 = 0; p0 < n; p0 += K) {
      alignas(64) RTCRayHit16 rh;
      alignas(64) int valid[K];
      for (size_t k = 0; k < K; ++k) {
        valid[k] = 0;
        rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
        if (p0 + k >= n) continue;
        const size_t i = p0 + k;
        Segment& sg = segments[i];
        if (slabExit(o[i], d[i], &sg.tExit, &sg.face, &out[i])) continue;
        sg.asked = true;
        valid[k] = -1;
        rh.ray.org_x[k] = float(o[i].x);
        rh.ray.org_y[k] = float(o[i].y);
        rh.ray.org_z[k] = float(o[i].z);
        rh.ray.dir_x[k] = float(d[i].x);
        rh.ray.dir_y[k] = float(d[i].y);
        rh.ray.dir_z[k] = float(d[i].z);
        rh.ray.tnear[k] = 0.f;
        rh.ray.tfar[k] = segmentEnd(sg.tExit, eps_);
        rh.ray.mask[k] = 0xFFFFFFFFu;
        rh.ray.flags[k] = 0;
        rh.ray.time[k] = 0.f;
        rh.ray.id[k] = 0;
      }
      rtcIntersect16(valid, scene_.get(), &ctx, &rh);
      for (size_t k = 0; k < K && p0 + k < n; ++k)
        if (valid[k] && rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID)
          met(p0 + k, rh.hit.primID[k], rh.hit.u[k], rh.hit.v[k], rh.ray.tfar[k]);
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const Segment& sg = segments[i];
    if (!sg.asked) continue;
    if (sg.primID != RTC_INVALID_GEOMETRY_ID && int(sg.primID) == leaves(i)) {
      // It met the triangle it leaves: trace() asks again beyond it, as it does.
      out[i] = traceFrom(o[i], d[i], leaves(i), 0);
      continue;
    }
    if (sg.primID != RTC_INVALID_GEOMETRY_ID) {
      out[i] = hitRecord(sg.primID, sg.u, sg.v, sg.tfar);
      continue;
    }
    Vec3 oi = o[i];
    if (!wrapOrEscape(&oi, d[i], sg.tExit, sg.face, &out[i])) out[i] = traceFrom(oi, d[i], leaves(i), 1);
  }
}

}  // namespace mbsdf
