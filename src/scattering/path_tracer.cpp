#include "scattering/path_tracer.h"

#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>

#include "core/rng.h"

namespace mbsdf {

// One tally: a path's weights (one per wavelength of its group) into (component, bin).
struct PathTracer::Event {
  int32_t bin;
  int32_t component;
  int32_t group;
  int32_t weightOffset;
};
struct PathTracer::Chunk {
  std::vector<Event> events;
  std::vector<double> weights;
  std::vector<double> truncated, leaked, missed;  // per wavelength
  uint64_t rays = 0;
};

PathTracer::PathTracer(const PeriodicScene& scene, const Material& material, std::vector<double> lambda_um,
                       const DirectionGrid& grid, PathTracerSettings settings)
    : scene_(scene), material_(material), lambda_um_(std::move(lambda_um)), grid_(grid), settings_(settings) {
  for (double l : lambda_um_) ior_.push_back(material_.isPerfectConductor() ? Complex(0, 0) : material_.ior(l));
  if (material_.directionsIndependentOfLambda()) {
    std::vector<int> all;
    for (int i = 0; i < int(lambda_um_.size()); ++i) all.push_back(i);
    groups_.push_back(all);
  } else {
    for (int i = 0; i < int(lambda_um_.size()); ++i) groups_.push_back({i});
  }
}

void PathTracer::tracePath(int tile, int incidenceBin, const std::optional<Vec3>& exact, uint64_t path, int group,
                           Chunk& out, PathRecord* rec) const {
  const std::vector<int>& lambdas = groups_[group];
  const size_t nl = lambdas.size();
  Sampler s(settings_.seed, uint32_t(tile), path, uint32_t(group));
  DirectionSample wi = grid_.sampleCosine(incidenceBin, s.get1D(), s.get1D());
  if (exact) wi = DirectionSample{*exact, 1.0};
  double px = (s.get1D() - 0.5) * scene_.sizeX(), py = (s.get1D() - 0.5) * scene_.sizeY();
  bool fromAbove = wi.w.z >= 0;
  // Periodic patch: enter through the top (bottom) of the slab at a uniform footprint point; the
  // wrapping makes this uniform over the illuminated projected area. Finite patch: aim at a uniform
  // point of the footprint on the mean surface plane, starting outside the geometry.
  Vec3 o{px, py, fromAbove ? scene_.zTop() : scene_.zBottom()};
  if (!scene_.periodic()) {
    double zStart = fromAbove ? scene_.zTop() : scene_.zBottom();
    Vec3 base{px, py, scene_.zMean()};
    o = base + wi.w * ((zStart - scene_.zMean()) / wi.w.z);
  }
  Vec3 d = -wi.w;
  bool inUpper = fromAbove;
  double w[64];
  double* wp = w;
  std::vector<double> wbig;
  if (nl > 64) { wbig.resize(nl); wp = wbig.data(); }
  for (size_t k = 0; k < nl; ++k) wp[k] = wi.weight;
  const double n1 = material_.outsideIor;
  const bool conductor = material_.isConductor(), perfect = material_.isPerfectConductor();
  const double eps = scene_.rayEpsilon();
  int depth = 0;
  int lastPrim = -1;

  auto tally = [&](int bin, Component c) {
    out.events.push_back({bin, int(c), group, int(out.weights.size())});
    out.weights.insert(out.weights.end(), wp, wp + nl);
  };
  auto addTo = [&](std::vector<double>& v) {
    for (size_t k = 0; k < nl; ++k) v[lambdas[k]] += wp[k];
  };
  if (rec) {
    rec->vertices.push_back(o);
    rec->wi = wi.w;
  }

  while (true) {
    TraceResult tr = scene_.trace(o, d, lastPrim);
    ++out.rays;
    if (tr.kind == TraceResult::Kind::Hit) {
      if (rec) rec->vertices.push_back(tr.p);
      ++depth;
      // PHYSICS.md §4 step 6: the specular direction leaving the first hit is blocked.
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
          for (size_t k = 0; k < nl; ++k) wp[k] *= fresnelReflectance(absCos, n1, ior_[lambdas[k]]);
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

TileResult PathTracer::run(int tile, int incidenceIndex, int incidenceBin, std::optional<Vec3> exactDirection,
                           const std::function<void(uint64_t)>& progress) const {
  if (exactDirection) exactDirection = normalize(*exactDirection);
  auto t0 = std::chrono::steady_clock::now();
  const int nL = int(lambda_um_.size()), nB = grid_.binCount();
  const uint64_t N = settings_.paths;
  TileResult r;
  r.tile = tile;
  r.incidenceIndex = incidenceIndex;
  r.incidenceBin = incidenceBin;
  r.nLambda = nL;
  r.nBins = nB;
  r.samples = N;
  std::vector<Component> comps = {Component::Coherent, Component::Multiple};
  if (settings_.tallyGeoMasked) comps.push_back(Component::GeoMasked);
  std::array<std::vector<double>, kComponentCount> sum, sum2;
  for (Component c : comps) {
    sum[int(c)].assign(size_t(nL) * nB, 0.0);
    sum2[int(c)].assign(size_t(nL) * nB, 0.0);
  }
  r.truncated.assign(nL, 0.0);
  r.leaked.assign(nL, 0.0);
  r.missed.assign(nL, 0.0);

  constexpr uint64_t kChunk = 1024;  // paths per chunk: the unit of deterministic merging
  constexpr uint64_t kChunksPerBatch = 256;
  for (int g = 0; g < int(groups_.size()); ++g) {
    uint64_t nChunks = (N + kChunk - 1) / kChunk;
    for (uint64_t b0 = 0; b0 < nChunks; b0 += kChunksPerBatch) {
      uint64_t b1 = std::min(nChunks, b0 + kChunksPerBatch);
      std::vector<Chunk> chunks(b1 - b0);
      tbb::parallel_for(uint64_t(0), b1 - b0, [&](uint64_t ci) {
        Chunk& c = chunks[ci];
        c.truncated.assign(nL, 0.0);
        c.leaked.assign(nL, 0.0);
        c.missed.assign(nL, 0.0);
        uint64_t p0 = (b0 + ci) * kChunk, p1 = std::min(N, p0 + kChunk);
        c.events.reserve(p1 - p0);
        for (uint64_t p = p0; p < p1; ++p) tracePath(tile, incidenceBin, exactDirection, p, g, c, nullptr);
      });
      // Merge in chunk order: identical sums for any number of threads.
      for (const Chunk& c : chunks) {
        for (const Event& e : c.events) {
          const auto& lambdas = groups_[e.group];
          for (size_t k = 0; k < lambdas.size(); ++k) {
            double w = c.weights[e.weightOffset + k];
            size_t idx = size_t(lambdas[k]) * nB + e.bin;
            sum[e.component][idx] += w;
            sum2[e.component][idx] += w * w;
          }
        }
        r.rays += c.rays;
        for (int l = 0; l < nL; ++l) {
          r.truncated[l] += c.truncated[l];
          r.leaked[l] += c.leaked[l];
          r.missed[l] += c.missed[l];
        }
      }
      if (progress) progress(uint64_t(g) * N + std::min(N, b1 * kChunk));
    }
  }
  const double dN = double(N);
  for (Component c : comps) {
    auto& v = r.value[int(c)];
    auto& e = r.stdError[int(c)];
    v.assign(size_t(nL) * nB, 0.0);
    e.assign(size_t(nL) * nB, 0.0);
    for (int l = 0; l < nL; ++l)
      for (int bIdx = 0; bIdx < nB; ++bIdx) {
        size_t i = size_t(l) * nB + bIdx;
        double op = grid_.projectedSolidAngle(bIdx);
        if (op <= 0) continue;
        double s1 = sum[int(c)][i], s2 = sum2[int(c)][i];
        v[i] = s1 / (dN * op);
        // Standard error of the mean of N i.i.d. per-path contributions (zero for most paths).
        double var = N > 1 ? std::max(0.0, (s2 - s1 * s1 / dN) / (dN - 1)) : 0.0;
        e[i] = std::sqrt(var / dN) / op;
      }
  }
  for (int l = 0; l < nL; ++l) {
    r.truncated[l] /= dN;
    r.leaked[l] /= dN;
    r.missed[l] /= dN;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

PathTracer::PathRecord PathTracer::replay(int tile, int incidenceBin, uint64_t path, int group,
                                          std::optional<Vec3> exactDirection) const {
  Chunk c;
  int nL = int(lambda_um_.size());
  c.truncated.assign(nL, 0.0);
  c.leaked.assign(nL, 0.0);
  c.missed.assign(nL, 0.0);
  PathRecord rec;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  tracePath(tile, incidenceBin, exactDirection, path, group, c, &rec);
  return rec;
}

}  // namespace mbsdf
