#include "scattering/path_tracer.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/huge_page_allocator.h"
#include "core/rng.h"
#include "geometry/ray_order.h"

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
  // Ordering rays by origin pays when the scene's tree and hit records outgrow a core's cache
  // (about 200 bytes a triangle): on a 128-triangle grating it only costs.
  orderByOrigin_ = scene_.triangleCount() >= kOrderByOriginMinTriangles;
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
                                            int group, double* w, Vec3* wi) const {
  Sampler s = pathSampler(tile, path, group);
  const DirectionSample incidence = pathIncidence(grid_, incidenceBin, exact, s);
  const double px = (s.get1D() - 0.5) * scene_.sizeX(), py = (s.get1D() - 0.5) * scene_.sizeY();
  PathState st;
  st.o = pathOrigin(scene_, incidence.w, px, py);
  st.d = -incidence.w;
  st.inUpper = incidence.w.z >= 0;
  st.nextBlock = s.nextBlock();
  st.secondLeft = s.secondLeft();
  for (size_t k = 0; k < groups_[size_t(group)].size(); ++k) w[k] = incidence.weight;
  if (wi) *wi = incidence.w;
  return st;
}

bool PathTracer::step(PathState& st, const TraceResult& tr, const PathContext& ctx, PathEnd& ended,
                      PathRecord* rec) const {
  const std::vector<int>& lambdas = groups_[size_t(ctx.group)];
  const size_t nl = lambdas.size();
  double* wp = ctx.weightsOf(st.path);
  // Every ray before this one met a surface (a ray that meets none ends its path): this is ray
  // depth + 1, and a path that ends on a surface has traced as many rays as it met surfaces.
  const bool hit = tr.kind == TraceResult::Kind::Hit;
  auto end = [&](PathEnd::Kind kind) {
    ended = {int32_t(st.depth) + (hit ? 0 : 1), -1, kind, st.depth == 1};
    return false;
  };
  if (hit) {
    if (rec) rec->vertices.push_back(tr.p);
    ++st.depth;
    // docs/physics.md §4 step 6: the specular direction leaving the first hit is blocked.
    if (st.depth == 2 && settings_.tallyGeoMasked) {
      ctx.geoMaskedBins[st.path] = grid_.binOf(st.d);
      std::copy(wp, wp + nl, wp + nl);
    }
    if (st.depth > uint32_t(settings_.maxDepth)) return end(PathEnd::Kind::Truncated);
    const double cosi = -dot(st.d, tr.n);
    const bool hitFromOutside = cosi > 0;
    if (hitFromOutside != bool(st.inUpper)) {
      // The ray met the back of a surface: holes or inconsistent winding. Follow the geometry.
      if (conductor_) return end(PathEnd::Kind::Leaked);
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
      Sampler s = pathSampler(ctx.tile, ctx.firstPath + st.path, ctx.group);
      s.resume(st.nextBlock, st.secondLeft);
      const double u = s.get1D();
      st.nextBlock = s.nextBlock();
      st.secondLeft = s.secondLeft();
      if (u < F || !refract(wo, nl_, etaI / etaT, &wt)) {
        d = reflect(wo, nl_);
      } else {
        d = wt;
        st.inUpper = !st.inUpper;
      }
    }
    st.d = normalize(d);
    st.o = tr.p + (dot(st.d, tr.n) > 0 ? tr.n : -tr.n) * scene_.rayEpsilon();
    st.lastPrim = int32_t(tr.prim);
    if (rec) rec->rays.push_back({st.o, st.d, st.lastPrim});
    return true;
  }
  if (tr.kind == TraceResult::Kind::TooManyWraps) return end(PathEnd::Kind::Truncated);
  // Primary ray met nothing: finite patch or a hole.
  if (st.depth == 0) return end(PathEnd::Kind::Missed);
  const bool down = tr.kind == TraceResult::Kind::EscapedDown, up = tr.kind == TraceResult::Kind::EscapedUp;
  // On a periodic (infinite) surface a ray can only leave upward in the upper medium or downward
  // in the lower one; anything else crossed the surface through a hole. A finite patch can be
  // left in any direction from either side.
  if (scene_.periodic() && ((up && !st.inUpper) || (down && st.inUpper))) return end(PathEnd::Kind::Leaked);
  end(PathEnd::Kind::Exited);
  ended.exitBin = grid_.binOf(st.d);
  if (rec) {
    rec->exitBin = ended.exitBin;
    rec->wo = st.d;
  }
  return false;
}

