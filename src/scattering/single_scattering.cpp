#include "scattering/single_scattering.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <tuple>

#include "core/stop.h"
#include "optics/fresnel.h"
#include "scattering/visibility_table.h"
#include "scattering/wave_common.h"

namespace mbsdf {

namespace {

// Fraction of triangle (a, b, c) whose points pass `test`, by splitting it into four (at the edge
// midpoints) where its four first-level points — the centroid and three points inset towards the
// vertices, as `exact` tests them — disagree, down to `depth` levels. A leaf whose points still
// disagree counts the fraction of its points and adds to *uncertain its area share times the
// largest possible deviation, max(f, 1 − f): the error bound of a partly lit or masked facet.
template <class Test>
double visibleFraction(const Vec3& a, const Vec3& b, const Vec3& c, const Test& test, int depth, double* uncertain) {
  int n = 0;
  for (const Vec3& x : firstLevelPoints(a, b, c)) n += test(x) ? 1 : 0;
  if (n == 0 || n == 4) return n / 4.0;
  if (depth == 0) {
    const double f = n / 4.0;
    *uncertain += std::max(f, 1 - f);
    return f;
  }
  const Vec3 ab = (a + b) * 0.5, bc = (b + c) * 0.5, ca = (c + a) * 0.5;
  double u = 0;
  const double f =
      (visibleFraction(a, ab, ca, test, depth - 1, &u) + visibleFraction(ab, b, bc, test, depth - 1, &u) +
       visibleFraction(ca, bc, c, test, depth - 1, &u) + visibleFraction(ab, bc, ca, test, depth - 1, &u)) /
      4;
  *uncertain += u / 4;
  return f;
}

// Fixed blocks of sub-direction rows summed on their own and reduced in order: the result does not
// depend on the thread count.
constexpr int kBlocks = 8;

}  // namespace

FacetSingleScattering::FacetSingleScattering(const Microgeometry& g, const PeriodicScene& scene,
                                             const Material& material, std::vector<double> lambda_um,
                                             const DirectionGrid& grid)
    : g_(g), scene_(scene), material_(material), lambda_um_(std::move(lambda_um)), grid_(grid) {
  ior_ = material_.iorAt(lambda_um_);
  // Facets in one plane orientation reflect (and refract) into the same direction: where no ray is
  // needed they are one term (a grating's texels, a flat patch's two triangles, a V-groove's faces).
  // Normals equal to 1e-12 are one orientation (a direction error of 1e-12 rad).
  // Grouped by sorting, not by a map: a random heightfield's 10^5–10^6 facets are as many
  // orientations, and a tree or node-based hash map allocated one node each (0.5 s for 524 k).
  // The planes keep the order of their first facet and list their facets in mesh order, so the
  // sums run in the order the facets come.
  struct Keyed {
    std::array<long long, 3> key;
    uint32_t t;
  };
  // The keys in parallel (a degenerate facet, with no area and no light, keeps t = kNone and is
  // dropped), then a parallel sort: (key, t) is a total order, so any sort gives the same list.
  constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
  std::vector<Keyed> keyed(g.triangles.size());
  std::vector<double> halfArea(g.triangles.size(), 0.0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, g.triangles.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t < r.end(); ++t) {
      const Vec3 N = g.triangleNormal(t);
      const double len = length(N);
      if (!(len > 0)) {
        keyed[t].t = kNone;
        continue;
      }
      const Vec3 n = N * (1.0 / len);
      keyed[t] = {{std::llround(n.x * 1e12), std::llround(n.y * 1e12), std::llround(n.z * 1e12)}, uint32_t(t)};
      halfArea[t] = 0.5 * len;
    }
  });
  keyed.erase(std::remove_if(keyed.begin(), keyed.end(), [&](const Keyed& k) { return k.t == kNone; }), keyed.end());
  // Compared element by element: std::array's == and != call memcmp, a library call per
  // comparison of the sort (a twentieth of the fft job's start-up).
  auto sameKey = [](const Keyed& x, const Keyed& y) {
    return x.key[0] == y.key[0] && x.key[1] == y.key[1] && x.key[2] == y.key[2];
  };
  tbb::parallel_sort(keyed.begin(), keyed.end(), [](const Keyed& x, const Keyed& y) {
    return std::tie(x.key[0], x.key[1], x.key[2], x.t) < std::tie(y.key[0], y.key[1], y.key[2], y.t);
  });
  std::vector<std::pair<uint32_t, size_t>> groups;  // (first facet, where its run starts in keyed)
  for (size_t i = 0; i < keyed.size(); ++i)
    if (i == 0 || !sameKey(keyed[i], keyed[i - 1])) groups.emplace_back(keyed[i].t, i);
  tbb::parallel_sort(groups.begin(), groups.end());  // first facets are distinct: a total order
  planes_.reserve(groups.size());
  planeFacets_.resize(keyed.size());
  planeFacetArea_.resize(keyed.size());
  size_t k = 0;
  for (const auto& [t0, start] : groups) {
    const Vec3 N = g.triangleNormal(t0);
    Plane p{N * (1.0 / length(N)), 0.0, k, 0};
    for (size_t i = start; i < keyed.size() && sameKey(keyed[i], keyed[start]); ++i, ++k, ++p.count) {
      const uint32_t t = keyed[i].t;
      p.area += halfArea[t];
      planeFacets_[k] = t;
      planeFacetArea_[k] = halfArea[t];
    }
    planes_.push_back(p);
  }
  facets_ = g.triangles.size();
  footprint_ = g.sizeX * g.sizeY;
  fresnel_ = conductorFresnelTables(material_, ior_);  // optics/fresnel_table.h
  slope_ = SlopeBound::of(g);
}

