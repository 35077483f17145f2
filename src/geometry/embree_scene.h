// Embree 3 scene of a microgeometry patch with periodic ray wrapping (docs/physics.md §4 step 2).
// RAII around RTCDevice/RTCScene; the device's error callback is installed before anything else so
// that every Embree error becomes an exception with Embree's message.
//
// Precision: Embree works in float. The patch is centred on the origin, rays
// are re-based at every wrap so coordinates stay within the patch box, hit points are recomputed
// in double from Embree's barycentric coordinates on the double-precision triangle (so they lie on
// the triangle's plane to double precision), secondary rays skip the triangle they leave and start
// offset along the geometric normal by a scale-aware epsilon (rayEpsilon(): a few float ulps of the
// patch's largest coordinate, enough to clear Embree's float rounding of the ray origin).
#pragma once
#include <embree3/rtcore.h>

#include <array>
#include <memory>
#include <span>
#include <vector>

#include "core/vecmath.h"
#include "geometry/microgeometry.h"

namespace mbsdf {

struct EmbreeDeviceDeleter {
  void operator()(RTCDevice d) const { rtcReleaseDevice(d); }
};
struct EmbreeSceneDeleter {
  void operator()(RTCScene s) const { rtcReleaseScene(s); }
};
using EmbreeDevicePtr = std::unique_ptr<RTCDeviceTy, EmbreeDeviceDeleter>;
using EmbreeScenePtr = std::unique_ptr<RTCSceneTy, EmbreeSceneDeleter>;

// Creates a device with the error callback installed first (throws std::runtime_error on error).
EmbreeDevicePtr makeEmbreeDevice(const char* config = nullptr);

struct TraceResult {
  enum class Kind { Hit, EscapedUp, EscapedDown, EscapedSide, TooManyWraps };
  Kind kind = Kind::EscapedUp;
  Vec3 p;  // hit point (double)
  Vec3 n;  // unit geometric normal of the triangle (points into the upper medium)
  unsigned prim = 0;
  double t = 0;
};

enum class TraceMode { Single, Packets };

class PeriodicScene {
 public:
  explicit PeriodicScene(const Microgeometry& g, int maxWraps = 100000);
  PeriodicScene(const PeriodicScene&) = delete;
  PeriodicScene& operator=(const PeriodicScene&) = delete;

  // Trace from o along unit direction d through the (periodic) patch. Hits on `ignorePrim` (the
  // triangle the ray leaves) are skipped: a flat triangle cannot be hit again by a ray leaving it.
  // On a periodic patch a ray escapes once it is above (below) every triangle and not travelling
  // down (up), however close to the horizon: no query of the empty copies beyond.
  TraceResult trace(Vec3 o, const Vec3& d, int ignorePrim = -1) const;
  // The same for many rays: out[i] is trace(o[i], d[i], ignorePrim[i]) (no triangle to skip when
  // ignorePrim is empty). Their first segments are asked of Embree one after the other
  // (TraceMode::Single) or as packets of 16 rays in the order given (TraceMode::Packets: for
  // near-parallel rays from above or below the slab ordered by origin, such as the first rays of
  // paths, whose traversals share the tree's nodes; geometry/ray_order.h). Embree's packet kernels
  // give each ray the hit its single-ray kernel gives (tests/geometry/embree_scene_test.cpp compares
  // them ray by ray). Either way the hits' records are read only after every ray has been asked, so
  // that their memory latencies overlap.
  void traceMany(std::span<const Vec3> o, std::span<const Vec3> d, std::span<const int> ignorePrim, TraceMode mode,
                 std::span<TraceResult> out) const;
  // Whether a ray from o along d leaves the patch through its top (up) or bottom (!up) without
  // meeting a triangle other than `ignorePrim` on its first segment: trace()'s answer (a hit or
  // the wrap limit is false; a finite patch's ray that leaves it any way is true), asked of Embree
  // as occlusion queries, which stop at the first triangle met instead of searching for the
  // nearest (the visibility rays of the wave estimators).
  bool escapes(Vec3 o, const Vec3& d, int ignorePrim, bool up) const;
  // escapes() for rays along one direction from nearby points that leave the same triangle (the
  // points of one facet's sub-elements): out[i] = escapes(o[i], d, ignorePrim, up). Their first
  // segments are asked as packets of 16 (rtcOccluded16), whose near-identical traversals share the
  // tree's nodes; rays that leave a side of the periodic cell go on one by one.
  void escapesMany(std::span<const Vec3> o, const Vec3& d, int ignorePrim, bool up, std::span<uint8_t> out) const;
  // One raw Embree query without wrapping (used by the benchmark baseline).
  bool intersectRaw(const Vec3& o, const Vec3& d, double tfar, double* t) const;

  // Height at which primary rays start (above all geometry) and the slab bounds.
  double zTop() const { return zHi_; }
  double zBottom() const { return zLo_; }
  double rayEpsilon() const { return eps_; }
  // Mean height of the surface (projected-area weighted over up-facing triangles): the macro
  // surface plane at which a finite patch's footprint is illuminated.
  double zMean() const { return zMean_; }
  double sizeX() const { return sizeX_; }
  double sizeY() const { return sizeY_; }
  bool periodic() const { return periodic_; }
  size_t triangleCount() const { return hitTriangles_.size(); }
  RTCScene scene() const { return scene_.get(); }

 private:
  // Where the ray leaves the slab it is followed through at this wrap (tExit, face: 0 x, 1 y, 2 top
  // or bottom), or true when it has already met all it can (r set to the escape).
  bool slabExit(const Vec3& o, const Vec3& d, double* tExit, int* face, TraceResult* r) const;
  // The hit Embree reported (triangle, barycentrics, distance), rebuilt in double.
  TraceResult hitRecord(unsigned primID, float u, float v, float tfar) const;
  // After a segment that met nothing: true when the ray escaped (r set), else o re-enters from the
  // opposite side of the patch.
  bool wrapOrEscape(Vec3* o, const Vec3& d, double tExit, int face, TraceResult* r) const;
  // escapes() from wrap `firstWrap` on.
  bool escapesFrom(Vec3 o, const Vec3& d, int ignorePrim, bool up, int firstWrap) const;
  // What escapes() answers for a ray that left the patch as `kind`.
  bool escapedAs(TraceResult::Kind kind, bool up) const {
    if (!periodic_) return true;
    return up ? kind == TraceResult::Kind::EscapedUp : kind == TraceResult::Kind::EscapedDown;
  }
  // trace() from wrap `firstWrap` on.
  TraceResult traceFrom(Vec3 o, const Vec3& d, int ignorePrim, int firstWrap) const;

  EmbreeDevicePtr device_;
  EmbreeScenePtr scene_;
  double sizeX_, sizeY_, zLo_, zHi_, eps_, zMean_ = 0;
  double zGeoLo_ = 0, zGeoHi_ = 0;  // the triangles' z range with a margin for float rounding
  Vec3 slabLo_, slabHi_;            // the periodic cell: (-size/2, -size/2, zGeoLo_) to (size/2, size/2, zGeoHi_)
  bool periodic_;
  int maxWraps_;
  // Double copies of each triangle's corners and its unit normal (from the mesh, not Embree's float
  // Ng), in one record: a hit is rebuilt from Embree's barycentrics by reading one place in
  // memory, two cache lines, instead of four scattered ones.
  struct alignas(32) HitTriangle {
    Vec3 v0, v1, v2, n;
  };
  std::vector<HitTriangle> hitTriangles_;
};

}  // namespace mbsdf