void PathTracer::commit(const PathEnd& e, const double* w, int geoMaskedBin, int group, PathChunk& out) const {
  const std::vector<int>& lambdas = groups_[size_t(group)];
  const size_t nl = lambdas.size();
  out.rays += uint64_t(e.rays);
  if (geoMaskedBin >= 0) out.tally(geoMaskedBin, Component::GeoMasked, group, w + nl, nl);
  auto addTo = [&](std::vector<double>& v) {
    for (size_t k = 0; k < nl; ++k) v[size_t(lambdas[k])] += w[k];
  };
  switch (e.kind) {
    case PathEnd::Kind::Exited:
      out.tally(e.exitBin, e.coherent ? Component::Coherent : Component::Multiple, group, w, nl);
      break;
    case PathEnd::Kind::Truncated:
      addTo(out.truncated);
      break;
    case PathEnd::Kind::Leaked:
      addTo(out.leaked);
      break;
    case PathEnd::Kind::Missed:
      addTo(out.missed);
      break;
  }
}

void PathTracer::tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group,
                           PathChunk& out, PathRecord* rec) const {
  const size_t nl = groups_[size_t(group)].size();
  std::vector<double> w(weightsPerPath(group));
  int32_t geoMaskedBin = -1;
  const PathContext ctx{tile, group, path, w.data(), w.size(), &geoMaskedBin};
  Vec3 wi;
  PathState st = startPath(tile, incidenceBin, exact, path, group, w.data(), &wi);
  if (rec) {
    rec->vertices.push_back(st.o);
    rec->wi = wi;
    rec->rays.push_back({st.o, st.d, -1});
  }
  PathEnd ended;
  TraceResult tr = scene_.trace(st.o, st.d);
  while (step(st, tr, ctx, ended, rec)) tr = scene_.trace(st.o, st.d, st.lastPrim);
  commit(ended, w.data(), geoMaskedBin, group, out);
  if (rec) {
    rec->depth = int(st.depth);
    rec->weight.assign(w.begin(), w.begin() + std::ptrdiff_t(nl));
  }
}

struct PathTracer::Wavefront {
  // The buffers only grow: a batch reuses them without clearing or faulting in their pages. Huge
  // pages make their first touch cheap (tens of MB: thousands of faults of small pages, a fifth of
  // a second on a small job's first tile) and their out-of-order reads light on the TLB.
  template <typename T>
  using Buffer = std::vector<T, HugePageAllocator<T>>;
  // The states of the paths that go on, one per ray of the round, in the order their rays are
  // traced (by origin when the tracer orders them): a block reads and steps its states in
  // sequence instead of fetching each from a place of its path.
  Buffer<PathState> live, next;
  // What the ended paths leave for their tallies, in the order they ended: endedAt[i] is path i's
  // place.
  Buffer<PathEnd> ended;
  Buffer<uint32_t> endedAt;
  std::atomic<uint32_t> nEnded{0};
  Buffer<double> weights;         // per path: its weights (PathContext)
  Buffer<int32_t> geoMaskedBins;  // per path, when geo_masked is tallied (PathContext)
  size_t nRays = 0;
  // A round's states that go on stay in their block, the first goOnCount[b] of block b, with
  // their origins' cells; from[j] is the live state that becomes the next round's j-th.
  Buffer<uint32_t> goOnCells, cells, from;
  std::vector<size_t> goOnCount;
  OriginOrder order;
};

PathTracer::~PathTracer() = default;

template <typename T, typename A>
static void growTo(std::vector<T, A>& v, size_t n) {
  if (v.size() < n) v.resize(n);
}

// Copies states into their places in sequence: next[j] = live[from[j]]. Reading scattered and
// writing in order lets the reads overlap (each is fetched a few states ahead) where scattered
// writes would each wait for their line.
template <typename Buf>
static void gatherStates(const Buf& live, std::span<const uint32_t> from, Buf& next) {
  constexpr size_t kAhead = 16, kGrain = 4096;
  const size_t n = from.size();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kGrain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t j = r.begin(); j < r.end(); ++j) {
      if (j + kAhead < r.end()) __builtin_prefetch(&live[from[j + kAhead]]);
      next[j] = live[from[j]];
    }
  });
}

