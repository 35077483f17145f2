#include "job/symmetry.h"

#include "geometry/embree_scene.h"
#include "geometry/facet_index.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
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
  const FacetIndex index(g);
  if (!index.usable()) return {};
  auto wrap = [&](double v, double size) { return index.wrap(v, size); };
  // Invariance under the map (x, y) -> (a x + b y, c x + d y) of centroids and normals.
  auto invariantUnder = [&](double a, double b, double c, double d) {
    for (const auto& [p, n] : index.facets())
      if (!index.find({a * p.x + b * p.y, c * p.x + d * p.y, p.z}, {a * n.x + b * n.y, c * n.x + d * n.y, n.z}))
        return false;
    return true;
  };
  auto rotation = [&](int order) {
    const double t = 2 * kPi / order;
    return invariantUnder(std::cos(t), -std::sin(t), std::sin(t), std::cos(t));
  };
  PatchSymmetry s;
  if (std::abs(g.sizeX - g.sizeY) <= 1e-6 * g.sizeX && rotation(4))
    s.rotationOrder = 4;
  else if (rotation(2))
    s.rotationOrder = 2;
  s.mirror = invariantUnder(1, 0, 0, -1) || mirrorOfSurface(g, index.facets(), wrap);
  return s;
}

AzimuthalSymmetry::AzimuthalSymmetry(const Job& job, const DirectionGrid& grid) {
  const auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout());
  if (!job.symmetryReduced() || !tp || !job.incidenceAll)
    throw std::logic_error("AzimuthalSymmetry: job is not reducible");
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
