#include "job/symmetry.h"

#include "geometry/embree_scene.h"

#include <cmath>
#include <map>
#include <tuple>
#include <stdexcept>

namespace mbsdf {

namespace {
// The mirror y -> −y as a property of the surface rather than of its triangulation (a ruled or
// planar surface split along different diagonals): every facet centroid, mirrored, lies on the
// surface with the mirrored normal — a ray from 1e-4 L above it along the mirrored normal hits at
// that distance within 2e-5 L (Embree is float) with a normal within 1e-5.
template <class Wrap>
bool mirrorOfSurface(const Microgeometry& g, const std::vector<std::pair<Vec3, Vec3>>& facets, const Wrap& wrap) {
  const double L = std::max(g.sizeX, g.sizeY), h = 1e-4 * L;
  const PeriodicScene scene(g);
  for (const auto& [c, n] : facets) {
    const Vec3 mc{c.x, wrap(-c.y, g.sizeY), c.z}, mn{n.x, -n.y, n.z};
    const TraceResult r = scene.trace(mc + mn * h, -mn);
    if (r.kind != TraceResult::Kind::Hit || std::abs(r.t - h) > 2e-5 * L || dot(r.n, mn) < 1 - 1e-5) return false;
  }
  return true;
}
}  // namespace

PatchSymmetry patchSymmetryOf(const Microgeometry& g) {
  if (g.triangles.empty()) return {};
  const double L = std::max(g.sizeX, g.sizeY), tol = 1e-6 * L, cell = 1e-3 * L;
  // Facets by centroid (wrapped into the periodic cell) and unit normal, in a grid of cells of
  // 1e-3 L for the neighbour search.
  auto wrap = [&](double v, double size) { return g.periodic && size > 0 ? v - size * std::floor(v / size + 0.5) : v; };
  std::vector<std::pair<Vec3, Vec3>> facets;
  using Cell = std::tuple<long, long, long>;
  std::map<Cell, std::vector<size_t>> grid;
  auto cellOf = [&](const Vec3& c) {
    return Cell{long(std::floor(c.x / cell)), long(std::floor(c.y / cell)), long(std::floor(c.z / cell))};
  };
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    Vec3 c = (g.vertices[tri[0]] + g.vertices[tri[1]] + g.vertices[tri[2]]) * (1.0 / 3.0);
    c = {wrap(c.x, g.sizeX), wrap(c.y, g.sizeY), c.z};
    facets.push_back({c, normalize(g.triangleNormal(t))});
    grid[cellOf(c)].push_back(t);
  }
  // Is there a facet at centroid c with normal n? Near the edge of a periodic cell the match may
  // sit on the other side: the point is also looked up shifted by one period.
  auto foundNear = [&](const Vec3& c, const Vec3& n) {
    const Cell k = cellOf(c);
    for (long dx = -1; dx <= 1; ++dx)
      for (long dy = -1; dy <= 1; ++dy)
        for (long dz = -1; dz <= 1; ++dz) {
          auto it = grid.find(Cell{std::get<0>(k) + dx, std::get<1>(k) + dy, std::get<2>(k) + dz});
          if (it == grid.end()) continue;
          for (size_t f : it->second) {
            const Vec3 d = facets[f].first - c;
            if (std::abs(d.x) <= tol && std::abs(d.y) <= tol && std::abs(d.z) <= tol && dot(facets[f].second, n) > 1 - 1e-9)
              return true;
          }
        }
    return false;
  };
  auto found = [&](const Vec3& c, const Vec3& n) {
    if (foundNear(c, n)) return true;
    if (!g.periodic) return false;
    const bool edgeX = std::abs(c.x) > 0.5 * g.sizeX - 2 * cell, edgeY = std::abs(c.y) > 0.5 * g.sizeY - 2 * cell;
    for (int sx = edgeX ? -1 : 0; sx <= (edgeX ? 1 : 0); ++sx)
      for (int sy = edgeY ? -1 : 0; sy <= (edgeY ? 1 : 0); ++sy)
        if ((sx || sy) && foundNear(c + Vec3{sx * g.sizeX, sy * g.sizeY, 0}, n)) return true;
    return false;
  };
  // Invariance under the map (x, y) -> (a x + b y, c x + d y) of centroids and normals.
  auto invariantUnder = [&](double a, double b, double c, double d) {
    for (const auto& [p, n] : facets) {
      const Vec3 rp{wrap(a * p.x + b * p.y, g.sizeX), wrap(c * p.x + d * p.y, g.sizeY), p.z};
      if (!found(rp, {a * n.x + b * n.y, c * n.x + d * n.y, n.z})) return false;
    }
    return true;
  };
  auto rotation = [&](int order) {
    const double t = 2 * kPi / order;
    return invariantUnder(std::cos(t), -std::sin(t), std::sin(t), std::cos(t));
  };
  PatchSymmetry s;
  if (std::abs(g.sizeX - g.sizeY) <= tol && rotation(4)) s.rotationOrder = 4;
  else if (rotation(2)) s.rotationOrder = 2;
  s.mirror = invariantUnder(1, 0, 0, -1) || mirrorOfSurface(g, facets, wrap);
  return s;
}