FacetSingleScattering::Rule FacetSingleScattering::rule(int incidenceBin, const std::optional<Vec3>& exactDirection,
                                                        int s) const {
  Rule r;
  if (exactDirection) {
    r.wi.push_back({normalize(*exactDirection), 1.0});
    return r;
  }
  for (int i = 0; i < s; ++i)
    for (int j = 0; j < s; ++j) {
      DirectionSample d = grid_.sampleCosine(incidenceBin, (i + 0.5) / s, (j + 0.5) / s);
      d.weight /= double(s) * s;
      r.wi.push_back(d);
    }
  return r;
}

FacetSingleScattering::Cost FacetSingleScattering::cost(int incidenceBin, const std::optional<Vec3>& exactDirection,
                                                        double stopAbove) const {
  Cost c;
  const bool dielectric = !material_.isConductor();
  const double nDir = material_.directionsIndependentOfLambda() ? 1.0 : double(lambda_um_.size());
  const int S = kSubdirections;
  const double directions = exactDirection ? 1.0 : double(S * S + (S / 2) * (S / 2));
  c.pairs = pairs(exactDirection.has_value());
  // A facet that needs visibility: its four first-level points, a lit and an exit ray each, and
  // half as many again for the splitting where they disagree (an estimate: only the run knows).
  const double perFacet = 12;
  if (!slope_.maxSlope) {
    c.rays = directions * double(facets_) * perFacet * (dielectric ? 2 : 1) * nDir;
    return c;
  }
  for (int pass = 0; pass < (exactDirection ? 1 : 2); ++pass) {
    const Rule r = rule(incidenceBin, exactDirection, pass == 0 ? S : S / 2);
    for (const auto& wi : r.wi) {
      const bool fromAbove = wi.w.z >= 0;
      const bool litClear = slope_.clear(wi.w);
      for (const Plane& p : planes_) {
        const Vec3 side = fromAbove ? p.n : -p.n;
        if (dot(wi.w, side) <= 0) continue;
        const Vec3 rf = reflect(wi.w, side);
        // A reflection into the other half-space is blocked on a periodic surface: no ray.
        if ((rf.z >= 0) == fromAbove && !(litClear && slope_.clear(rf))) c.rays += perFacet * nDir * double(p.count);
        if (dielectric && !litClear) c.rays += perFacet * nDir * double(p.count);  // the refracted side
      }
      if (c.rays > stopAbove) return c;  // the caller only needs to know the budget is exceeded
    }
  }
  return c;
}

double FacetSingleScattering::pairs(bool collimated) const {
  const int S = kSubdirections;
  const double directions = collimated ? 1.0 : double(S * S + (S / 2) * (S / 2));
  const double nDir = material_.directionsIndependentOfLambda() ? 1.0 : double(lambda_um_.size());
  return directions * double(planes_.size()) * nDir;
}

