#include "job/symmetry.h"

#include "geometry/embree_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
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
  if (g.triangles.empty() || !(g.sizeX > 0 && g.sizeY > 0)) return {};
  // Centroids match within 1e-6 of the patch size along each axis (a long thin patch needs the
  // tolerance of its short side: with the long side's, a mirrored centroid of a 5000 × 1 µm grating
  // "matched" another facet a third of a row away).
  const Vec3 tol{1e-6 * g.sizeX, 1e-6 * g.sizeY, 1e-6 * std::max(g.sizeX, g.sizeY)}, cell = tol * 2.0;
  // Facets by centroid (wrapped into the periodic cell) and unit normal, hashed by the cell of
  // 2 tol that holds the centroid: a cell holds only facets whose centroids nearly coincide, so a
  // lookup costs O(1) for any patch shape (a grid of cells of 1e-3 L held thousands of facets each
  // on a 5000 × 1 µm grating of 1e7 facets: `check` took 227 s, now 11 s, most of it the mirror's
  // ray test).
  auto wrap = [&](double v, double size) { return g.periodic && size > 0 ? v - size * std::floor(v / size + 0.5) : v; };
  using Key = std::array<int32_t, 3>;
  std::vector<std::pair<Vec3, Vec3>> facets;
  facets.reserve(g.triangles.size());
  // Cell indices fit in int32 for centroids within 4e3 patch sizes of the centre; a patch with
  // facets beyond that (or with 2^32 of them) is not checked.
  constexpr double kMaxIndex = 2e9;
  auto indexable = [&](const Vec3& c) {
    return std::abs(c.x) < 0.5 * kMaxIndex * cell.x && std::abs(c.y) < 0.5 * kMaxIndex * cell.y &&
           std::abs(c.z) < 0.5 * kMaxIndex * cell.z;
  };
  if (g.triangles.size() >= std::numeric_limits<uint32_t>::max()) return {};
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    Vec3 c = (g.vertices[tri[0]] + g.vertices[tri[1]] + g.vertices[tri[2]]) * (1.0 / 3.0);
    c = {wrap(c.x, g.sizeX), wrap(c.y, g.sizeY), c.z};
    if (!indexable(c)) return {};
    facets.push_back({c, normalize(g.triangleNormal(t))});
  }
  auto keyOf = [&](const Vec3& c) {
    return Key{int32_t(std::floor(c.x / cell.x)), int32_t(std::floor(c.y / cell.y)), int32_t(std::floor(c.z / cell.z))};
  };
  // An open-addressing hash table (linear probing, load ≤ 1/2) from cell to the facets in it.
  size_t capacity = 1;
  while (capacity < 2 * facets.size()) capacity *= 2;
  const size_t mask = capacity - 1;
  constexpr uint32_t kEmpty = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> table(capacity, kEmpty);
  auto slotOf = [&](const Key& k) {
    // splitmix64's finaliser over the three indices: short probe chains whatever the mesh's layout.
    auto mix = [](uint64_t z) {
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      return z ^ (z >> 31);
    };
    return size_t(mix(mix(mix(uint32_t(k[0])) + uint32_t(k[1])) + uint32_t(k[2]))) & mask;
  };
  // More than 64 facets whose centroids coincide within 2e-6 L: a degenerate mesh whose
  // symmetries this test cannot tell apart (and whose lookups would no longer be cheap).
  constexpr int kMaxPerCell = 64;
  for (size_t f = 0; f < facets.size(); ++f) {
    const Key k = keyOf(facets[f].first);
    size_t pos = slotOf(k);
    int same = 0;
    for (; table[pos] != kEmpty; pos = (pos + 1) & mask) same += keyOf(facets[table[pos]].first) == k;
    if (same >= kMaxPerCell) return {};
    table[pos] = uint32_t(f);
  }
  // Is there a facet at centroid c with normal n? The match lies in c's cell or a neighbour; near
  // the edge of a periodic cell it may sit on the other side: the point is also looked up shifted
  // by one period.
  auto foundNear = [&](const Vec3& c, const Vec3& n) {
    if (!indexable(c)) return false;
    const Key k = keyOf(c);
    auto matchIn = [&](int dx, int dy, int dz) {
      const Key cellKey{k[0] + dx, k[1] + dy, k[2] + dz};
      for (size_t pos = slotOf(cellKey); table[pos] != kEmpty; pos = (pos + 1) & mask) {
        const auto& [fc, fn] = facets[table[pos]];
        const Vec3 d = fc - c;
        if (std::abs(d.x) <= tol.x && std::abs(d.y) <= tol.y && std::abs(d.z) <= tol.z && dot(fn, n) > 1 - 1e-9) return true;
      }
      return false;
    };
    if (matchIn(0, 0, 0)) return true;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz)
          if ((dx || dy || dz) && matchIn(dx, dy, dz)) return true;
    return false;
  };
  auto found = [&](const Vec3& c, const Vec3& n) {
    if (foundNear(c, n)) return true;
    if (!g.periodic) return false;
    const bool edgeX = std::abs(c.x) > 0.5 * g.sizeX - 2 * cell.x, edgeY = std::abs(c.y) > 0.5 * g.sizeY - 2 * cell.y;
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
  if (std::abs(g.sizeX - g.sizeY) <= tol.x && rotation(4)) s.rotationOrder = 4;
  else if (rotation(2)) s.rotationOrder = 2;
  s.mirror = invariantUnder(1, 0, 0, -1) || mirrorOfSurface(g, facets, wrap);
  return s;
}

AzimuthalSymmetry::AzimuthalSymmetry(const Job& job, const DirectionGrid& grid) {
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
