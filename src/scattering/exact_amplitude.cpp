// The facet sum of the `exact` estimator (exact_amplitude.h).
#include "scattering/exact_amplitude.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>

#include "scattering/triangle_fourier.h"
#include "scattering/visibility_table.h"

namespace mbsdf::wave {
namespace {
constexpr int kSubOffset[kExactMaxDepth + 1] = {0, 0, 16, 80};  // first sub-point of each depth

// The visibility of points of one facet t (unit normal m towards the incident medium) for one
// order: 0 shadowed, 1 visible, 2 masked.
struct FacetVisibility {
  const WaveContext& ctx;
  const VisibilityTable* table;
  const VisibilityTable::Cell& exitCell;  // the table's cell of ω_G
  bool tableAnswers;                      // whether the table answers for this facet at exitCell
  const std::vector<uint8_t>& lit;
  ShadowCache& shadow;
  const OrderDirection& ord;
  Vec3 wi;
  bool fromAbove, litClear, exitClear;
  uint32_t t;
  size_t slot;  // t's index in the cell (its rows of the shadow cache)
  Vec3 m;
  uint64_t* rays;

  // First-level point k: its shadowing is known (`lit`), and the shared table may answer its
  // masking (the facet faces ω_G here, so visibleExit's answer is escapes').
  int firstLevel(const Vec3& x, int k) const {
    if (!((lit[t] >> k) & 1)) return 0;
    if (exitClear) return 1;
    if (tableAnswers)
      if (const auto e = table->escapes(exitCell, t, k)) return *e ? 1 : 2;
    const ExitVisibility v = visibleExit(ctx.scene, x, m, ord.wo, t, fromAbove, ord.transmission, rays);
    return v == ExitVisibility::Visible ? 1 : 2;
  }

