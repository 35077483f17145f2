#include "scattering/visibility_table.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

#include "core/stop.h"
#include "scattering/wave_common.h"

namespace mbsdf {

VisibilityTable::VisibilityTable(const Microgeometry& g, const PeriodicScene& scene, const LatticeCell& cell, int M,
                                 bool lowerHemisphere)
    : M_(M), lower_(lowerHemisphere) {
  const auto t0 = std::chrono::steady_clock::now();
  const size_t F = cell.facets.size();
  words_ = wordsPerRow(F);
  coord_.resize(size_t(M) + 1);
  for (int i = 0; i <= M; ++i) coord_[size_t(i)] = -1 + 2.0 * i / M;
  cornerZ_.resize(size_t(M + 1) * size_t(M + 1));
  for (int i = 0; i <= M; ++i)
    for (int j = 0; j <= M; ++j) {
      const double x = coord_[size_t(i)], y = coord_[size_t(j)];
      cornerZ_[size_t(i) * size_t(M + 1) + size_t(j)] = x * x + y * y < 1 - 1e-12 ? safeSqrt(1 - x * x - y * y) : -1;
    }
  slot_.assign(g.triangles.size(), -1);
  normal_.resize(F);
  for (size_t f = 0; f < F; ++f) {
    slot_[cell.facets[f]] = int32_t(f);
    const Vec3 n = g.triangleNormal(cell.facets[f]);
    normal_[f] = dot(n, n) > 0 ? normalize(n) : Vec3{0, 0, 0};
  }
  const int H = lower_ ? 2 : 1;
  const size_t corners = size_t(M + 1) * size_t(M + 1);
  bits_.assign(size_t(H) * corners * words_, 0);
  std::atomic<uint64_t> rays{0};
  for (int h = 0; h < H; ++h) {
    const bool up = h == 0;
    // By word: the 16 facets whose points share a word of every corner row, so no two tasks write
    // the same word.
    tbb::parallel_for(size_t(0), words_, [&](size_t w) {
      uint64_t count = 0;
      for (size_t f = 16 * w; f < std::min(F, 16 * w + 16); ++f) {
        if (stopRequested()) return;
        const Vec3& n = normal_[f];
        if (dot(n, n) == 0) continue;
        const Vec3 side = up ? n : -n;
        const auto& tri = g.triangles[cell.facets[f]];
        const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
        for (int k = 0; k < 4; ++k) {
          const uint64_t bit = uint64_t(1) << ((4 * f + size_t(k)) % 64);
          for (int i = 0; i <= M_; ++i)
            for (int j = 0; j <= M_; ++j) {
              if (!cornerInside(i, j)) continue;
              const Vec3 d = corner(i, j, up);
              if (dot(side, d) <= 0) continue;  // the facet's own horizon: not stored (never agreed on)
              ++count;
              if (wave::escapes(scene, pts[size_t(k)], side, d, cell.facets[f], up))
                bits_[(size_t(h) * corners + size_t(i) * size_t(M_ + 1) + size_t(j)) * words_ + w] |= bit;
            }
        }
      }
      rays += count;
    });
    throwIfStopped();
  }
  rays_ = rays.load();
  seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

bool VisibilityTable::cornerInside(int i, int j) const {
  return cornerZ_[size_t(i) * size_t(M_ + 1) + size_t(j)] >= 0;
}

Vec3 VisibilityTable::corner(int i, int j, bool up) const {
  const double z = cornerZ_[size_t(i) * size_t(M_ + 1) + size_t(j)];
  return {coord_[size_t(i)], coord_[size_t(j)], up ? z : -z};
}

VisibilityTable::Cell VisibilityTable::cellOf(const Vec3& d, bool up) const {
  Cell c;
  c.up = up;
  if ((d.z > 0) != up || (!up && !lower_)) return c;
  const int i = std::clamp(int(std::floor((d.x + 1) * 0.5 * M_)), 0, M_ - 1);
  const int j = std::clamp(int(std::floor((d.y + 1) * 0.5 * M_)), 0, M_ - 1);
  const size_t corners = size_t(M_ + 1) * size_t(M_ + 1);
  for (int di = 0; di <= 1; ++di)
    for (int dj = 0; dj <= 1; ++dj) {
      if (!cornerInside(i + di, j + dj)) return c;
      const size_t at = size_t(2 * di + dj), k = size_t(i + di) * size_t(M_ + 1) + size_t(j + dj);
      c.corner[at] = corner(i + di, j + dj, up);
      c.row[at] = &bits_[(size_t(up ? 0 : 1) * corners + k) * words_];
    }
  c.usable = true;
  return c;
}

bool VisibilityTable::answers(const Cell& cell, uint32_t t, const Vec3& side) const {
  if (!cell.usable || t >= slot_.size() || slot_[t] < 0) return false;
  // The table was built from the upper side for the upper hemisphere and from the lower side for
  // the lower one.
  if (dot(side, normal_[size_t(slot_[t])]) * (cell.up ? 1 : -1) <= 0) return false;
  for (const Vec3& c : cell.corner)
    if (dot(side, c) <= 0) return false;  // the facet's own horizon: never stored
  return true;
}

std::optional<bool> VisibilityTable::escapes(uint32_t t, int k, const Vec3& side, const Vec3& d, bool up) const {
  const Cell cell = cellOf(d, up);
  if (!answers(cell, t, side)) return std::nullopt;
  return escapes(cell, t, k);
}

}  // namespace mbsdf
