// The facet sum of the `exact` estimator (exact_amplitude.h).
#include "scattering/exact_amplitude.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <functional>

#include "scattering/triangle_fourier.h"
#include "scattering/visibility_table.h"

namespace mbsdf::wave {
namespace {
constexpr int kSubOffset[kExactMaxDepth + 1] = {0, 0, 16, 80};  // first sub-point of each depth
}  // namespace

std::vector<uint8_t> firstLevelShadowing(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                                         const SlopeBound& slope, const Vec3& wi, bool fromAbove, uint64_t* rays) {
  const Microgeometry& g = ctx.geometry;
  std::vector<uint8_t> lit(g.triangles.size(), 0);
  const bool clear = slope.clear(wi);  // above a heightfield's steepest slope: every facing point is lit
  std::atomic<uint64_t> count{0};
  tbb::parallel_for(size_t(0), cell.facets.size(), [&](size_t f) {
    const size_t t = cell.facets[f];
    const Vec3 n = g.triangleNormal(t);
    if (dot(n, n) == 0) return;
    const Vec3 m = fromAbove ? normalize(n) : -normalize(n);
    if (dot(m, wi) <= 0) return;
    if (clear) {
      lit[t] = 0xF;
      return;
    }
    const auto& tri = g.triangles[t];
    const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
    uint8_t bits = 0;
    for (int k = 0; k < 4; ++k) {
      const std::optional<bool> known = table ? table->escapes(uint32_t(t), k, m, wi, fromAbove) : std::nullopt;
      if (!known) ++count;
      if (known ? *known : escapes(ctx.scene, pts[size_t(k)], m, wi, unsigned(t), fromAbove)) bits |= uint8_t(1 << k);
    }
    lit[t] = bits;
  });
  *rays += count.load();
  return lit;
}

void exactAmplitude(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                    const SlopeBound& slope, const OrderDirection& ord, const Vec3& wi, bool fromAbove,
                    const Media& media, bool masked, const std::vector<uint8_t>& lit, ShadowCache& shadow, Complex* H,
                    uint64_t* rays) {
  const Microgeometry& g = ctx.geometry;
  const int l = ord.lambda;
  const double k0 = 2 * kPi / ctx.lambda_um[size_t(l)];
  const double nI = media.incident(l, fromAbove), nO = ord.transmission ? media.other(l, fromAbove) : nI;
  const Vec3 q = wi * (-nI * k0) - ord.wo * (nO * k0);  // k1 − k2, as in kirchhoffIntegrand
  Complex Hc[4] = {0, 0, 0, 0};
  // On a heightfield, directions above its steepest slope need no ray (SlopeBound): the light
  // reaches every facing point, and an order leaving on its own side is seen from every point of a
  // facet that faces it.
  const bool litClear = slope.clear(wi);
  const bool exitClear = ((ord.wo.z > 0) == (fromAbove != ord.transmission)) && slope.clear(ord.wo);
  for (size_t slot = 0; slot < cell.facets.size(); ++slot) {
    const uint32_t t = cell.facets[slot];
    const auto& tri = g.triangles[t];
    const Vec3 n = g.triangleNormal(t);
    if (dot(n, n) == 0) continue;  // degenerate: no area
    const Vec3 m = fromAbove ? normalize(n) : -normalize(n);
    const double cosLocal = dot(m, wi);
    if (cosLocal <= 0 || lit[t] == 0) continue;  // back-facing to the light, or shadowed at every first-level point
    const double mo = dot(m, ord.wo);
    if (ord.transmission ? mo >= 0 : mo <= 0) continue;  // back-facing to the order direction
    // g (s, p) of the facet: the integrand without its phase.
    const KirchhoffValue g0 = integrandAt(media, l, Vec3{0, 0, 0}, m, wi, ord.wo, k0, fromAbove, ord.transmission);
    // 0 shadowed, 1 visible, 2 masked, for a point of facet t; `firstLevel` >= 0: the point is the
    // facet's first-level point of that index, whose shadowing is known (`lit`) and whose masking
    // the shared table may answer (the facet faces ω_G here, so visibleExit's answer is escapes');
    // otherwise `sub` indexes its shadowing in the cache.
    auto state = [&](const Vec3& x, int firstLevel, size_t sub) {
      if (firstLevel < 0 && !litClear) {
        std::atomic<uint8_t>& known = shadow.state[slot * kExactSubPoints + sub];
        uint8_t st = known.load(std::memory_order_relaxed);
        if (st == 0) {
          st = escapes(ctx.scene, x, m, wi, unsigned(t), fromAbove) ? 1 : 2;
          // Counted by the thread that stores it (a ray two threads raced to cast counts once).
          uint8_t unknown = 0;
          if (known.compare_exchange_strong(unknown, st, std::memory_order_relaxed)) ++*rays;
        }
        if (st == 2) return 0;
      } else if (firstLevel >= 0 && !((lit[t] >> firstLevel) & 1))
        return 0;
      if (exitClear) return 1;
      if (table && firstLevel >= 0)
        if (const auto e = ord.transmission ? table->escapes(t, firstLevel, -m, ord.wo, !fromAbove)
                                            : table->escapes(t, firstLevel, m, ord.wo, fromAbove))
          return *e ? 1 : 2;
      const ExitVisibility v = visibleExit(ctx.scene, x, m, ord.wo, unsigned(t), fromAbove, ord.transmission, rays);
      return v == ExitVisibility::Visible ? 1 : 2;
    };
    auto add = [&](const Vec3& a, const Vec3& b, const Vec3& c, int st) {
      if (st == 0 || (st == 2 && !masked)) return;
      const Complex f = triangleFourier(a, b, c, q);
      Hc[st == 1 ? 0 : 2] += g0.s * f;
      Hc[st == 1 ? 1 : 3] += g0.p * f;
    };
    // Visibility by the centroid and three points inset towards the vertices; split where they
    // disagree.
    // `path`: the sub-element's index among the 4^depth of its depth.
    std::function<void(const Vec3&, const Vec3&, const Vec3&, int, size_t)> element =
        [&](const Vec3& a, const Vec3& b, const Vec3& c, int depth, size_t path) {
          const auto pts = firstLevelPoints(a, b, c);
          auto st = [&](int k) {
            return state(pts[size_t(k)], depth == 0 ? k : -1, size_t(kSubOffset[depth]) + path * 4 + size_t(k));
          };
          const int s0 = st(0);
          bool agree = true;
          for (int k = 1; k < 4; ++k) agree = agree && st(k) == s0;
          if (agree || depth == kExactMaxDepth) {
            add(a, b, c, s0);
            return;
          }
          const Vec3 ab = (a + b) * 0.5, bc = (b + c) * 0.5, ca = (c + a) * 0.5;
          element(a, ab, ca, depth + 1, path * 4);
          element(ab, b, bc, depth + 1, path * 4 + 1);
          element(ca, bc, c, depth + 1, path * 4 + 2);
          element(ab, bc, ca, depth + 1, path * 4 + 3);
        };
    element(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]], 0, 0);
  }
  for (int i = 0; i < 4; ++i) H[i] += double(cell.copies()) * Hc[i];
}

}  // namespace mbsdf::wave
