#include "scattering/path_tracer.h"

#include <cmath>

#include "core/rng.h"

namespace mbsdf {

PathTracer::PathTracer(const PeriodicScene& scene, const Material& material, std::vector<double> lambda_um,
                       const DirectionGrid& grid, PathTracerSettings settings)
    : scene_(scene), material_(material), lambda_um_(std::move(lambda_um)), grid_(grid), settings_(settings) {
  ior_ = material_.iorAt(lambda_um_);
  fresnel_ = conductorFresnelTables(material_, ior_);  // optics/fresnel_table.h
  groups_ = wavelengthGroups(int(lambda_um_.size()), material_.directionsIndependentOfLambda());
}

// Where a path lit from wi starts, at footprint point (px, py). Periodic patch: it enters through
// the top (bottom) of the slab there; the wrapping makes this uniform over the illuminated
// projected area. Finite patch: it aims at that point of the mean surface plane, starting outside
// the geometry.
static Vec3 pathOrigin(const PeriodicScene& scene, const Vec3& wi, double px, double py) {
  const bool fromAbove = wi.z >= 0;
  const double zStart = fromAbove ? scene.zTop() : scene.zBottom();
  if (scene.periodic()) return {px, py, zStart};
  const Vec3 base{px, py, scene.zMean()};
  return base + wi * ((zStart - scene.zMean()) / wi.z);
}

void PathTracer::tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group,
                           PathChunk& out, PathRecord* rec) const {
  const std::vector<int>& lambdas = groups_[group];
  const size_t nl = lambdas.size();
  Sampler s(settings_.seed, uint32_t(tile), path, uint32_t(group));
  const DirectionSample wi = pathIncidence(grid_, incidenceBin, exact, s);
  double px = (s.get1D() - 0.5) * scene_.sizeX(), py = (s.get1D() - 0.5) * scene_.sizeY();
  bool fromAbove = wi.w.z >= 0;
  Vec3 o = pathOrigin(scene_, wi.w, px, py);
  Vec3 d = -wi.w;
  bool inUpper = fromAbove;
  double w[64];
  double* wp = w;
  std::vector<double> wbig;
  if (nl > 64) {
    wbig.resize(nl);
    wp = wbig.data();
  }
  for (size_t k = 0; k < nl; ++k) wp[k] = wi.weight;
  const double n1 = material_.outsideIor;
  const bool conductor = material_.isConductor(), perfect = material_.isPerfectConductor();
  const double eps = scene_.rayEpsilon();
  int depth = 0;
  int lastPrim = -1;

  auto tally = [&](int bin, Component c) { out.tally(bin, c, group, wp, nl); };
  auto addTo = [&](std::vector<double>& v) {
    for (size_t k = 0; k < nl; ++k) v[lambdas[k]] += wp[k];
  };
  if (rec) {
    rec->vertices.push_back(o);
    rec->wi = wi.w;
  }

  while (true) {
    if (rec) rec->rays.push_back({o, d, lastPrim});
    TraceResult tr = scene_.trace(o, d, lastPrim);
    ++out.rays;
    if (tr.kind == TraceResult::Kind::Hit) {
      if (rec) rec->vertices.push_back(tr.p);
      ++depth;
      // docs/physics.md §4 step 6: the specular direction leaving the first hit is blocked.
      if (depth == 2 && settings_.tallyGeoMasked) tally(grid_.binOf(d), Component::GeoMasked);
      if (depth > settings_.maxDepth) {
        addTo(out.truncated);
        break;
      }
      double cosi = -dot(d, tr.n);
      bool hitFromOutside = cosi > 0;
      if (hitFromOutside != inUpper) {
        // The ray met the back of a surface: holes or inconsistent winding. Follow the geometry.
        if (conductor) {
          addTo(out.leaked);
          break;
        }
        inUpper = hitFromOutside;
      }
      Vec3 nl_ = hitFromOutside ? tr.n : -tr.n;
      Vec3 wo = -d;
      double absCos = std::min(1.0, std::abs(cosi));
      if (conductor) {
        if (!perfect)
          for (size_t k = 0; k < nl; ++k) wp[k] *= fresnel_[size_t(lambdas[k])](absCos);
        d = reflect(wo, nl_);
      } else {
        // Real dielectric (the imaginary part, if any, is ignored by the geometric tracer).
        double n2 = ior_[lambdas[0]].real();
        double etaI = hitFromOutside ? n1 : n2, etaT = hitFromOutside ? n2 : n1;
        double F = fresnelReflectance(absCos, etaI, Complex(etaT, 0));
        Vec3 wt;
        double u = s.get1D();
        if (u < F || !refract(wo, nl_, etaI / etaT, &wt)) {
          d = reflect(wo, nl_);
        } else {
          d = wt;
          inUpper = !inUpper;
        }
      }
      d = normalize(d);
      o = tr.p + (dot(d, tr.n) > 0 ? tr.n : -tr.n) * eps;
      lastPrim = int(tr.prim);
      continue;
    }
    if (tr.kind == TraceResult::Kind::TooManyWraps) {
      addTo(out.truncated);
      break;
    }
    if (depth == 0) {
      // Primary ray met nothing: finite patch or a hole.
      addTo(out.missed);
      break;
    }
    bool down = tr.kind == TraceResult::Kind::EscapedDown, up = tr.kind == TraceResult::Kind::EscapedUp;
    // On a periodic (infinite) surface a ray can only leave upward in the upper medium or downward
    // in the lower one; anything else crossed the surface through a hole. A finite patch can be
    // left in any direction from either side.
    if (scene_.periodic() && ((up && !inUpper) || (down && inUpper))) {
      addTo(out.leaked);
      break;
    }
    int bin = grid_.binOf(d);
    tally(bin, depth == 1 ? Component::Coherent : Component::Multiple);
    if (rec) {
      rec->exitBin = bin;
      rec->wo = d;
    }
    break;
  }
  if (rec) {
    rec->depth = depth;
    rec->weight.assign(wp, wp + nl);
  }
}

TileResult PathTracer::run(const TileRequest& q, const std::function<void(uint64_t)>& progress) const {
  const int tile = q.tile, incidenceBin = q.incidenceBin;
  std::optional<Vec3> exactDirection = q.exactDirection;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  PathTallyPlan plan{tile,
                     q.incidenceIndex,
                     incidenceBin,
                     &grid_,
                     int(lambda_um_.size()),
                     groups_,
                     q.paths > 0 ? q.paths : settings_.paths,
                     q.firstPath,
                     {Component::Coherent, Component::Multiple}};
  if (settings_.tallyGeoMasked) plan.components.push_back(Component::GeoMasked);
  return runPaths(
      plan, [&](uint64_t p, int g, PathChunk& c) { tracePath(tile, incidenceBin, exactDirection, p, g, c, nullptr); },
      progress);
}

PathTracer::PathRecord PathTracer::replay(int tile, int incidenceBin, uint64_t path, int group,
                                          std::optional<Vec3> exactDirection) const {
  PathChunk c(int(lambda_um_.size()));
  PathRecord rec;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  tracePath(tile, incidenceBin, exactDirection, path, group, c, &rec);
  return rec;
}

}  // namespace mbsdf
