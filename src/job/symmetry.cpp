#include "job/symmetry.h"

#include <cmath>
#include <map>
#include <tuple>
#include <stdexcept>

namespace mbsdf {

int rotationOrderOf(const Microgeometry& g) {
  if (g.triangles.empty()) return 1;
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
  auto invariant = [&](int order) {
    const double a = 2 * kPi / order, ca = std::cos(a), sa = std::sin(a);
    for (const auto& [c, n] : facets) {
      const Vec3 rc{wrap(ca * c.x - sa * c.y, g.sizeX), wrap(sa * c.x + ca * c.y, g.sizeY), c.z};
      if (!found(rc, {ca * n.x - sa * n.y, sa * n.x + ca * n.y, n.z})) return false;
    }
    return true;
  };
  if (std::abs(g.sizeX - g.sizeY) <= tol && invariant(4)) return 4;
  if (invariant(2)) return 2;
  return 1;
}

AzimuthalSymmetry::AzimuthalSymmetry(const Job& job, const DirectionGrid& grid) : grid_(grid) {
  const auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout());
  if (!job.symmetryReduced() || !tp || !job.incidenceAll) throw std::logic_error("AzimuthalSymmetry: job is not reducible");
  nPhi_ = tp->nPhi;
  // Rotations by whole multiples of `step` bins are symmetries: every bin for an isotropic surface,
  // nPhi / n bins for an n-fold one (the job checks that n divides nPhi).
  const int step = job.isotropic ? 1 : nPhi_ / job.rotationOrder;
  const int n = int(job.incidence.size()), perHemi = grid.binsPerHemisphere();
  std::map<int, int> indexOfBin;
  for (int i = 0; i < n; ++i) indexOfBin[job.incidence[size_t(i)].bin] = i;
  rep_.assign(size_t(n), -1);
  shift_.assign(size_t(n), 0);
  members_.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const int bin = job.incidence[size_t(i)].bin, hemi = bin / perHemi, local = bin % perHemi;
    const int repBin = hemi * perHemi + (local / nPhi_) * nPhi_ + (local % nPhi_) % step;
    auto it = indexOfBin.find(repBin);
    // Every bin of a ring has the same projected solid angle, so "all" holds whole rings.
    if (it == indexOfBin.end()) throw std::logic_error("AzimuthalSymmetry: incomplete ring");
    rep_[size_t(i)] = it->second;
    shift_[size_t(i)] = local % nPhi_ - (local % nPhi_) % step;
    members_[size_t(it->second)].push_back(i);
  }
  for (int i = 0; i < n; ++i) count_ += rep_[size_t(i)] == i;
}

TileResult AzimuthalSymmetry::rotate(const TileResult& r, int target, int targetBin) const {
  TileResult out = r;
  out.tile = target;
  out.incidenceIndex = target;
  out.incidenceBin = targetBin;
  const int s = shift_[size_t(target)];
  if (s == 0) return out;
  for (int c = 0; c < kComponentCount; ++c) {
    if (r.value[size_t(c)].empty()) continue;
    for (int l = 0; l < r.nLambda; ++l)
      for (int b = 0; b < r.nBins; ++b) {
        // Exit bin b = (ring, p') takes the value of (ring, p' − s) of the representative.
        const int ring = b / nPhi_, p = b % nPhi_;
        const int from = ring * nPhi_ + ((p - s) % nPhi_ + nPhi_) % nPhi_;
        out.value[size_t(c)][size_t(l) * r.nBins + b] = r.value[size_t(c)][size_t(l) * r.nBins + from];
        out.stdError[size_t(c)][size_t(l) * r.nBins + b] = r.stdError[size_t(c)][size_t(l) * r.nBins + from];
      }
  }
  return out;
}

}  // namespace mbsdf