bool FacetSingleScattering::cheaperThan(int incidenceBin, const std::optional<Vec3>& exactDirection,
                                        double rays) const {
  // The pair count needs no loop: a tile that loses on pairs alone (a large heightfield) costs no
  // counting pass, and the count stops once the rays pass what is left of the budget.
  const double budget = rays - pairs(exactDirection.has_value()) / kPairsPerRay;
  if (budget < 0) return false;
  return cost(incidenceBin, exactDirection, budget).rays <= budget;
}

// The blocks' power per (λ, bin) summed in block order (deterministic) and divided by the bins'
// projected solid angles: f and its uncertainty; the blocks' rays added to *rays.
static void mergeBlocks(const DirectionGrid& grid, int nL, const std::vector<std::vector<double>>& block,
                        const std::vector<std::vector<double>>& blockU, const std::vector<uint64_t>& blockRays,
                        std::vector<double>& out, std::vector<double>& uncertain, uint64_t* rays) {
  const int nB = grid.binCount();
  out.assign(size_t(nL) * nB, 0.0);
  uncertain.assign(size_t(nL) * nB, 0.0);
  for (int k = 0; k < int(block.size()); ++k) {
    for (size_t i = 0; i < out.size(); ++i) {
      out[i] += block[size_t(k)][i];
      uncertain[i] += blockU[size_t(k)][i];
    }
    *rays += blockRays[size_t(k)];
  }
  for (int l = 0; l < nL; ++l)
    for (int bin = 0; bin < nB; ++bin) {
      const double op = grid.projectedSolidAngle(bin);
      const size_t i = size_t(l) * nB + bin;
      out[i] = op > 0 ? out[i] / op : 0.0;
      uncertain[i] = op > 0 ? uncertain[i] / op : 0.0;
    }
}

