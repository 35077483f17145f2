#include "scattering/visibility_table.h"

#include <tbb/parallel_for.h>

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
  words_ = wordsPerRow(M);
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
  bits_.assign(size_t(H) * F * 4 * words_, 0);
  std::atomic<uint64_t> rays{0};
  for (int h = 0; h < H; ++h) {
    const bool up = h == 0;
    tbb::parallel_for(size_t(0), F, [&](size_t f) {
      if (stopRequested()) return;
      const Vec3& n = normal_[f];
      if (dot(n, n) == 0) return;
      const Vec3 side = up ? n : -n;
      const auto& tri = g.triangles[cell.facets[f]];
      const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
      uint64_t count = 0;
      for (int k = 0; k < 4; ++k) {
        uint64_t* row = &bits_[((size_t(h) * F + f) * 4 + size_t(k)) * words_];
        for (int i = 0; i <= M_; ++i)
          for (int j = 0; j <= M_; ++j) {
            if (!cornerInside(i, j)) continue;
            const Vec3 d = corner(i, j, up);
            if (dot(side, d) <= 0) continue;  // the facet's own horizon: not stored (never agreed on)
            ++count;
            if (wave::escapes(scene, pts[size_t(k)], side, d, cell.facets[f], up)) {
              const size_t c = size_t(i) * size_t(M_ + 1) + size_t(j);
              row[c / 64] |= uint64_t(1) << (c % 64);
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

std::optional<bool> VisibilityTable::escapes(uint32_t t, int k, const Vec3& side, const Vec3& d, bool up) const {
  if (t >= slot_.size() || slot_[t] < 0 || (d.z > 0) != up || (!up && !lower_)) return std::nullopt;
  const size_t f = size_t(slot_[t]);
  const Vec3& n = normal_[f];
  // The table was built from the upper side for the upper hemisphere and from the lower side for
  // the lower one.
  if (dot(side, n) * (up ? 1 : -1) <= 0) return std::nullopt;
  const int i = std::clamp(int(std::floor((d.x + 1) * 0.5 * M_)), 0, M_ - 1);
  const int j = std::clamp(int(std::floor((d.y + 1) * 0.5 * M_)), 0, M_ - 1);
  const size_t F = normal_.size();
  const uint64_t* row = &bits_[((size_t(up ? 0 : 1) * F + f) * 4 + size_t(k)) * words_];
  int value = -1;
  for (int di = 0; di <= 1; ++di)
    for (int dj = 0; dj <= 1; ++dj) {
      if (!cornerInside(i + di, j + dj) || dot(side, corner(i + di, j + dj, up)) <= 0) return std::nullopt;
      const size_t c = size_t(i + di) * size_t(M_ + 1) + size_t(j + dj);
      const int b = int((row[c / 64] >> (c % 64)) & 1);
      if (value >= 0 && b != value) return std::nullopt;
      value = b;
    }
  return value == 1;
}

}  // namespace mbsdf
