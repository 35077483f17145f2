// The periodic Embree scene against a double-precision brute force over the periodic copies, and
// rays at the horizon just above or below the geometry (swept in elevation).
#include "geometry/embree_scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/rng.h"
#include "geometry/generators.h"

namespace mbsdf {
namespace {

// A binary mirror grating: plateaus at z = 0 and z = 1 joined by vertical walls; the patch is
// narrow along the grooves (y), so rays along them wrap many times.
Microgeometry grating() {
  return makeBinaryGrating(2.0, 0.3, 2.0, 1.0, 0.5, 0.1);
}

// First intersection along o + t d (t > 0) with every triangle of the periodic copies the ray can
// reach while inside the geometry's z range, by Möller–Trumbore in double; the point returned is
// mapped back into the base patch.
std::optional<Vec3> bruteForceHit(const Microgeometry& g, const Vec3& o, const Vec3& d) {
  const double zmin = g.zMin(), zmax = g.zMax();
  double tMax = std::numeric_limits<double>::infinity();
  if (d.z > 0) tMax = (zmax - o.z) / d.z;
  if (d.z < 0) tMax = (zmin - o.z) / d.z;
  const double reachX = std::abs(d.x) * tMax, reachY = std::abs(d.y) * tMax;
  const int nx = int(std::ceil(reachX / g.sizeX)) + 1, ny = int(std::ceil(reachY / g.sizeY)) + 1;
  double best = std::numeric_limits<double>::infinity();
  for (int i = -nx; i <= nx; ++i)
    for (int j = -ny; j <= ny; ++j) {
      const Vec3 shift{i * g.sizeX, j * g.sizeY, 0};
      for (const auto& tri : g.triangles) {
        const Vec3 a = g.vertices[tri[0]] + shift, e1 = g.vertices[tri[1]] - g.vertices[tri[0]],
                   e2 = g.vertices[tri[2]] - g.vertices[tri[0]];
        const Vec3 p = cross(d, e2);
        const double det = dot(e1, p);
        if (std::abs(det) < 1e-14) continue;
        const Vec3 s = o - a;
        const double u = dot(s, p) / det;
        if (u < 0 || u > 1) continue;
        const Vec3 q = cross(s, e1);
        const double v = dot(d, q) / det;
        if (v < 0 || u + v > 1) continue;
        const double t = dot(e2, q) / det;
        if (t > 1e-9 && t < best) best = t;
      }
    }
  if (!std::isfinite(best)) return std::nullopt;
  Vec3 p = o + d * best;
  p.x -= g.sizeX * std::floor(p.x / g.sizeX + 0.5);
  p.y -= g.sizeY * std::floor(p.y / g.sizeY + 0.5);
  return p;
}

// Random rays from inside the slab: the scene finds the brute force's first hit (the same point
// in the base patch), or the ray escapes on the side its direction points to.
TEST(PeriodicScene, FirstHitsMatchABruteForceOverThePeriodicCopies) {
  const Microgeometry g = grating();
  const PeriodicScene scene(g);
  Sampler s(11, 0, 0);
  int hits = 0, escapes = 0;
  for (int k = 0; k < 3000; ++k) {
    const Vec3 o{(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY,
                 g.zMin() + s.get1D() * (g.zMax() - g.zMin())};
    const double z = s.get1D() < 0.5 ? 0.1 + 0.9 * s.get1D() : -(0.1 + 0.9 * s.get1D()), phi = 2 * kPi * s.get1D();
    const double r = std::sqrt(1 - z * z);
    const Vec3 d{r * std::cos(phi), r * std::sin(phi), z};
    const TraceResult tr = scene.trace(o, d);
    const std::optional<Vec3> ref = bruteForceHit(g, o, d);
    if (ref) {
      ASSERT_EQ(tr.kind, TraceResult::Kind::Hit) << "ray " << k;
      Vec3 dp = tr.p - *ref;
      dp.x -= g.sizeX * std::round(dp.x / g.sizeX);
      dp.y -= g.sizeY * std::round(dp.y / g.sizeY);
      ASSERT_LT(length(dp), 1e-5) << "ray " << k;
      ++hits;
    } else {
      ASSERT_EQ(tr.kind, d.z > 0 ? TraceResult::Kind::EscapedUp : TraceResult::Kind::EscapedDown) << "ray " << k;
      ++escapes;
    }
  }
  EXPECT_GT(hits, 1000);
  EXPECT_GT(escapes, 300);
}

// Rays leaving the top plateau at elevations from 0.1 down to 1e-14 rad, along the grooves (where
// the narrow patch wraps them every 0.3 µm) and across them: nothing lies above the plateau, so
// every one escapes upward (they used to wrap until the wrap limit, and count as blocked); along
// the grooves the same rays pointed down by as little meet the plateau they started above.
TEST(PeriodicScene, NearHorizonRaysAboveTheTopPlateau) {
  const Microgeometry g = grating();
  const PeriodicScene scene(g);
  const double zTopPlateau = g.zMax();
  for (double phi : {0.0, 0.4, kPi / 2, 2.0, kPi, 1.5 * kPi, 4.0})
    for (double elevation = 0.1; elevation > 1e-14; elevation /= 3) {
      const Vec3 up{std::cos(elevation) * std::cos(phi), std::cos(elevation) * std::sin(phi), std::sin(elevation)};
      // A point of the upper plateau (x in [-0.5, 0.5] for this grating), lifted as a path lifts
      // a secondary ray off a hit.
      const Vec3 o{0.1, 0.05, zTopPlateau + scene.rayEpsilon()};
      const TraceResult escaped = scene.trace(o, up);
      ASSERT_EQ(escaped.kind, TraceResult::Kind::EscapedUp) << "phi " << phi << " elevation " << elevation;
      // Down, along the grooves (across them the ray would pass the ridge's edge first).
      if (std::abs(std::cos(phi)) > 1e-12 || elevation < 1e-6) continue;
      const Vec3 down{up.x, up.y, -up.z};
      const TraceResult hit = scene.trace(o, down);
      ASSERT_EQ(hit.kind, TraceResult::Kind::Hit) << "phi " << phi << " elevation " << elevation;
      EXPECT_NEAR(hit.p.z, zTopPlateau, 1e-9) << "phi " << phi << " elevation " << elevation;
      EXPECT_EQ(hit.n.z, 1.0);
    }
}

// A periodic grating, a periodic dome lattice and a finite rough patch: the scenes the tracing
// functions are compared on.
std::vector<std::pair<const char*, Microgeometry>> rayCases() {
  std::vector<std::pair<const char*, Microgeometry>> cases;
  cases.emplace_back("grating", grating());
  cases.emplace_back(
      "domes",
      makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.3}));
  Microgeometry finite = makeGaussian(6, 6, 0.3, 1.0, 32, 32, 4);
  finite.periodic = false;
  cases.emplace_back("finite", std::move(finite));
  return cases;
}

// traceMany, by single rays and by packets, against trace ray by ray, to the last bit (kind,
// triangle, distance, point, normal): first rays from above and below the slab at elevations swept
// from the normal down to 1e-7 rad (wrapping many times), rays from inside the slab, and the
// secondary rays that leave the triangles those met (the triangle to skip given), on periodic
// patches (a binary grating, a dome lattice) and a finite one.
TEST(PeriodicScene, TraceManyEqualsTraceRayByRay) {
  for (auto& [name, g] : rayCases()) {
    const PeriodicScene scene(g);
    Sampler s(5, 0, 0);
    std::vector<Vec3> o, d;
    for (double elevation = kPi / 2; elevation > 1e-7; elevation /= 2.5)
      for (int side = 0; side < 2; ++side)
        for (int k = 0; k < 24; ++k) {
          const double phi = 2 * kPi * s.get1D(), z = std::sin(elevation), r = std::cos(elevation);
          o.push_back(
              {(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY, side ? scene.zBottom() : scene.zTop()});
          d.push_back({r * std::cos(phi), r * std::sin(phi), side ? z : -z});
        }
    for (int k = 0; k < 1000; ++k) {
      o.push_back(
          {(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY, g.zMin() + s.get1D() * (g.zMax() - g.zMin())});
      const double z = 2 * s.get1D() - 1, phi = 2 * kPi * s.get1D(), r = std::sqrt(1 - z * z);
      d.push_back({r * std::cos(phi), r * std::sin(phi), z});
    }
    std::vector<TraceResult> one(o.size());
    for (size_t i = 0; i < o.size(); ++i) one[i] = scene.trace(o[i], d[i]);
    // Secondary rays: reflected off each hit, lifted off it, leaving its triangle.
    std::vector<Vec3> o2, d2;
    std::vector<int> leaving;
    for (size_t i = 0; i < o.size(); ++i) {
      if (one[i].kind != TraceResult::Kind::Hit) continue;
      const Vec3 n = dot(d[i], one[i].n) < 0 ? one[i].n : -one[i].n;
      const Vec3 r = normalize(d[i] - n * (2 * dot(d[i], n)));
      o2.push_back(one[i].p + n * scene.rayEpsilon());
      d2.push_back(r);
      leaving.push_back(int(one[i].prim));
    }
    ASSERT_GT(o2.size(), 300u) << name;
    auto same = [&](const TraceResult& a, const TraceResult& b, const std::string& what) {
      ASSERT_EQ(a.kind, b.kind) << what;
      if (a.kind != TraceResult::Kind::Hit) return;
      ASSERT_EQ(a.prim, b.prim) << what;
      ASSERT_EQ(a.t, b.t) << what;
      ASSERT_EQ(a.p.x, b.p.x) << what;
      ASSERT_EQ(a.p.y, b.p.y) << what;
      ASSERT_EQ(a.p.z, b.p.z) << what;
      ASSERT_EQ(a.n.z, b.n.z) << what;
    };
    for (TraceMode mode : {TraceMode::Single, TraceMode::Packets}) {
      const std::string m = std::string(name) + (mode == TraceMode::Single ? " single" : " packets");
      std::vector<TraceResult> many(o.size());
      scene.traceMany(o, d, {}, mode, many);
      for (size_t i = 0; i < o.size(); ++i) same(many[i], one[i], m + " ray " + std::to_string(i));
      std::vector<TraceResult> many2(o2.size());
      scene.traceMany(o2, d2, leaving, mode, many2);
      for (size_t i = 0; i < o2.size(); ++i)
        same(many2[i], scene.trace(o2[i], d2[i], leaving[i]), m + " secondary " + std::to_string(i));
    }
  }
}

// escapes() asks Embree occlusion queries (with a filter that skips the triangle the ray leaves)
// where trace() asks for the nearest hit: both must give every visibility ray the same answer.
// Rays from above and below down to 1e-7 rad of elevation, rays from inside the slab, and rays
// leaving a triangle: lifted off it as the wave estimators cast them, and from the triangle's own
// plane, where Embree meets the triangle they leave at t = 0 and only the skip keeps them going.
TEST(PeriodicScene, EscapesAnswersAsTraceDoes) {
  for (auto& [name, g] : rayCases()) {
    const PeriodicScene scene(g);
    Sampler s(9, 0, 0);
    struct Ray {
      Vec3 o, d;
      int leaves;
    };
    std::vector<Ray> rays;
    for (double elevation = kPi / 2; elevation > 1e-7; elevation /= 2.5)
      for (int side = 0; side < 2; ++side)
        for (int k = 0; k < 24; ++k) {
          const double phi = 2 * kPi * s.get1D(), z = std::sin(elevation), r = std::cos(elevation);
          rays.push_back(
              {{(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY, side ? scene.zBottom() : scene.zTop()},
               {r * std::cos(phi), r * std::sin(phi), side ? z : -z},
               -1});
        }
    for (int k = 0; k < 2000; ++k) {
      const double z = 2 * s.get1D() - 1, phi = 2 * kPi * s.get1D(), r = std::sqrt(1 - z * z);
      rays.push_back(
          {{(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY, g.zMin() + s.get1D() * (g.zMax() - g.zMin())},
           {r * std::cos(phi), r * std::sin(phi), z},
           -1});
    }
    size_t leaving = 0, met = 0;
    for (size_t i = 0, n = rays.size(); i < n; ++i) {
      const TraceResult h = scene.trace(rays[i].o, rays[i].d);
      if (h.kind != TraceResult::Kind::Hit) continue;
      ++leaving;
      // Off the hit, to a random direction on either side of the triangle: lifted to that side
      // (a visibility ray) and from the hit point itself.
      const double z = 2 * s.get1D() - 1, phi = 2 * kPi * s.get1D(), r = std::sqrt(1 - z * z);
      const Vec3 d{r * std::cos(phi), r * std::sin(phi), z};
      const Vec3 side = dot(d, h.n) > 0 ? h.n : -h.n;
      rays.push_back({h.p + side * scene.rayEpsilon(), d, int(h.prim)});
      rays.push_back({h.p, d, int(h.prim)});
    }
    ASSERT_GT(leaving, 300u) << name;
    for (size_t i = 0; i < rays.size(); ++i) {
      const TraceResult h = scene.trace(rays[i].o, rays[i].d, rays[i].leaves);
      met += h.kind == TraceResult::Kind::Hit;
      for (bool up : {true, false}) {
        const bool expected =
            h.kind != TraceResult::Kind::Hit && h.kind != TraceResult::Kind::TooManyWraps &&
            (!scene.periodic() || h.kind == (up ? TraceResult::Kind::EscapedUp : TraceResult::Kind::EscapedDown));
        ASSERT_EQ(scene.escapes(rays[i].o, rays[i].d, rays[i].leaves, up), expected)
            << name << " ray " << i << (up ? " up" : " down");
      }
    }
    // Both answers occur often enough for the comparison to mean something.
    EXPECT_GT(met, rays.size() / 10) << name;
    EXPECT_LT(met, rays.size() * 9 / 10) << name;
  }
}

// escapesMany() asks the rays of one facet along one direction as packets of 16: each answer must
// be escapes()'s for that ray. Points spread over the hit triangles (20 per triangle: a full packet
// and a partial one), lifted off them and on them, to random directions on either side, with
// grazing ones among them.
TEST(PeriodicScene, EscapesManyAnswersAsEscapesDoes) {
  for (auto& [name, g] : rayCases()) {
    const PeriodicScene scene(g);
    Sampler s(11, 0, 0);
    size_t asked = 0, seen = 0;
    for (int k = 0; k < 600; ++k) {
      const Vec3 o{(s.get1D() - 0.5) * g.sizeX, (s.get1D() - 0.5) * g.sizeY, scene.zTop()};
      const double zi = -0.2 - 0.8 * s.get1D(), phi_i = 2 * kPi * s.get1D();
      const TraceResult h =
          scene.trace(o, {std::sqrt(1 - zi * zi) * std::cos(phi_i), std::sqrt(1 - zi * zi) * std::sin(phi_i), zi});
      if (h.kind != TraceResult::Kind::Hit) continue;
      // Every fourth direction within 1e-3 rad of the horizon.
      const double z = k % 4 == 0 ? (s.get1D() - 0.5) * 2e-3 : 2 * s.get1D() - 1, phi = 2 * kPi * s.get1D();
      const Vec3 d{std::sqrt(1 - z * z) * std::cos(phi), std::sqrt(1 - z * z) * std::sin(phi), z};
      const Vec3 side = dot(d, h.n) > 0 ? h.n : -h.n;
      const auto& tri = g.triangles[h.prim];
      const Vec3 a = g.vertices[tri[0]], b = g.vertices[tri[1]], c = g.vertices[tri[2]];
      std::vector<Vec3> pts;
      for (int j = 0; j < 20; ++j) {
        double u = s.get1D(), v = s.get1D();
        if (u + v > 1) u = 1 - u, v = 1 - v;
        const Vec3 x = a * (1 - u - v) + b * u + c * v;
        pts.push_back(k % 2 ? x : x + side * scene.rayEpsilon());
      }
      for (bool up : {true, false}) {
        std::vector<uint8_t> many(pts.size(), 7);
        scene.escapesMany(pts, d, int(h.prim), up, many);
        for (size_t j = 0; j < pts.size(); ++j) {
          const bool one = scene.escapes(pts[j], d, int(h.prim), up);
          ASSERT_EQ(many[j], uint8_t(one)) << name << " ray " << k << " point " << j << (up ? " up" : " down");
          ++asked;
          seen += one;
        }
      }
    }
    EXPECT_GT(asked, 5000u) << name;
    EXPECT_GT(seen, asked / 10) << name;
    EXPECT_LT(seen, asked * 9 / 10) << name;
  }
}

}  // namespace
}  // namespace mbsdf