void FacetSingleScattering::sum(const Rule& r, std::vector<double>& out, std::vector<double>& uncertain,
                                uint64_t* rays) const {
  const int nL = int(lambda_um_.size()), nB = grid_.binCount();
  const bool conductor = material_.isConductor(), perfect = material_.isPerfectConductor();
  const bool shared = material_.directionsIndependentOfLambda();
  const double n1 = material_.outsideIor;
  const int rows = int(r.wi.size());
  std::vector<std::vector<double>> block(kBlocks), blockU(kBlocks);
  std::vector<uint64_t> blockRays(kBlocks, 0);
  tbb::parallel_for(0, kBlocks, [&](int k) {
    if (stopRequested()) return;
    std::vector<double>& acc = block[size_t(k)];
    std::vector<double>& accU = blockU[size_t(k)];
    acc.assign(size_t(nL) * nB, 0.0);
    accU.assign(size_t(nL) * nB, 0.0);
    uint64_t nRays = 0;
    for (int s = rows * k / kBlocks; s < rows * (k + 1) / kBlocks; ++s) {
      const Vec3 wi = r.wi[size_t(s)].w;
      const bool fromAbove = wi.z >= 0;
      const double scale = r.wi[size_t(s)].weight / (footprint_ * std::abs(wi.z));
      const bool litClear = slope_.clear(wi);
      for (const Plane& p : planes_) {
        const Vec3 side = fromAbove ? p.n : -p.n;
        const double cosLocal = std::min(1.0, dot(wi, side));
        if (cosLocal <= 0) continue;
        // Area-weighted fraction of the plane lit from wi that also sees d (on the side `up`,
        // leaving by the face `face`), and its uncertainty: 1 by the slope bound where it applies,
        // else by rays (visibleFraction per facet).
        struct Seen {
          double f = 0, u = 0;
        };
        auto seen = [&](const Vec3& d, const Vec3& face, bool up) {
          Seen v;
          if ((d.z >= 0) != up) return v;  // into the surface (periodic: it must meet it again)
          if (litClear && slope_.clear(d)) {
            v.f = 1;
            return v;
          }
          const bool dClear = slope_.clear(d);
          for (size_t q = p.first; q < p.first + p.count; ++q) {
            const uint32_t t = planeFacets_[q];
            auto test = [&](const Vec3& x) {
              if (!litClear) {
                ++nRays;
                if (!wave::escapes(scene_, x, side, wi, t, fromAbove)) return false;
              }
              if (dClear) return true;
              ++nRays;
              return wave::escapes(scene_, x, face, d, t, up);
            };
            const auto& tri = g_.triangles[t];
            double u = 0;
            const double share = planeFacetArea_[q] / p.area;
            v.f += share * visibleFraction(g_.vertices[tri[0]], g_.vertices[tri[1]], g_.vertices[tri[2]], test,
                                           kVisibilityDepth, &u);
            v.u += share * u;
          }
          return v;
        };
        const double power = p.area * cosLocal * scale;
        const Vec3 rf = reflect(wi, side);
        // Reflection: one direction for every wavelength.
        const Seen vr = seen(rf, side, fromAbove);
        const int binR = vr.f > 0 || vr.u > 0 ? grid_.binOf(rf) : -1;
        if (conductor) {
          if (binR < 0) continue;
          for (int l = 0; l < nL; ++l) {
            double F = 1.0;
            if (!perfect) F = fresnel_[size_t(l)](cosLocal);
            acc[size_t(l) * nB + binR] += power * F * vr.f;
            accU[size_t(l) * nB + binR] += power * F * vr.u;
          }
          continue;
        }
        // Dielectric (real index, as the path tracer takes it): reflected F, refracted 1 − F.
        Seen vt;
        bool refracted = false;
        int binT = -1;
        for (int l = 0; l < nL; ++l) {
          const double n2 = ior_[size_t(l)].real();
          const double etaI = fromAbove ? n1 : n2, etaT = fromAbove ? n2 : n1;
          const double F = fresnelReflectance(cosLocal, etaI, Complex(etaT, 0));
          if (binR >= 0) {
            acc[size_t(l) * nB + binR] += power * F * vr.f;
            accU[size_t(l) * nB + binR] += power * F * vr.u;
          }
          if (F >= 1) continue;
          if (!shared || !refracted) {
            Vec3 wt;
            if (!refract(wi, side, etaI / etaT, &wt)) continue;
            vt = seen(wt, -side, !fromAbove);
            binT = vt.f > 0 || vt.u > 0 ? grid_.binOf(wt) : -1;
            refracted = true;
          }
          if (binT >= 0) {
            acc[size_t(l) * nB + binT] += power * (1 - F) * vt.f;
            accU[size_t(l) * nB + binT] += power * (1 - F) * vt.u;
          }
        }
      }
    }
    blockRays[size_t(k)] = nRays;
  });
  throwIfStopped();
  mergeBlocks(grid_, nL, block, blockU, blockRays, out, uncertain, rays);
}

TileResult FacetSingleScattering::run(const TileRequest& q, const std::function<void(uint64_t)>& progress) const {
  const int tile = q.tile, incidenceIndex = q.incidenceIndex, incidenceBin = q.incidenceBin;
  const std::optional<Vec3>& exactDirection = q.exactDirection;
  const auto t0 = std::chrono::steady_clock::now();
  TileResult res;
  res.tile = tile;
  res.incidenceIndex = incidenceIndex;
  res.incidenceBin = incidenceBin;
  res.nLambda = int(lambda_um_.size());
  res.nBins = grid_.binCount();
  res.truncated = res.leaked = res.missed = std::vector<double>(size_t(res.nLambda), 0.0);
  std::vector<double> fine, uncertain, coarse, coarseUncertain;
  sum(rule(incidenceBin, exactDirection, kSubdirections), fine, uncertain, &res.rays);
  auto& err = res.stdError[int(Component::Coherent)];
  err = uncertain;
  if (!exactDirection) {
    // The incidence quadrature's error: the S/2 rule's distance (the coarser rule's error, so on
    // the safe side for the S rule).
    sum(rule(incidenceBin, exactDirection, kSubdirections / 2), coarse, coarseUncertain, &res.rays);
    for (size_t i = 0; i < fine.size(); ++i) err[i] += std::abs(fine[i] - coarse[i]);
  }
  res.value[int(Component::Coherent)] = std::move(fine);
  res.samples = 0;  // deterministic: no paths
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (progress) progress(0);
  return res;
}

}  // namespace mbsdf
