#include "scattering/path_tracer.h"

#include <algorithm>
#include <cmath>

#include "core/rng.h"

namespace mbsdf {

PathTracer::PathTracer(const PeriodicScene& scene, const Material& material, std::vector<double> lambda_um,
                       const DirectionGrid& grid, PathTracerSettings settings)
    : scene_(scene),
      material_(material),
      conductor_(material.isConductor()),
      perfectConductor_(material.isPerfectConductor()),
      lambda_um_(std::move(lambda_um)),
      grid_(grid),
      settings_(settings) {
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

PathTracer::PathState PathTracer::startPath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path,
                                            int group, double* w, double* wGeoMasked) const {
  PathState st(Sampler(settings_.seed, uint32_t(tile), path, uint32_t(group)));
  st.wi = pathIncidence(grid_, incidenceBin, exact, st.s);
  const double px = (st.s.get1D() - 0.5) * scene_.sizeX(), py = (st.s.get1D() - 0.5) * scene_.sizeY();
  st.o = pathOrigin(scene_, st.wi.w, px, py);
  st.d = -st.wi.w;
  st.inUpper = st.wi.w.z >= 0;
  st.w = w;
  st.wGeoMasked = wGeoMasked;
  for (size_t k = 0; k < groups_[size_t(group)].size(); ++k) w[k] = st.wi.weight;
  return st;
}

bool PathTracer::step(PathState& st, const TraceResult& tr, int group, PathRecord* rec) const {
  const std::vector<int>& lambdas = groups_[size_t(group)];
  const size_t nl = lambdas.size();
  double* wp = st.w;
  if (tr.kind == TraceResult::Kind::Hit) {
    if (rec) rec->vertices.push_back(tr.p);
    ++st.depth;
    // docs/physics.md §4 step 6: the specular direction leaving the first hit is blocked.
    if (st.depth == 2 && settings_.tallyGeoMasked) {
      st.geoMaskedBin = grid_.binOf(st.d);
      std::copy(wp, wp + nl, st.wGeoMasked);
    }
    if (st.depth > settings_.maxDepth) {
      st.end = PathState::End::Truncated;
      return false;
    }
    const double cosi = -dot(st.d, tr.n);
    const bool hitFromOutside = cosi > 0;
    if (hitFromOutside != st.inUpper) {
      // The ray met the back of a surface: holes or inconsistent winding. Follow the geometry.
      if (conductor_) {
        st.end = PathState::End::Leaked;
        return false;
      }
      st.inUpper = hitFromOutside;
    }
    const Vec3 nl_ = hitFromOutside ? tr.n : -tr.n;
    const Vec3 wo = -st.d;
    const double absCos = std::min(1.0, std::abs(cosi));
    Vec3 d;
    if (conductor_) {
      if (!perfectConductor_)
        for (size_t k = 0; k < nl; ++k) wp[k] *= fresnel_[size_t(lambdas[k])](absCos);
      d = reflect(wo, nl_);
    } else {
      // Real dielectric (the imaginary part, if any, is ignored by the geometric tracer).
      const double n1 = material_.outsideIor, n2 = ior_[size_t(lambdas[0])].real();
      const double etaI = hitFromOutside ? n1 : n2, etaT = hitFromOutside ? n2 : n1;
      const double F = fresnelReflectance(absCos, etaI, Complex(etaT, 0));
      Vec3 wt;
      const double u = st.s.get1D();
      if (u < F || !refract(wo, nl_, etaI / etaT, &wt)) {
        d = reflect(wo, nl_);
      } else {
        d = wt;
        st.inUpper = !st.inUpper;
      }
    }
    st.d = normalize(d);
    st.o = tr.p + (dot(st.d, tr.n) > 0 ? tr.n : -tr.n) * scene_.rayEpsilon();
    st.lastPrim = int(tr.prim);
    if (rec) rec->rays.push_back({st.o, st.d, st.lastPrim});
    return true;
  }
  if (tr.kind == TraceResult::Kind::TooManyWraps) {
    st.end = PathState::End::Truncated;
    return false;
  }
  if (st.depth == 0) {
    // Primary ray met nothing: finite patch or a hole.
    st.end = PathState::End::Missed;
    return false;
  }
  const bool down = tr.kind == TraceResult::Kind::EscapedDown, up = tr.kind == TraceResult::Kind::EscapedUp;
  // On a periodic (infinite) surface a ray can only leave upward in the upper medium or downward
  // in the lower one; anything else crossed the surface through a hole. A finite patch can be
  // left in any direction from either side.
  if (scene_.periodic() && ((up && !st.inUpper) || (down && st.inUpper))) {
    st.end = PathState::End::Leaked;
    return false;
  }
  st.exitBin = grid_.binOf(st.d);
  st.end = PathState::End::Exited;
  if (rec) {
    rec->exitBin = st.exitBin;
    rec->wo = st.d;
  }
  return false;
}

void PathTracer::commit(const PathState& st, int group, PathChunk& out) const {
  const std::vector<int>& lambdas = groups_[size_t(group)];
  const size_t nl = lambdas.size();
  if (st.geoMaskedBin >= 0) out.tally(st.geoMaskedBin, Component::GeoMasked, group, st.wGeoMasked, nl);
  auto addTo = [&](std::vector<double>& v) {
    for (size_t k = 0; k < nl; ++k) v[size_t(lambdas[k])] += st.w[k];
  };
  switch (st.end) {
    case PathState::End::Exited:
      out.tally(st.exitBin, st.depth == 1 ? Component::Coherent : Component::Multiple, group, st.w, nl);
      break;
    case PathState::End::Truncated:
      addTo(out.truncated);
      break;
    case PathState::End::Leaked:
      addTo(out.leaked);
      break;
    case PathState::End::Missed:
      addTo(out.missed);
      break;
  }
}

void PathTracer::tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group,
                           PathChunk& out, PathRecord* rec) const {
  const size_t nl = groups_[size_t(group)].size();
  std::vector<double> w(nl), wGeoMasked(nl);
  PathState st = startPath(tile, incidenceBin, exact, path, group, w.data(), wGeoMasked.data());
  if (rec) {
    rec->vertices.push_back(st.o);
    rec->wi = st.wi.w;
    rec->rays.push_back({st.o, st.d, -1});
  }
  TraceResult tr = scene_.trace(st.o, st.d);
  while (true) {
    ++out.rays;
    if (!step(st, tr, group, rec)) break;
    tr = scene_.trace(st.o, st.d, st.lastPrim);
  }
  commit(st, group, out);
  if (rec) {
    rec->depth = st.depth;
    rec->weight = w;
  }
}

