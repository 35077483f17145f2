#include "geometry/facet_index.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace mbsdf {

namespace {
constexpr uint32_t kEmpty = std::numeric_limits<uint32_t>::max();
// Cell indices fit in int32 for centroids within 4e3 patch sizes of the centre.
constexpr double kMaxIndex = 2e9;
// More than this many facets in one cell: a degenerate mesh (and lookups would no longer be cheap).
constexpr int kMaxPerCell = 64;
}  // namespace

FacetIndex::FacetIndex(const Microgeometry& g) : sizeX_(g.sizeX), sizeY_(g.sizeY), periodic_(g.periodic) {
  if (g.triangles.empty() || !(g.sizeX > 0 && g.sizeY > 0) || g.triangles.size() >= kEmpty) return;
  tol_ = {1e-6 * g.sizeX, 1e-6 * g.sizeY, 1e-6 * std::max(g.sizeX, g.sizeY)};
  cell_ = tol_ * 2.0;
  facets_.reserve(g.triangles.size());
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    Vec3 c = (g.vertices[tri[0]] + g.vertices[tri[1]] + g.vertices[tri[2]]) * (1.0 / 3.0);
    c = {wrap(c.x, g.sizeX), wrap(c.y, g.sizeY), c.z};
    if (!indexable(c)) return;
    facets_.push_back({c, normalize(g.triangleNormal(t))});
  }
  size_t capacity = 1;
  while (capacity < 2 * facets_.size()) capacity *= 2;
  mask_ = capacity - 1;
  table_.assign(capacity, kEmpty);
  // The facets' cells first, so that the table's slots a few facets ahead are fetched while this
  // one is placed (each is a random place in a table of megabytes: 3/4 of the time went on waiting
  // for them one by one), and a probe compares an occupant's cell from there instead of computing
  // it again from a centroid fetched from anywhere in the facets. 12 bytes a facet, for the build.
  std::vector<Key> keys(facets_.size());
  for (size_t f = 0; f < facets_.size(); ++f) keys[f] = keyOf(facets_[f].first);
  constexpr size_t kAhead = 16;
  for (size_t f = 0; f < facets_.size(); ++f) {
    // Two stages: the slot 16 facets ahead, and the cell of the occupant of the slot 8 ahead (its
    // slot fetched by then).
    if (f + kAhead < facets_.size()) __builtin_prefetch(&table_[slotOf(keys[f + kAhead])]);
    if (f + kAhead / 2 < facets_.size()) {
      const uint32_t occupant = table_[slotOf(keys[f + kAhead / 2])];
      if (occupant != kEmpty) __builtin_prefetch(&keys[occupant]);
    }
    const Key& k = keys[f];
    size_t pos = slotOf(k);
    int same = 0;
    for (; table_[pos] != kEmpty; pos = (pos + 1) & mask_) {
      const Key& o = keys[table_[pos]];
      same += o[0] == k[0] && o[1] == k[1] && o[2] == k[2];
    }
    if (same >= kMaxPerCell) return;
    table_[pos] = uint32_t(f);
  }
  usable_ = true;
}

bool FacetIndex::indexable(const Vec3& c) const {
  return std::abs(c.x) < 0.5 * kMaxIndex * cell_.x && std::abs(c.y) < 0.5 * kMaxIndex * cell_.y &&
         std::abs(c.z) < 0.5 * kMaxIndex * cell_.z;
}

FacetIndex::Key FacetIndex::keyOf(const Vec3& c) const {
  return Key{int32_t(std::floor(c.x / cell_.x)), int32_t(std::floor(c.y / cell_.y)),
             int32_t(std::floor(c.z / cell_.z))};
}

size_t FacetIndex::slotOf(const Key& k) const {
  // splitmix64's finaliser over the three indices: short probe chains whatever the mesh's layout.
  auto mix = [](uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  };
  return size_t(mix(mix(mix(uint32_t(k[0])) + uint32_t(k[1])) + uint32_t(k[2]))) & mask_;
}

// The match lies in c's cell or a neighbour.
std::optional<uint32_t> FacetIndex::findNear(const Vec3& c, const Vec3& n) const {
  if (!indexable(c)) return std::nullopt;
  const Key k = keyOf(c);
  auto matchIn = [&](int dx, int dy, int dz) -> std::optional<uint32_t> {
    const Key cellKey{k[0] + dx, k[1] + dy, k[2] + dz};
    for (size_t pos = slotOf(cellKey); table_[pos] != kEmpty; pos = (pos + 1) & mask_) {
      const auto& [fc, fn] = facets_[table_[pos]];
      const Vec3 d = fc - c;
      if (std::abs(d.x) <= tol_.x && std::abs(d.y) <= tol_.y && std::abs(d.z) <= tol_.z && dot(fn, n) > 1 - 1e-9)
        return table_[pos];
    }
    return std::nullopt;
  };
  if (auto f = matchIn(0, 0, 0)) return f;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if (dx || dy || dz)
          if (auto f = matchIn(dx, dy, dz)) return f;
  return std::nullopt;
}

std::optional<uint32_t> FacetIndex::find(const Vec3& c0, const Vec3& n) const {
  if (!usable_) return std::nullopt;
  const Vec3 c{wrap(c0.x, sizeX_), wrap(c0.y, sizeY_), c0.z};
  if (auto f = findNear(c, n)) return f;
  if (!periodic_) return std::nullopt;
  // Near the edge of a periodic cell the match may sit on the other side: look it up shifted by
  // one period.
  const bool edgeX = std::abs(c.x) > 0.5 * sizeX_ - 2 * cell_.x, edgeY = std::abs(c.y) > 0.5 * sizeY_ - 2 * cell_.y;
  for (int sx = edgeX ? -1 : 0; sx <= (edgeX ? 1 : 0); ++sx)
    for (int sy = edgeY ? -1 : 0; sy <= (edgeY ? 1 : 0); ++sy)
      if (sx || sy)
        if (auto f = findNear(c + Vec3{sx * sizeX_, sy * sizeY_, 0}, n)) return f;
  return std::nullopt;
}

}  // namespace mbsdf