void PathTracer::traceRound(const PathContext& ctx, bool firstRays, Wavefront& wf) const {
  // Blocks of rays, each traced and stepped by one thread: in origin order, the paths whose rays
  // neighbour in the scene are advanced together. Each path draws its own random numbers, so the
  // order changes no number.
  constexpr size_t kBlock = 512;
  const size_t n = wf.nRays, nBlocks = (n + kBlock - 1) / kBlock;
  // Whether step() reads a path's weights (a real conductor's Fresnel factor, the geo_masked copy).
  const bool stepWeighs = (conductor_ && !perfectConductor_) || settings_.tallyGeoMasked;
  // The next round's rays are fewer: cells for n rays are as fine as they need, or finer.
  if (orderByOrigin_) wf.order.prepare(n, scene_.sizeX(), scene_.sizeY());
  growTo(wf.goOnCells, n);
  // Set here, not only by their blocks: when the run is abandoned (runPaths cancels its batch),
  // the blocks not run leave no rays and the rounds end.
  wf.goOnCount.assign(nBlocks, 0);
  tbb::parallel_for(size_t(0), nBlocks, [&](size_t b) {
    thread_local std::vector<Vec3> o, d;
    thread_local std::vector<int> leaving;
    thread_local std::vector<TraceResult> results;
    const size_t k0 = b * kBlock, m = std::min(n, k0 + kBlock) - k0;
    PathState* states = wf.live.data() + k0;
    o.resize(m);
    d.resize(m);
    leaving.resize(m);
    results.resize(m);
    for (size_t k = 0; k < m; ++k) {
      o[k] = states[k].o;
      d[k] = states[k].d;
      leaving[k] = states[k].lastPrim;
      // The weights, spread over the batch's, are read after the rays are traced: fetched now,
      // they arrive while Embree works.
      if (stepWeighs) __builtin_prefetch(ctx.weightsOf(states[k].path));
    }
    // Packets of 16 neighbours: the first rays are near-parallel, and in origin order many later
    // rays are too (those leaving one flat stretch of surface). Later rays in their paths' order
    // (a small scene) are not.
    const bool packets = settings_.packets && (firstRays || orderByOrigin_);
    scene_.traceMany(o, d, firstRays ? std::span<const int>{} : std::span<const int>(leaving),
                     packets ? TraceMode::Packets : TraceMode::Single, results);
    thread_local std::vector<uint8_t> goesOn;
    thread_local std::vector<PathEnd> ends;
    goesOn.resize(m);
    ends.resize(m);
    size_t ending = 0;
    for (size_t k = 0; k < m; ++k) {
      goesOn[k] = step(states[k], results[k], ctx, ends[k], nullptr);
      ending += !goesOn[k];
    }
    // The states that go on move to the front of the block (in order). What those that end leave
    // for the tallies is kept together, at places taken from a shared counter, with each path's
    // place noted: written to their paths' own places, scattered over the batch, each would wait
    // for its line. The places depend on the threads' timing; the tallies, read by path, do not.
    uint32_t endedAt = wf.nEnded.fetch_add(uint32_t(ending), std::memory_order_relaxed);
    size_t goingOn = 0;
    for (size_t k = 0; k < m; ++k) {
      const PathState& st = states[k];
      if (!goesOn[k]) {
        wf.endedAt[st.path] = endedAt;
        wf.ended[endedAt++] = ends[k];
        continue;
      }
      if (orderByOrigin_) wf.goOnCells[k0 + goingOn] = wf.order.cellOf(st.o);
      if (goingOn != k) states[goingOn] = st;
      ++goingOn;
    }
    wf.goOnCount[b] = goingOn;
  });
  // The next round's rays: the blocks' rays that go on, block after block, put in origin order.
  std::vector<size_t> start(nBlocks + 1, 0);
  for (size_t b = 0; b < nBlocks; ++b) start[b + 1] = start[b] + wf.goOnCount[b];
  wf.nRays = start[nBlocks];
  std::span<const uint32_t> places;
  if (orderByOrigin_) {
    tbb::parallel_for(size_t(0), nBlocks, [&](size_t b) {
      std::copy_n(wf.goOnCells.data() + b * kBlock, wf.goOnCount[b], wf.cells.data() + start[b]);
    });
    places = wf.order.places({wf.cells.data(), wf.nRays});
  }
  tbb::parallel_for(size_t(0), nBlocks, [&](size_t b) {
    for (size_t j = 0; j < wf.goOnCount[b]; ++j)
      wf.from[places.empty() ? start[b] + j : places[start[b] + j]] = uint32_t(b * kBlock + j);
  });
  gatherStates(wf.live, {wf.from.data(), wf.nRays}, wf.next);
  std::swap(wf.live, wf.next);
}

void PathTracer::fit(Wavefront& wf, uint64_t count, size_t weightsPerPath) const {
  if (count > kMaxBatchPaths) throw std::logic_error("PathTracer: a batch of more paths than a state can number");
  growTo(wf.ended, count);
  growTo(wf.weights, count * weightsPerPath);  // each path sets its weights before it reads them
  if (settings_.tallyGeoMasked) growTo(wf.geoMaskedBins, count);
  growTo(wf.live, count);
  growTo(wf.next, count);
  growTo(wf.cells, count);
  growTo(wf.from, count);
  growTo(wf.endedAt, count);
  growTo(wf.goOnCells, count);
  if (orderByOrigin_) wf.order.prepare(count, scene_.sizeX(), scene_.sizeY());
}