  // Sub-element points x[0..count) (count <= 16) with shadow-cache slots `sub`: shadowing from the
  // cache (cast and stored on first use), then the lit points' masking rays towards ω_G together,
  // as packets: they start within one facet and run parallel, the most coherent rays there are.
  void subElements(const Vec3* x, const size_t* sub, int count, int* st) const {
    std::array<Vec3, 16> o;
    std::array<int, 16> which;
    int n = 0;
    for (int k = 0; k < count; ++k) {
      if (!litClear) {
        std::atomic<uint8_t>& known = shadow.state[slot * kExactSubPoints + sub[k]];
        uint8_t sh = known.load(std::memory_order_relaxed);
        if (sh == 0) {
          sh = escapes(ctx.scene, x[k], m, wi, t, fromAbove) ? 1 : 2;
          // Counted by the thread that stores it (a ray two threads raced to cast counts once).
          uint8_t unknown = 0;
          if (known.compare_exchange_strong(unknown, sh, std::memory_order_relaxed)) ++*rays;
        }
        if (sh == 2) {
          st[k] = 0;
          continue;
        }
      }
      st[k] = 1;
      if (exitClear) continue;
      // visibleExit's ray (the facet faces ω_G: it was checked before any point was asked).
      o[size_t(n)] = x[k] + (ord.transmission ? -m : m) * ctx.scene.rayEpsilon();
      which[size_t(n++)] = k;
    }
    if (n == 0) return;
    std::array<uint8_t, 16> seen;
    ctx.scene.escapesMany({o.data(), size_t(n)}, ord.wo, int(t), ord.transmission ? !fromAbove : fromAbove,
                          {seen.data(), size_t(n)});
    *rays += uint64_t(n);
    for (int r = 0; r < n; ++r) st[which[size_t(r)]] = seen[size_t(r)] ? 1 : 2;
  }
};
}  // namespace

IncidenceFacets incidenceFacets(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                                const SlopeBound& slope, const Vec3& wi, bool fromAbove, const Media& media,
                                uint64_t* rays) {
  const Microgeometry& g = ctx.geometry;
  const size_t F = cell.facets.size();
  IncidenceFacets out;
  out.lit.assign(g.triangles.size(), 0);
  out.m.resize(F);
  out.fresnel.resize(ctx.lambda_um.size() * F);
  std::vector<uint8_t>& lit = out.lit;
  const bool clear = slope.clear(wi);  // above a heightfield's steepest slope: every facing point is lit
  const VisibilityTable::Cell litCell = table ? table->cellOf(wi, fromAbove) : VisibilityTable::Cell{};
  std::atomic<uint64_t> count{0};
  tbb::parallel_for(size_t(0), cell.facets.size(), [&](size_t f) {
    const size_t t = cell.facets[f];
    const Vec3 n = g.triangleNormal(t);
    if (dot(n, n) == 0) return;
    const Vec3 m = fromAbove ? normalize(n) : -normalize(n);
    if (dot(m, wi) <= 0) return;
    out.m[f] = m;
    for (size_t l = 0; l < ctx.lambda_um.size(); ++l)
      out.fresnel[l * F + f] = media.fresnel(int(l), dot(m, wi), fromAbove);
    if (clear) {
      lit[t] = 0xF;
      return;
    }
    const auto& tri = g.triangles[t];
    const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
    uint8_t bits = 0;
    const bool tableAnswers = table && table->answers(litCell, uint32_t(t), m);
    for (int k = 0; k < 4; ++k) {
      const std::optional<bool> known = tableAnswers ? table->escapes(litCell, uint32_t(t), k) : std::nullopt;
      if (!known) ++count;
      if (known ? *known : escapes(ctx.scene, pts[size_t(k)], m, wi, unsigned(t), fromAbove)) bits |= uint8_t(1 << k);
    }
    lit[t] = bits;
  });
  *rays += count.load();
  return out;
}

void exactAmplitude(const WaveContext& ctx, const LatticeCell& cell, const VisibilityTable* table,
                    const SlopeBound& slope, const OrderDirection& ord, const Vec3& wi, bool fromAbove,
                    const Media& media, bool masked, const IncidenceFacets& facets, ShadowCache& shadow, Complex* H,
                    uint64_t* rays) {
  const Microgeometry& g = ctx.geometry;
  const std::vector<uint8_t>& lit = facets.lit;
  // The reverse path's integrand takes its Fresnel factor at ω_G (wave::integrandAt).
  const bool reverse = ord.transmission && media.reverseTransmission(ord.lambda, fromAbove);
  const int l = ord.lambda;
  const double k0 = 2 * kPi / ctx.lambda_um[size_t(l)];
  const double nI = media.incident(l, fromAbove), nO = ord.transmission ? media.other(l, fromAbove) : nI;
  const Vec3 q = wi * (-nI * k0) - ord.wo * (nO * k0);  // k1 − k2, as in kirchhoffIntegrand
  Complex Hc[4] = {0, 0, 0, 0};
  // Rays counted here and added once: the orders run in parallel and their counters are neighbours
  // (threads counting into one cache line serialise on it).
  uint64_t raysHere = 0;
  // On a heightfield, directions above its steepest slope need no ray (SlopeBound): the light
  // reaches every facing point, and an order leaving on its own side is seen from every point of a
  // facet that faces it.
  const bool litClear = slope.clear(wi);
  const bool exitClear = ((ord.wo.z > 0) == (fromAbove != ord.transmission)) && slope.clear(ord.wo);
  const VisibilityTable::Cell exitCell =
      table && !exitClear ? table->cellOf(ord.wo, ord.transmission ? !fromAbove : fromAbove) : VisibilityTable::Cell{};
  for (size_t slot = 0; slot < cell.facets.size(); ++slot) {
    const uint32_t t = cell.facets[slot];
    const auto& tri = g.triangles[t];
    // Degenerate (no area), back-facing to the light, or shadowed at every first-level point.
    if (lit[t] == 0) continue;
    const Vec3& m = facets.m[slot];
    const double mo = dot(m, ord.wo);
    if (ord.transmission ? mo >= 0 : mo <= 0) continue;  // back-facing to the order direction
    // g (s, p) of the facet: the integrand without its phase.
    const KirchhoffValue g0 =
        reverse ? integrandAt(media, l, Vec3{0, 0, 0}, m, wi, ord.wo, k0, fromAbove, true)
                : kirchhoffIntegrand(Vec3{0, 0, 0}, m, wi, ord.wo, k0, nI, nO,
                                     facets.fresnel[size_t(l) * cell.facets.size() + slot], ord.transmission);
    const bool tableAnswers = table && table->answers(exitCell, t, ord.transmission ? -m : m);
    const FacetVisibility vis{ctx,      table,     exitCell, tableAnswers, lit, shadow,   ord, wi, fromAbove,
                              litClear, exitClear, t,        slot,         m,   &raysHere};
    auto add = [&](const Vec3& a, const Vec3& b, const Vec3& c, int st) {
      if (st == 0 || (st == 2 && !masked)) return;
      const Complex f = triangleFourier(a, b, c, q);
      Hc[st == 1 ? 0 : 2] += g0.s * f;
      Hc[st == 1 ? 1 : 3] += g0.p * f;
    };
    // Visibility by the centroid and three points inset towards the vertices (states `st`); split
    // where they disagree, the four children's points decided together. A child at the deepest
    // level takes its centroid's state, so only that point is asked there.
    // `path`: the sub-element's index among the 4^depth of its depth.
    // (A generic lambda that takes itself: a std::function here was built for every facet and order.)
    auto element = [&](const auto& self, const Vec3& a, const Vec3& b, const Vec3& c, int depth, size_t path,
                       const int* st) -> void {
      if ((st[1] == st[0] && st[2] == st[0] && st[3] == st[0]) || depth == kExactMaxDepth) {
        add(a, b, c, st[0]);
        return;
      }
      const Vec3 ab = (a + b) * 0.5, bc = (b + c) * 0.5, ca = (c + a) * 0.5;
      const std::array<std::array<Vec3, 3>, 4> child = {{{a, ab, ca}, {ab, b, bc}, {ca, bc, c}, {ab, bc, ca}}};
      const int perChild = depth + 1 == kExactMaxDepth ? 1 : 4;
      std::array<Vec3, 16> x;
      std::array<size_t, 16> sub;
      int count = 0;
      for (size_t ch = 0; ch < 4; ++ch) {
        const auto pts = firstLevelPoints(child[ch][0], child[ch][1], child[ch][2]);
        for (int k = 0; k < perChild; ++k) {
          x[size_t(count)] = pts[size_t(k)];
          sub[size_t(count++)] = size_t(kSubOffset[depth + 1]) + (path * 4 + ch) * 4 + size_t(k);
        }
      }
      std::array<int, 16> packed, childStates;
      vis.subElements(x.data(), sub.data(), count, packed.data());
      for (size_t ch = 0; ch < 4; ++ch)
        for (int k = 0; k < 4; ++k)
          childStates[4 * ch + size_t(k)] = packed[ch * size_t(perChild) + size_t(std::min(k, perChild - 1))];
      for (size_t ch = 0; ch < 4; ++ch)
        self(self, child[ch][0], child[ch][1], child[ch][2], depth + 1, path * 4 + ch, &childStates[4 * ch]);
    };
    const auto pts = firstLevelPoints(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]]);
    // Points 1–3 only while they agree with the centroid: the first that differs decides the split.
    int st0[4] = {vis.firstLevel(pts[0], 0), 0, 0, 0};
    bool agree = true;
    for (int k = 1; k < 4; ++k) {
      st0[k] = agree ? vis.firstLevel(pts[size_t(k)], k) : st0[0];
      agree = agree && st0[k] == st0[0];
    }
    if (st0[1] == st0[0] && st0[2] == st0[0] && st0[3] == st0[0])
      add(g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]], st0[0]);  // the common case: no split
    else
      element(element, g.vertices[tri[0]], g.vertices[tri[1]], g.vertices[tri[2]], 0, 0, st0);
  }
  for (int i = 0; i < 4; ++i) H[i] += double(cell.copies()) * Hc[i];
  *rays += raysHere;
}

}  // namespace mbsdf::wave