AzimuthalSymmetry::AzimuthalSymmetry(const Job& job, const DirectionGrid& grid) : grid_(grid) {
  const auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout());
  if (!job.symmetryReduced() || !tp || !job.incidenceAll) throw std::logic_error("AzimuthalSymmetry: job is not reducible");
  nPhi_ = tp->nPhi;
  // Rotations by whole multiples of `step` bins are symmetries: every bin for an isotropic surface,
  // nPhi / n bins for an n-fold one (the job checks that n divides nPhi); with a mirror also
  // φ -> −φ, which maps bin p to nPhi − 1 − p.
  const int step = job.isotropic ? 1 : job.rotationOrder > 1 ? nPhi_ / job.rotationOrder : nPhi_;
  const bool mirror = job.mirrorSymmetric && !job.isotropic;
  auto apply = [&](int p, bool m, int shift) { return (((m ? nPhi_ - 1 - p : p) + shift) % nPhi_ + nPhi_) % nPhi_; };
  const int n = int(job.incidence.size()), perHemi = grid.binsPerHemisphere();
  std::map<int, int> indexOfBin;
  for (int i = 0; i < n; ++i) indexOfBin[job.incidence[size_t(i)].bin] = i;
  rep_.assign(size_t(n), -1);
  shift_.assign(size_t(n), 0);
  mirror_.assign(size_t(n), 0);
  members_.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const int bin = job.incidence[size_t(i)].bin, hemi = bin / perHemi, local = bin % perHemi;
    const int ringStart = hemi * perHemi + (local / nPhi_) * nPhi_, p = local % nPhi_;
    // The representative is the smallest azimuth index of p's orbit; (m, shift) maps it onto p.
    int best = p, bestShift = 0;
    bool bestMirror = false;
    for (int m = 0; m <= (mirror ? 1 : 0); ++m)
      for (int k = 0; k < nPhi_; k += step) {
        // q with apply(q, m, k) = p.
        const int q = m ? nPhi_ - 1 - (((p - k) % nPhi_ + nPhi_) % nPhi_) : ((p - k) % nPhi_ + nPhi_) % nPhi_;
        if (q < best) best = q, bestShift = k, bestMirror = m;
      }
    if (apply(best, bestMirror, bestShift) != p) throw std::logic_error("AzimuthalSymmetry: inconsistent transform");
    auto it = indexOfBin.find(ringStart + best);
    // Every bin of a ring has the same projected solid angle, so "all" holds whole rings.
    if (it == indexOfBin.end()) throw std::logic_error("AzimuthalSymmetry: incomplete ring");
    rep_[size_t(i)] = it->second;
    shift_[size_t(i)] = bestShift;
    mirror_[size_t(i)] = bestMirror;
    members_[size_t(it->second)].push_back(i);
  }
  for (int i = 0; i < n; ++i) count_ += rep_[size_t(i)] == i;
}

TileResult AzimuthalSymmetry::mappedSlice(const TileResult& r, int target, int targetBin) const {
  TileResult out = r;
  out.tile = target;
  out.incidenceIndex = target;
  out.incidenceBin = targetBin;
  const int s = shift_[size_t(target)];
  const bool m = mirror_[size_t(target)] != 0;
  if (s == 0 && !m) return out;
  for (int c = 0; c < kComponentCount; ++c) {
    if (r.value[size_t(c)].empty()) continue;
    for (int l = 0; l < r.nLambda; ++l)
      for (int b = 0; b < r.nBins; ++b) {
        // f(T(rep) -> o) = f(rep -> T^-1(o)): exit bin (ring, p') takes the representative's value at
        // (ring, p' − s), mirrored to nPhi − 1 − (p' − s) when T mirrors.
        const int ring = b / nPhi_, p = b % nPhi_;
        const int back = ((p - s) % nPhi_ + nPhi_) % nPhi_;
        const int from = ring * nPhi_ + (m ? nPhi_ - 1 - back : back);
        out.value[size_t(c)][size_t(l) * r.nBins + b] = r.value[size_t(c)][size_t(l) * r.nBins + from];
        out.stdError[size_t(c)][size_t(l) * r.nBins + b] = r.stdError[size_t(c)][size_t(l) * r.nBins + from];
      }
  }
  return out;
}

}  // namespace mbsdf