void PathTracer::traceRange(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t firstPath,
                            uint64_t count, int group, PathChunk& out) const {
  // The paths advance together, one ray each per round (a wavefront): the first rays go to Embree
  // as packets, later rounds as many single rays whose hit records are fetched together
  // (PeriodicScene::traceMany). Each path draws its own random numbers, so the rounds change no
  // number, and the tallies are made in path order at the end: the same sums as path by path.
  const size_t nl = groups_[size_t(group)].size();
  thread_local std::vector<PathState> paths;
  thread_local std::vector<double> weights;
  thread_local std::vector<uint32_t> active, next;
  thread_local std::vector<Vec3> origins, directions;
  thread_local std::vector<int> leaving;
  thread_local std::vector<TraceResult> results;
  weights.assign(2 * count * nl, 0.0);
  paths.clear();
  origins.clear();
  directions.clear();
  active.clear();
  for (uint64_t j = 0; j < count; ++j) {
    paths.push_back(
        startPath(tile, incidenceBin, exact, firstPath + j, group, &weights[2 * j * nl], &weights[(2 * j + 1) * nl]));
    origins.push_back(paths.back().o);
    directions.push_back(paths.back().d);
    active.push_back(uint32_t(j));
  }
  results.resize(count);
  scene_.traceMany(origins, directions, {}, TraceMode::Packets, results);
  while (!active.empty()) {
    next.clear();
    origins.clear();
    directions.clear();
    leaving.clear();
    for (size_t a = 0; a < active.size(); ++a) {
      PathState& st = paths[active[a]];
      ++out.rays;
      if (!step(st, results[a], group, nullptr)) continue;
      next.push_back(active[a]);
      origins.push_back(st.o);
      directions.push_back(st.d);
      leaving.push_back(st.lastPrim);
    }
    active.swap(next);
    results.resize(active.size());
    if (!active.empty()) scene_.traceMany(origins, directions, leaving, TraceMode::Single, results);
  }
  for (const PathState& st : paths) commit(st, group, out);
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
      plan,
      [&](uint64_t p0, uint64_t n, int g, PathChunk& c) {
        traceRange(tile, incidenceBin, exactDirection, p0, n, g, c);
      },
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