void PathTracer::traceBatch(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t firstPath,
                            uint64_t count, int group, std::span<PathChunk> chunks, Wavefront& wf) const {
  const size_t nw = weightsPerPath(group);
  fit(wf, count, nw);
  const PathContext ctx{tile, group, firstPath, wf.weights.data(), nw, wf.geoMaskedBins.data()};
  wf.nRays = count;
  wf.nEnded = 0;
  auto blocks = [&](auto&& body) {
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, count, 1024), [&](const tbb::blocked_range<uint64_t>& r) {
      for (uint64_t j = r.begin(); j < r.end(); ++j) body(j);
    });
  };
  // The first states by path, in `next` (free until the first round's end), then in origin order
  // in `live`; or straight in `live` when the rays stay in their paths' order.
  auto& first = orderByOrigin_ ? wf.next : wf.live;
  blocks([&](uint64_t j) {
    first[j] = startPath(tile, incidenceBin, exact, firstPath + j, group, &wf.weights[j * nw]);
    first[j].path = uint32_t(j);
    wf.endedAt[j] = std::numeric_limits<uint32_t>::max();
    if (settings_.tallyGeoMasked) wf.geoMaskedBins[j] = -1;
    if (orderByOrigin_) wf.cells[j] = wf.order.cellOf(first[j].o);
  });
  if (orderByOrigin_) {
    const std::span<const uint32_t> places = wf.order.places({wf.cells.data(), count});
    blocks([&](uint64_t j) { wf.from[places[j]] = uint32_t(j); });
    gatherStates(wf.next, {wf.from.data(), count}, wf.live);
  }
  for (bool first = true; wf.nRays > 0; first = false) traceRound(ctx, first, wf);
  // The tallies in path order within each chunk: the same sums as path by path. A path that did
  // not end (its batch abandoned) has left nothing and is not tallied.
  const uint32_t nEnded = wf.nEnded.load();
  tbb::parallel_for(size_t(0), chunks.size(), [&](size_t c) {
    constexpr uint64_t kAhead = 16;
    const uint64_t j1 = std::min(count, (c + 1) * kPathChunk);
    for (uint64_t j = c * kPathChunk; j < j1; ++j) {
      if (j + kAhead < j1 && wf.endedAt[j + kAhead] < nEnded) __builtin_prefetch(&wf.ended[wf.endedAt[j + kAhead]]);
      if (wf.endedAt[j] >= nEnded) continue;
      commit(wf.ended[wf.endedAt[j]], ctx.weightsOf(uint32_t(j)), settings_.tallyGeoMasked ? wf.geoMaskedBins[j] : -1,
             group, chunks[c]);
    }
  });
}

PathTallyPlan PathTracer::tallyPlan(const TileRequest& q) const {
  PathTallyPlan plan{q.tile,
                     q.incidenceIndex,
                     q.incidenceBin,
                     &grid_,
                     int(lambda_um_.size()),
                     groups_,
                     q.paths > 0 ? q.paths : settings_.paths,
                     q.firstPath,
                     {Component::Coherent, Component::Multiple}};
  if (settings_.tallyGeoMasked) plan.components.push_back(Component::GeoMasked);
  return plan;
}

void PathTracer::reserveBuffers() const {
  const PathTallyPlan plan = tallyPlan({});
  size_t nw = 0;
  for (int g = 0; g < int(groups_.size()); ++g) nw = std::max(nw, weightsPerPath(g));
  SparePool<std::unique_ptr<Wavefront>>::Lease wf(spareWavefronts_);
  if (!*wf) *wf = std::make_unique<Wavefront>();
  fit(**wf, std::min(plan.paths, kPathChunksPerBatch * kPathChunk), nw);
  reservePathChunks(plan);
}

TileResult PathTracer::run(const TileRequest& q, const std::function<void(uint64_t)>& progress) const {
  const int tile = q.tile, incidenceBin = q.incidenceBin;
  std::optional<Vec3> exactDirection = q.exactDirection;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  const PathTallyPlan plan = tallyPlan(q);
  // The wavefront's buffers (some 160 bytes per path of a batch) are leased from the tracer's
  // spares, so that a run of many tiles does not fault their pages in again.
  SparePool<std::unique_ptr<Wavefront>>::Lease wf(spareWavefronts_);
  if (!*wf) *wf = std::make_unique<Wavefront>();
  return runPaths(
      plan,
      [&](uint64_t p0, uint64_t n, int g, std::span<PathChunk> chunks) {
        traceBatch(tile, incidenceBin, exactDirection, p0, n, g, chunks, **wf);
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
