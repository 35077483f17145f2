#include "scattering/orders_estimator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <map>
#include <stdexcept>
#include <tuple>

#include "core/stop.h"
#include "core/quadrature.h"
#include "core/rng.h"
#include "scattering/exact_amplitude.h"
#include "scattering/heightfield_spectrum.h"
#include "scattering/lobe_shares.h"
#include "scattering/triangle_fourier.h"
#include "scattering/visibility_table.h"
#include "scattering/wave_common.h"

using mbsdf::wave::ExitVisibility;

namespace mbsdf {

namespace {
constexpr uint32_t kOrdersStream = 0x0D0E5;
constexpr int kGroups = 8;  // jackknife groups of points

struct Order {
  long a, b;   // G = 2π (a/Lx, b/Ly)
  bool below;  // a conductor's reflected order below the horizon (masked field only)
  int lambda;
  Vec3 wo;  // order direction
  bool transmission;
  double scale;  // Q_G / |Ĥ_G|² (mean of s and p), Q_G = P_G cos θ_G (lobeBins applies 1/cos θ_G)
  double sd;     // lobe standard deviation in (x, y) of ωo
};

// exact/fft over an incidence bin: one order's Q = P_G · cos θ_G (the power without its 1/cos θ_G,
// which is singular where the order grazes the horizon; lobeSecant restores it, finite, at each
// sub-direction) at every node of the incidence rule, visible and masked, and whether the order
// propagates there.
struct NodePowers {
  Order ord;
  std::vector<double> q;         // [node * 2 + msk], the high rule's n² nodes first
  std::vector<double> var;       // the Monte Carlo variance of q (orders), else empty
  std::vector<uint8_t> present;  // [node]
};

// The K-point stratified pattern of a unit normal: Φ⁻¹((i + ½)/K), K a power of two from
// kMinSubdirections / 2 (the coarse binning's) to kMaxSubdirections, each made once.
const std::vector<double>& lobeNodes(int K) {
  auto make = [](int k) {
    std::vector<double> v(static_cast<size_t>(k));
    for (int i = 0; i < k; ++i) {
      const double p = (i + 0.5) / k;
      double x = 0;  // Newton on erfc, enough for a stratified pattern
      for (int it = 0; it < 40; ++it)
        x -= (0.5 * std::erfc(-x / std::sqrt(2.0)) - p) / (std::exp(-0.5 * x * x) / std::sqrt(2 * kPi));
      v[size_t(i)] = x;
    }
    return v;
  };
  constexpr int kSmallest = kMinSubdirections / 2;
  static const std::vector<std::vector<double>> patterns = [&] {
    std::vector<std::vector<double>> p;
    for (int k = kSmallest; k <= kMaxSubdirections; k *= 2) p.push_back(make(k));
    return p;
  }();
  if (K < kSmallest || K > kMaxSubdirections || !std::has_single_bit(unsigned(K)))
    throw std::logic_error("lobeNodes: " + std::to_string(K) + " is not a power of two from " +
                           std::to_string(kSmallest) + " to " + std::to_string(kMaxSubdirections));
  return patterns[size_t(std::countr_zero(unsigned(K / kSmallest)))];
}

// Half the spacing of node i of the K-point pattern around it (units of sd): the cell a node stands for.
double lobeCellHalfWidth(int K, int i) {
  const std::vector<double>& n = lobeNodes(K);
  const double lo = i > 0 ? n[size_t(i - 1)] : 2 * n[0] - n[1],
               hi = i + 1 < K ? n[size_t(i + 1)] : 2 * n[size_t(K - 1)] - n[size_t(K - 2)];
  return 0.25 * (hi - lo);
}

// The mean of 1/cos θ over a radial cell [ρ − h, ρ + h] of direction cosines ρ = |(u_x, u_y)|, with
// the part beyond the horizon (ρ > 1: evanescent, carries nothing) counted as zero:
//   (asin(min(1, ρ + h)) − asin(max(0, ρ − h))) / 2h.
// An order's lobe is a spot in direction cosines (the window's transform), and its power per solid
// angle p(ω) is smooth there; the power in a bin is ∫ p dω = ∫ p du / cos θ(u). Evaluating 1/cos θ at
// the spot's centre diverges as an order reaches the horizon (a Rayleigh anomaly: n Λ / λ a whole
// number), while the integral stays finite (1/√(1 − ρ²) is integrable) and falls to zero as the spot
// leaves the disk. This is that integral, cell by cell; far from the horizon it is 1/cos θ.
double meanSecant(double rho, double h) {
  if (h <= 0) return rho < 1 ? 1.0 / std::sqrt(1.0 - rho * rho) : 0.0;
  const double lo = std::max(0.0, rho - h), hi = std::min(1.0, rho + h);
  if (hi <= lo) return 0.0;
  // asin at the clamped ends is known (asin(1) is π/2 to the last bit): half of a lobe's cells
  // near the horizon reach it, and asin is most of this function's cost.
  const double asinHi = hi == 1.0 ? kPi / 2 : std::asin(hi), asinLo = lo == 0.0 ? 0.0 : std::asin(lo);
  return (asinHi - asinLo) / (2 * h);
}

// The power an order sends into a bin is Q_G = P_G cos θ_G times the lobe's share of that bin times a
// 1/cos θ: the Jacobian from the spot in direction cosines to solid angle. Far from the horizon this
// is 1/cos θ_G of the lobe's centre — with it a flat interface gives exactly Fresnel's R and T (the
// normalisation of the scalar model). Near the horizon the centre value diverges, while the lobe's
// own mean of 1/cos θ over the disk (lobeMeanSecant) stays finite; the smaller of the two is used,
// which is the centre value wherever the lobe resolves it (by Jensen's inequality the mean is larger
// while the whole lobe is inside the disk) and the finite mean where the lobe reaches the horizon.
// The lobe's mean 1/cos θ over the disk per unit of the lobe inside the disk (the 16 x 16 pattern's
// points inside it; the cells of meanSecant).
double lobeMeanSecant(double cx, double cy, double sd) {
  constexpr int K = 16;
  // The pattern's nodes and each (i, j) cell's half width in units of sd, made once.
  struct Pattern {
    std::array<double, K> node;
    std::array<std::array<double, K>, K> halfWidth;
  };
  static const Pattern pattern = [] {
    Pattern p;
    const std::vector<double>& nodes = lobeNodes(K);
    for (int i = 0; i < K; ++i) p.node[size_t(i)] = nodes[size_t(i)];
    for (int i = 0; i < K; ++i)
      for (int j = 0; j < K; ++j)
        p.halfWidth[size_t(i)][size_t(j)] = std::max(lobeCellHalfWidth(K, i), lobeCellHalfWidth(K, j));
    return p;
  }();
  double sum = 0;
  int inside = 0;
  for (int i = 0; i < K; ++i) {
    const double x = cx + sd * pattern.node[size_t(i)];
    for (int j = 0; j < K; ++j) {
      const double rho = std::hypot(x, cy + sd * pattern.node[size_t(j)]);
      inside += rho < 1;
      sum += meanSecant(rho, sd * pattern.halfWidth[size_t(i)][size_t(j)]);
    }
  }
  return inside ? sum / inside : 0.0;
}
// The factor of the lobe's fractions inside the disk: 1/cos θ_G, or the finite mean near the horizon.
double lobeSecant(double cx, double cy, double sd) {
  const double rho2 = cx * cx + cy * cy, centre = rho2 < 1 ? 1.0 / std::sqrt(1.0 - rho2) : HUGE_VAL;
  if (std::sqrt(rho2) + 5 * sd < 1) return centre;  // the lobe stays clear of the horizon
  return std::min(centre, lobeMeanSecant(cx, cy, sd));
}

// The share of a Gaussian lobe (centre (cx, cy), standard deviation sd in the xy plane of the
// hemisphere `zs`) in each bin, times its 1/cos θ (lobeSecant): an order's power per bin is
// Q_G · share. Integrated over the bins (lobe_shares.h); where that does not apply (a disk grid's
// rim), a fixed 16 x 16 stratified pattern through the inverse normal CDF. Directions outside the
// unit disk are evanescent and dropped.
void lobeBins(const DirectionGrid& grid, double cx, double cy, double sd, double zs,
              std::vector<std::pair<int, double>>* out) {
  out->clear();
  const double secant = lobeSecant(cx, cy, sd);
  // Fast path: the whole lobe (±5 sd) inside one bin.
  auto binAt = [&](double x, double y) {
    double r2 = x * x + y * y;
    return r2 < 1 ? grid.binOf({x, y, zs * std::sqrt(1 - r2)}) : -1;
  };
  int c = binAt(cx, cy);
  bool inside = c >= 0;
  for (int dx = -1; dx <= 1 && inside; ++dx)
    for (int dy = -1; dy <= 1 && inside; ++dy)
      if ((dx || dy) && binAt(cx + 5 * sd * dx, cy + 5 * sd * dy) != c) inside = false;
  if (inside) {
    out->push_back({c, secant});
    return;
  }
  if (gaussianLobeShares(grid, cx, cy, sd, zs > 0, out)) {
    for (auto& [b, share] : *out) share *= secant;
    return;
  }
  // At a disk grid's rim (lobe_shares.h): the lobe sampled by the pattern.
  constexpr int K = 16;
  const std::vector<double>& nodes = lobeNodes(K);
  const double w = secant / (K * K);
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < K; ++j) {
      int b = binAt(cx + sd * nodes[size_t(i)], cy + sd * nodes[size_t(j)]);
      if (b < 0) continue;
      if (!out->empty() && out->back().first == b)
        out->back().second += w;
      else {
        bool found = false;
        for (auto& e : *out)
          if (e.first == b) {
            e.second += w;
            found = true;
            break;
          }
        if (!found) out->push_back({b, w});
      }
    }
}

// fft (header): Ĥ_G of every order from the heightfield's FFT tables, one group of orders per
// wavelength and side; then the sparse masking correction below the steepest slope.
void fourierAmplitudes(const WaveContext& ctx, const HeightfieldSpectrum& spectrum, const std::vector<Order>& orders,
                       const Vec3& wi, bool fromAbove, const wave::Media& media, bool masked, Complex* H,
                       uint64_t* rays) {
  const std::vector<uint8_t> lit = spectrum.lit(wi, fromAbove, rays);
  // Triangles of the geometry with a lit facet (the masking correction visits only those).
  std::vector<uint8_t> anyLit(spectrum.parents(), 0);
  for (size_t p = 0; p < spectrum.parents(); ++p)
    for (const uint32_t* c = spectrum.childrenBegin(p); c != spectrum.childrenEnd(p) && !anyLit[p]; ++c)
      anyLit[p] = lit[*c];
  const int nL = int(ctx.lambda_um.size());
  for (int l = 0; l < nL; ++l)
    for (int trans = 0; trans < 2; ++trans) {
      std::vector<size_t> group, below;
      for (size_t o = 0; o < orders.size(); ++o)
        if (orders[o].lambda == l && orders[o].transmission == bool(trans))
          (orders[o].below ? below : group).push_back(o);
      if (group.empty() && below.empty()) continue;
      const double k0 = 2 * kPi / ctx.lambda_um[size_t(l)];
      const double nI = media.incident(l, fromAbove), nO = trans ? media.other(l, fromAbove) : nI;
      if (trans && media.reverseTransmission(l, fromAbove)) continue;  // facet sums (OrdersWaveEstimator::run)
      const auto fields = spectrum.fields(wi, fromAbove, l, k0, nI, nO, bool(trans), media, lit);
      auto qzOf = [&](const Order& ord) { return -nI * k0 * wi.z - nO * k0 * ord.wo.z; };
      if (!group.empty()) {
        long a0 = orders[group[0]].a, a1 = a0, b0 = orders[group[0]].b, b1 = b0;
        double qMin = qzOf(orders[group[0]]), qMax = qMin;
        for (size_t o : group) {
          a0 = std::min(a0, orders[o].a), a1 = std::max(a1, orders[o].a);
          b0 = std::min(b0, orders[o].b), b1 = std::max(b1, orders[o].b);
          qMin = std::min(qMin, qzOf(orders[o])), qMax = std::max(qMax, qzOf(orders[o]));
        }
        const auto nodes = spectrum.qzNodes(qMin, qMax);
        const size_t N = nodes.q.size(), na = size_t(a1 - a0 + 1), nb = size_t(b1 - b0 + 1);
        std::vector<Complex> w(group.size() * N);
        for (size_t g = 0; g < group.size(); ++g) nodes.weights(qzOf(orders[group[g]]), &w[g * N]);
        std::vector<Complex> tab;
        for (size_t n = 0; n < N; ++n) {
          spectrum.nodeTables(fields, nodes.q[n], a0, a1, b0, b1, &tab);
          tbb::parallel_for(size_t(0), group.size(), [&](size_t g) {
            const Order& ord = orders[group[g]];
            const Vec3 k2 = ord.wo * (nO * k0);
            const size_t cell = size_t(ord.a - a0) * nb + size_t(ord.b - b0);
            for (int pol = 0; pol < 2; ++pol) {
              H[4 * group[g] + size_t(pol)] +=
                  w[g * N + n] * HeightfieldSpectrum::combine(&tab[size_t(pol) * 4 * na * nb + cell], na * nb, k2);
            }
          });
        }
      }
      // Masking: only order directions below the steepest slope can have masked or back-facing
      // facets; their terms leave the visible field (and form the masked one). Visibility is decided
      // per triangle of the geometry at its four first-level points (as `exact` does before
      // splitting) for all the facets split from it, or per facet where those points disagree.
      std::vector<size_t> grazing = below;
      for (size_t o : group) {
        const Vec3& wo = orders[o].wo;
        if (std::abs(wo.z) <= spectrum.maxSlope() * std::hypot(wo.x, wo.y)) grazing.push_back(o);
      }
      std::vector<uint64_t> grazingRays(grazing.size(), 0);
      tbb::parallel_for(size_t(0), grazing.size(), [&](size_t g) {
        const Order& ord = orders[grazing[g]];
        const Vec3 k2 = ord.wo * (nO * k0), q = wi * (-nI * k0) - k2;
        // Summed here and added once: neighbouring orders' amplitudes and counters share cache lines.
        Complex h[4] = {0, 0, 0, 0};
        uint64_t raysHere = 0;
        const Microgeometry& geo = ctx.geometry;
        for (size_t p = 0; p < spectrum.parents(); ++p) {
          if (!anyLit[p]) continue;
          const auto& tri = geo.triangles[p];
          const Vec3 n = spectrum.normal(*spectrum.childrenBegin(p));
          const Vec3 m = fromAbove ? n : -n;
          auto visibility = [&](const Vec3& x) {
            return wave::visibleExit(ctx.scene, x, m, ord.wo, unsigned(p), fromAbove, ord.transmission, &raysHere);
          };
          // The triangle's four first-level points decide for all its facets when they agree;
          // otherwise each facet by its own centroid.
          const auto pts = firstLevelPoints(geo.vertices[tri[0]], geo.vertices[tri[1]], geo.vertices[tri[2]]);
          const ExitVisibility v0 = visibility(pts[0]);
          bool agree = true;
          for (int k = 1; k < 4 && agree; ++k) agree = visibility(pts[size_t(k)]) == v0;
          if (agree && v0 == ExitVisibility::Visible) continue;
          Complex ts = 0, tp = 0, ms = 0, mp = 0;
          for (const uint32_t* c = spectrum.childrenBegin(p); c != spectrum.childrenEnd(p); ++c) {
            if (!lit[*c]) continue;
            const ExitVisibility v = agree ? v0 : visibility(spectrum.centroid(*c));
            if (v == ExitVisibility::Visible) continue;
            const auto term = spectrum.facetTerm(fields, *c, q, k2);
            ts += term[0], tp += term[1];
            if (v == ExitVisibility::Blocked) ms += term[0], mp += term[1];
          }
          if (!ord.below) h[0] -= ts, h[1] -= tp;
          if (masked) h[2] += ms, h[3] += mp;
        }
        for (int c = 0; c < 4; ++c) H[4 * grazing[g] + c] += h[c];
        grazingRays[g] = raysHere;
      });
      for (uint64_t r : grazingRays) *rays += r;
    }
}

// The propagating orders of every wavelength for incidence wi: reflected on the incident side;
// for the masked field of a conductor also the reflected orders below the horizon; for a
// dielectric the transmitted ones (when wanted). Only the orders of the cell's lattice carry power
// (lattice_cell.h): a = nx a', b = ny b'.
std::vector<Order> propagatingOrders(const WaveContext& ctx, const wave::Media& media, const LatticeCell& cell,
                                     const Vec3& wi, bool fromAbove, bool transmissionWanted, bool masked) {
  const double Lx = ctx.scene.sizeX(), Ly = ctx.scene.sizeY(), sigma = ctx.window.sigma();
  const double cosI = std::abs(wi.z);
  std::vector<Order> orders;
  for (int l = 0; l < int(ctx.lambda_um.size()); ++l) {
    const double k0 = 2 * kPi / ctx.lambda_um[l];
    for (int side = 0; side < 3; ++side) {
      const bool trans = side == 2;
      if (trans && (media.conductor() || !transmissionWanted)) continue;
      if (side == 1 && !(masked && media.conductor())) continue;
      const double nI = media.incident(l, fromAbove), nO = trans ? media.other(l, fromAbove) : nI;
      const double reach = nO * k0 + nI * k0;  // |G| can be at most this for a propagating order
      const long amax = long(std::ceil(reach * cell.sizeX / (2 * kPi))),
                 bmax = long(std::ceil(reach * cell.sizeY / (2 * kPi)));
      for (long ac = -amax; ac <= amax; ++ac)
        for (long bc = -bmax; bc <= bmax; ++bc) {
          const long a = ac * cell.nx, b = bc * cell.ny;
          double x = -(2 * kPi * a / Lx + nI * k0 * wi.x) / (nO * k0);
          double y = -(2 * kPi * b / Ly + nI * k0 * wi.y) / (nO * k0);
          double r2 = x * x + y * y;
          if (r2 >= 1) continue;  // evanescent
          double cz = std::sqrt(1 - r2);
          bool up = fromAbove != (trans || side == 1);
          Order o;
          o.a = a;
          o.b = b;
          o.below = side == 1;
          o.lambda = l;
          o.wo = {x, y, up ? cz : -cz};
          o.transmission = trans;
          o.scale = 1.0 / (4 * nI * nO * k0 * k0 * Lx * Lx * Ly * Ly * cosI) *
                    (kPi * sigma * sigma / ctx.window.w2());  // W2 of the truncated copy sum
          o.sd = 1.0 / (std::sqrt(2.0) * sigma * nO * k0);
          orders.push_back(o);
        }
    }
  }
  return orders;
}

// Monte Carlo: the group sums S_g of the Kirchhoff integrand (s, p; visible, masked) over N
// surface points for every order, indexed by groupSlot. Points in parallel blocks, each block
// accumulating into its own group: deterministic. Rays cast are added per group.
size_t groupSlot(size_t o, int pol, int g, int msk) {
  return ((o * 2 + pol) * kGroups + g) * 2 + msk;
}
void accumulateGroupSums(const WaveContext& ctx, const SurfaceSampler& sampler, const std::vector<Order>& orders,
                         int tile, int k, int N, const Vec3& wi, bool fromAbove, const wave::Media& media, bool masked,
                         std::vector<Complex>& S, std::vector<uint64_t>& blockRays) {
  const double area = sampler.totalArea();
  tbb::parallel_for(0, kGroups, [&](int g) {
    if (stopRequested()) return;
    // Each group sums into its own buffer, copied out once: the groups' slots of S interleave, and
    // threads adding into neighbouring slots share cache lines (two threads spent 10 times the CPU
    // of one here). S is zero on entry, so the sums' bits are those of adding into S directly.
    std::vector<Complex> local(orders.size() * 4, 0.0);
    uint64_t rays = 0;
    const int j0 = g * N / kGroups, j1 = (g + 1) * N / kGroups;
    for (int j = j0; j < j1; ++j) {
      Sampler ps(ctx.settings.seed, uint32_t(tile), (uint64_t(k) << 32) | uint64_t(j), kOrdersStream + 1);
      // Stratified over the surface within each group (the groups are independent replicas).
      const double u1 = (double(j - j0) + ps.get1D()) / double(j1 - j0);
      const double u3 = ps.get1D(), u2 = ps.get1D();  // in this order (the last argument's first)
      SurfaceSample sp = sampler.sample(u1, u2, u3);
      const Vec3 m = fromAbove ? sp.n : -sp.n;
      const double cosLocal = dot(m, wi);
      if (cosLocal <= 0) continue;
      ++rays;
      if (!wave::escapes(ctx.scene, sp.x, m, wi, sp.prim, fromAbove)) continue;
      for (size_t o = 0; o < orders.size(); ++o) {
        const Order& ord = orders[o];
        const ExitVisibility vis =
            wave::visibleExit(ctx.scene, sp.x, m, ord.wo, sp.prim, fromAbove, ord.transmission, &rays);
        if (vis == ExitVisibility::BackFacing || (vis == ExitVisibility::Blocked && !masked)) continue;
        const bool visible = vis == ExitVisibility::Visible;
        const int l = ord.lambda;
        const double k0 = 2 * kPi / ctx.lambda_um[l];
        KirchhoffValue kv = wave::integrandAt(media, l, sp.x, m, wi, ord.wo, k0, fromAbove, ord.transmission);
        // kirchhoffIntegrand's phase is q·x with q_xy = G exactly at the order direction: it is
        // the e^{i (G·x_xy + q_z z)} of Ĥ_G.
        const int msk = visible ? 0 : 1;
        const Complex xs = kv.s * area, xp = kv.p * area;
        local[(o * 2 + 0) * 2 + msk] += xs;
        local[(o * 2 + 1) * 2 + msk] += xp;
      }
    }
    for (size_t o = 0; o < orders.size(); ++o)
      for (int pol = 0; pol < 2; ++pol)
        for (int msk = 0; msk < 2; ++msk) S[groupSlot(o, pol, g, msk)] += local[(o * 2 + pol) * 2 + msk];
    blockRays[g] += rays;
  });
}

// An order's power, its variance and the lobe's share of each bin.
struct OrderPower {
  double P[2] = {0, 0}, var[2] = {0, 0};
  std::vector<std::pair<int, double>> share;
};

// Monte Carlo |Ĥ_G|² of order o (visible or masked) from the group sums S_g (independent
// replicas, each stratified), unbiased: (|Σ_g S_g|² − Σ_g |S_g|²) / (n_g² G (G − 1)), with a
// delete-a-group jackknife variance. False when the power is 0.
bool monteCarloPower(const std::vector<Complex>& S, size_t o, int msk, int N, double scale, double* P, double* var) {
  auto estimate = [&](int skip) {
    const double ng = double(N) / kGroups;
    const int G = skip < 0 ? kGroups : kGroups - 1;
    double total = 0;
    for (int pol = 0; pol < 2; ++pol) {
      Complex sum = 0;
      double q = 0;
      for (int g = 0; g < kGroups; ++g)
        if (g != skip) {
          sum += S[groupSlot(o, pol, g, msk)];
          q += std::norm(S[groupSlot(o, pol, g, msk)]);
        }
      total += 0.5 * (std::norm(sum) - q) / (ng * ng * G * (G - 1));
    }
    return total * scale;
  };
  const double p = estimate(-1);
  if (p == 0) return false;
  double jk[kGroups], jkMean = 0;
  for (int g = 0; g < kGroups; ++g) {
    jk[g] = estimate(g);
    jkMean += jk[g] / kGroups;
  }
  double v = 0;
  for (double x : jk) v += (x - jkMean) * (x - jkMean);
  *P = p;
  *var = v * double(kGroups - 1) / kGroups;
  return true;
}

// exact/fft: Ĥ_G (s, p; visible, masked) of every order into H; returns the rays cast. exact: every
// order by facet sums. fft: by the FFT of the facets' fields, except transmitted orders from the
// denser medium: their integrand is the reverse path's (wave::integrandAt), which depends on the
// order's direction through the facet's Fresnel factor and is no longer a field shared by all
// orders; those take the facet sums.
uint64_t deterministicAmplitudes(const WaveContext& ctx, OrderAmplitudes amplitudes,
                                 const HeightfieldSpectrum* spectrum, const LatticeCell& cell, const SlopeBound& slope,
                                 const std::function<const VisibilityTable*()>& visibilityTable,
                                 const std::vector<Order>& orders, const Vec3& wi, bool fromAbove,
                                 const wave::Media& media, bool masked, std::vector<Complex>& H) {
  const size_t nO = orders.size();
  uint64_t rays = 0;
  auto facetSum = [&](size_t o) {
    return amplitudes == OrderAmplitudes::Exact ||
           (orders[o].transmission && media.reverseTransmission(orders[o].lambda, fromAbove));
  };
  if (amplitudes == OrderAmplitudes::Fourier)
    fourierAmplitudes(ctx, *spectrum, orders, wi, fromAbove, media, masked, H.data(), &rays);
  bool anyFacetSum = false;
  for (size_t o = 0; o < nO; ++o) anyFacetSum = anyFacetSum || facetSum(o);
  if (!anyFacetSum) return rays;
  const VisibilityTable* table = visibilityTable();
  const wave::IncidenceFacets facets = wave::incidenceFacets(ctx, cell, table, slope, wi, fromAbove, media, &rays);
  std::vector<uint64_t> orderRays(nO, 0);
  wave::ShadowCache shadow(cell.facets.size());
  tbb::parallel_for(size_t(0), nO, [&](size_t o) {
    if (stopRequested() || !facetSum(o)) return;
    for (int c = 0; c < 4; ++c) H[4 * o + c] = 0;
    wave::exactAmplitude(ctx, cell, table, slope, {orders[o].lambda, orders[o].wo, orders[o].transmission}, wi,
                         fromAbove, media, masked, facets, shadow, &H[4 * o], &orderRays[o]);
  });
  for (uint64_t v : orderRays) rays += v;
  return rays;
}

// The average over the K incidence samples of the power per (λ, bin) as f (÷ Ω⊥); the error
// combines the point error and the spread over the samples (a collimated beam: K = 1).
void averageOverIncidences(const DirectionGrid& grid, int K, const std::vector<std::vector<double>>& p,
                           const std::vector<std::vector<double>>& v, std::vector<double>& f, std::vector<double>& e) {
  const int nB = grid.binCount();
  for (size_t i = 0; i < f.size(); ++i) {
    const int b = int(i % size_t(nB));
    if (grid.projectedSolidAngle(b) <= 0) continue;  // disk pixels outside the unit disk
    const double toF = 1.0 / grid.projectedSolidAngle(b);
    double mean = 0, var = 0;
    for (int k = 0; k < K; ++k) mean += p[k][i] / K;
    for (int k = 0; k < K; ++k) var += v[k][i] / (double(K) * K);
    if (K > 1) {
      double spread = 0;
      for (int k = 0; k < K; ++k) spread += (p[k][i] - mean) * (p[k][i] - mean);
      var = std::max(var, spread / (K - 1) / K);
    }
    f[i] = mean * toF;
    e[i] = std::sqrt(var) * toF;
  }
}

}  // namespace

OrdersWaveEstimator::OrdersWaveEstimator(const WaveContext& ctx, OrderAmplitudes amplitudes)
    : ctx_(ctx),
      sampler_(ctx.geometry),
      amplitudes_(amplitudes),
      cell_(latticeCellOf(ctx.geometry)),
      slope_(SlopeBound::of(ctx.geometry)) {
  if (!ctx.scene.periodic() || !ctx.window.active())
    throw std::invalid_argument("the " + name() + " estimator needs a periodic patch and a coherence window");
  if (amplitudes == OrderAmplitudes::Fourier) {
    const std::optional<HeightGrid> hg = heightGridOf(ctx.geometry);
    if (!hg)
      throw std::invalid_argument("the fft estimator needs a heightfield (a gaussian, noise or heightmap patch)");
    spectrum_ = std::make_unique<HeightfieldSpectrum>(ctx.geometry, *hg, ctx.scene,
                                                      fourierMaxTexel(ctx.material, ctx.lambda_um));
  }
}

OrdersWaveEstimator::~OrdersWaveEstimator() = default;

std::string OrdersWaveEstimator::notes() const {
  if (amplitudes_ == OrderAmplitudes::MonteCarlo) return "";
  std::string s = "deterministic (no sampling error; incidence bins by Gauss-Legendre)";
  if (cell_.copies() > 1 && amplitudes_ == OrderAmplitudes::Exact)
    s += "; the facets of one cell summed (" + std::to_string(cell_.facets.size()) + " of " +
         std::to_string(ctx_.geometry.triangles.size()) + ")";
  if (amplitudes_ == OrderAmplitudes::Exact && ctx_.settings.visibilityTable > 0)
    s += "; a shared visibility table of " + std::to_string(ctx_.settings.visibilityTable) + " x " +
         std::to_string(ctx_.settings.visibilityTable) + " directions per hemisphere (" +
         std::to_string(int(std::lround(memoryBytes() / 1e6))) + " MB)";
  if (spectrum_)
    s += "; " + std::to_string(spectrum_->nx()) + " x " + std::to_string(spectrum_->ny()) +
         " FFT of the facets (texels split " + std::to_string(spectrum_->refinement()) + " x " +
         std::to_string(spectrum_->refinement()) + ")";
  return s;
}

double OrdersWaveEstimator::memoryBytes() const {
  // The FFT's facet data, fields and per-thread transforms; the order tables are small beside them.
  // The visibility table: one bit per first-level point and direction (visibility_table.h).
  const double table =
      amplitudes_ == OrderAmplitudes::Exact && ctx_.settings.visibilityTable > 0
          ? VisibilityTable::bytesFor(cell_.facets.size(), ctx_.settings.visibilityTable, !ctx_.material.isConductor())
          : 0.0;
  // The shadow cache of the split pieces' points (one byte each, per incidence direction).
  const double shadow =
      amplitudes_ == OrderAmplitudes::Exact ? double(cell_.facets.size()) * wave::kExactSubPoints : 0.0;
  return (spectrum_ ? spectrum_->memoryBytes() : 0.0) + table + shadow;
}

const VisibilityTable* OrdersWaveEstimator::visibilityTable() const {
  if (amplitudes_ != OrderAmplitudes::Exact || ctx_.settings.visibilityTable <= 0) return nullptr;
  // Built by the first tile that needs it, once per estimator (and so per rank), whichever thread
  // gets there first; its contents do not depend on which.
  std::call_once(tableOnce_, [&] {
    table_ = std::make_unique<VisibilityTable>(ctx_.geometry, ctx_.scene, cell_, ctx_.settings.visibilityTable,
                                               !ctx_.material.isConductor());
  });
  return table_.get();
}

double OrdersWaveEstimator::setupSeconds() const {
  return table_ ? table_->buildSeconds() : 0.0;
}

std::string OrdersWaveEstimator::name() const {
  return amplitudes_ == OrderAmplitudes::Exact ? "exact" : amplitudes_ == OrderAmplitudes::Fourier ? "fft" : "orders";
}

// exact and fft over an incidence bin. Each order's power P_G(ωi) is smooth across the bin, but
// which exit bin its direction ωo(ωi) = −(G + n_i k0 ωi,xy)/(n_o k0) (+ its lobe) falls in jumps:
// a Gauss–Legendre rule over the bin converges slowly there and not monotonically (Al grating,
// Λ = 2 µm, 39.4°: rule orders 2…6 gave L1 errors of 0.17, 0.060, 0.073, 0.062, 0.047 per slice).
// So the powers computed at the n × n nodes (the costly facet sums) are interpolated (Lagrange in
// the bin's cosine-weighted (u, v) square) to M × M sub-directions ([sampling] wave_subdirections,
// 16 by default), and at each the lobe's share of every bin is integrated (lobe_shares.h): the
// jumps are smoothed by the lobe itself, so a midpoint rule over the sub-directions converges fast.
// Where the shares cannot be integrated (a disk grid's rim), the sub-direction takes one point of
// the lobe's M × M stratified pattern, paired by a fixed scrambled permutation (both marginals
// exact). Error per bin: the interpolation's, |B(P_n) − B(P_{n−1})| from the (n − 1) × (n − 1)
// companion nodes, plus the binning's, |B_M − B_{M/2}| with M/2 × M/2 sub-directions (both
// estimates of the coarser, on the safe side).
// WaveExact.IncidenceBinAverageMatchesDenseCollimatedMean: that grating at 5°, 39.4°, 65° within
// 0.002–0.007 (L1 per slice) of the mean of 24 × 24 collimated tables over the bin, reported
// 0.010–0.044. The paper's HEMISPHERES at 75 × 300 bins, θi = 30°, 8 wavelengths: M = 16 is
// 0.04–0.08 % (L1) from M = 64 and M = 32 0.01 %; sampling the lobe at one point per sub-direction
// instead, as before, left 6–8 % at M = 32 and about 1 % at M = 256 (docs/accuracy.md).
namespace {

// Lagrange interpolation weights of the nodes x at t.
std::vector<double> lagrangeWeights(const std::vector<double>& x, double t) {
  std::vector<double> w(x.size(), 1.0);
  for (size_t i = 0; i < x.size(); ++i)
    for (size_t j = 0; j < x.size(); ++j)
      if (i != j) w[i] *= (t - x[j]) / (x[i] - x[j]);
  return w;
}

// A sub-direction of the incidence bin (binOverIncidenceBin): its place (u, v) in the bin's
// cosine-weighted square, its direction, its interpolation weights and the lobe offset paired with it.
struct SubDirection {
  double u, v;
  Vec3 wi;
  std::vector<double> wh, wl;  // interpolation weights of the n² and (n − 1)² nodes
  double lx, ly;               // the paired lobe offset (units of sd)
};

// The M × M sub-directions of an incidence bin, each paired with one point of the lobe's M × M
// stratified pattern by a fixed scrambled permutation; qh, ql: the n- and (n − 1)-node rules.
std::vector<SubDirection> subDirections(const DirectionGrid& grid, int incidenceBin, const QuadratureRule& qh,
                                        const QuadratureRule& ql, int M) {
  const int n = int(qh.x.size());
  std::vector<SubDirection> v;
  const std::vector<double>& ln = lobeNodes(M);
  std::vector<int> perm(size_t(M * M));
  for (int i = 0; i < M * M; ++i) perm[size_t(i)] = i;
  Sampler shuffle(0x10BE5EEDu, 0, uint64_t(M), 0);
  for (int i = M * M - 1; i > 0; --i)
    std::swap(perm[size_t(i)], perm[size_t(std::min(i, int(shuffle.get1D() * (i + 1))))]);
  for (int i = 0; i < M; ++i)
    for (int j = 0; j < M; ++j) {
      const double u = (i + 0.5) / M, w = (j + 0.5) / M;
      SubDirection sub;
      sub.u = u, sub.v = w;
      sub.wi = grid.sampleCosine(incidenceBin, u, w).w;
      const std::vector<double> hu = lagrangeWeights(qh.x, u), hv = lagrangeWeights(qh.x, w),
                                lu = lagrangeWeights(ql.x, u), lv = lagrangeWeights(ql.x, w);
      for (int a = 0; a < n; ++a)
        for (int b = 0; b < n; ++b) sub.wh.push_back(hu[size_t(a)] * hv[size_t(b)]);
      for (int a = 0; a < n - 1; ++a)
        for (int b = 0; b < n - 1; ++b) sub.wl.push_back(lu[size_t(a)] * lv[size_t(b)]);
      const int cell = perm[size_t(i * M + j)];
      sub.lx = ln[size_t(cell / M)];
      sub.ly = ln[size_t(cell % M)];
      v.push_back(std::move(sub));
    }
  return v;
}

}  // namespace

// Adds `entry` to the list's entry of the same key, searched from the end: an order's image covers
// a few bins, so its lists stay short.
template <class Entry>
void addMerged(std::vector<Entry>& list, const Entry& entry) {
  auto hit = std::find_if(list.rbegin(), list.rend(), [&](const Entry& q) { return q.key() == entry.key(); });
  if (hit != list.rend())
    hit->value += entry.value;
  else
    list.push_back(entry);
}

// An order's contribution to one binned table (binOverIncidenceBin) at (λ, bin) `at`.
struct BinPart {
  int table, msk;
  size_t at;
  double value;
  auto key() const { return std::make_tuple(table, msk, at); }
};
// Sampled powers (orders): a node's coefficient c_m in the value of (msk, λ, bin) `at`.
struct NodeCoefficient {
  size_t node;
  int msk;
  size_t at;
  double value;
  auto key() const { return std::make_tuple(node, msk, at); }
};

// The binned tables into f and its error: acc[table * nMsk + msk], tables 0 (the n-node rule on
// M × M sub-directions), 1 (the (n − 1)-node rule), 2 (the n-node rule on M/2 × M/2) and, for
// sampled powers, 3 and 4 (the variances of 0 and 1).
static void storeBinned(const DirectionGrid& grid, int nMsk, bool sampled, const std::vector<std::vector<double>>& acc,
                        WaveTileResult* r) {
  const int nB = grid.binCount();
  for (int msk = 0; msk < nMsk; ++msk) {
    std::vector<double>& f = msk ? r->pmsk : r->fws;
    std::vector<double>& e = msk ? r->pmskErr : r->fwsErr;
    const std::vector<double>&hi = acc[size_t(msk)], &lo = acc[size_t(nMsk + msk)], &half = acc[size_t(2 * nMsk + msk)];
    for (size_t i = 0; i < f.size(); ++i) {
      const double op = grid.projectedSolidAngle(int(i % size_t(nB)));
      if (op <= 0) continue;  // disk pixels outside the unit disk
      f[i] = hi[i] / op;
      if (!sampled) {
        e[i] = (std::abs(hi[i] - lo[i]) + std::abs(hi[i] - half[i])) / op;
        continue;
      }
      // The sampling error, and the rule's: the two rules' difference less what their sampling
      // noise explains (an unbiased estimate of the squared bias), and the binning's.
      const double varHi = acc[size_t(3 * nMsk + msk)][i], varLo = acc[size_t(4 * nMsk + msk)][i];
      const double d = hi[i] - lo[i], h = hi[i] - half[i];
      e[i] = std::sqrt(varHi + std::max(0.0, d * d - varHi - varLo) + h * h) / op;
    }
  }
}

namespace {
// The binning's shared inputs (binOverIncidenceBin): the rules, their sub-directions and the media.
struct IncidenceBinning {
  const WaveContext& ctx;
  const wave::Media& media;
  bool fromAbove;
  int n;  // the n-node rule (and the (n − 1)-node one)
  QuadratureRule qh, ql;
  std::vector<SubDirection> fine, coarse;
  int nMsk;
  bool sampled;
};
}  // namespace

// One order's contributions to the binned tables (binOverIncidenceBin) into `parts`.
static void binOrder(const IncidenceBinning& in, const NodePowers& np, std::vector<BinPart>& parts) {
  using Sub = SubDirection;
  const WaveContext& ctx = in.ctx;
  const DirectionGrid& grid = ctx.grid;
  const wave::Media& media = in.media;
  const int n = in.n, nMsk = in.nMsk, nB = grid.binCount();
  const bool fromAbove = in.fromAbove, sampled = in.sampled;
  const QuadratureRule &qh = in.qh, &ql = in.ql;
  const std::vector<Sub>&fine = in.fine, &coarse = in.coarse;
  const double Lx = ctx.scene.sizeX(), Ly = ctx.scene.sizeY();
  const Order& ord = np.ord;
  const std::vector<double>& Q = np.q;
  const std::vector<uint8_t>& present = np.present;
  // Lagrange over a rule's nodes where the order propagates at all of them; else (it crosses the
  // horizon inside the bin) the nearest node where it propagates.
  auto complete = [&](size_t first, size_t count) {
    for (size_t m = first; m < first + count; ++m)
      if (!present[m]) return false;
    return true;
  };
  const bool allHi = complete(0, size_t(n * n)), allLo = complete(size_t(n * n), size_t((n - 1) * (n - 1)));
  auto nearest = [&](const Sub& sub, bool high) {
    const int r = high ? n : n - 1;
    const std::vector<double>& x = high ? qh.x : ql.x;
    const size_t first = high ? 0 : size_t(n * n);
    size_t best = SIZE_MAX;
    double d2 = 1e300;
    for (int a = 0; a < r; ++a)
      for (int b = 0; b < r; ++b) {
        const size_t m = first + size_t(a * r + b);
        const double d = std::pow(x[size_t(a)] - sub.u, 2) + std::pow(x[size_t(b)] - sub.v, 2);
        if (present[m] && d < d2) d2 = d, best = m;
      }
    return best;
  };
  const int l = ord.lambda;
  const double k0 = 2 * kPi / ctx.lambda_um[size_t(l)];
  const double nI = media.incident(l, fromAbove), nO = ord.transmission ? media.other(l, fromAbove) : nI;
  const double zs = fromAbove != (ord.transmission || ord.below) ? 1.0 : -1.0;
  // The lobe's share of each bin at one sub-direction, integrated (lobe_shares.h); at a disk
  // grid's rim, the bin of the lobe point paired with the sub-direction.
  std::vector<std::pair<int, double>> spread;
  std::vector<NodeCoefficient> coefficients;
  // One sub-direction of `set`: its exit direction and the lobe's bins once, then the power of
  // each table in `tables` (0 and 1 share the fine sub-directions).
  auto bin = [&](const Sub& sub, std::initializer_list<int> tables, const std::vector<Sub>& set) {
    const double x = -(2 * kPi * double(ord.a) / Lx + nI * k0 * sub.wi.x) / (nO * k0);
    const double y = -(2 * kPi * double(ord.b) / Ly + nI * k0 * sub.wi.y) / (nO * k0);
    if (x * x + y * y >= 1) return;                  // evanescent here
    const double secant = lobeSecant(x, y, ord.sd);  // 1/cos θ_G, finite at the horizon
    if (!gaussianLobeShares(grid, x, y, ord.sd, zs > 0, &spread)) {
      const double bx = x + ord.sd * sub.lx, by = y + ord.sd * sub.ly, r2 = bx * bx + by * by;
      if (r2 >= 1) return;
      const int b = grid.binOf({bx, by, zs * std::sqrt(1 - r2)});
      if (b < 0) return;
      spread.assign(1, {b, 1.0});
    }
    for (const int table : tables) {
      const bool high = table != 1;
      const size_t near = (high ? allHi : allLo) ? SIZE_MAX : nearest(sub, high);
      if (!(high ? allHi : allLo) && near == SIZE_MAX) continue;
      // The node weights of this sub-direction: the nearest node's alone, or the rule's Lagrange weights.
      auto forEachWeight = [&](auto&& fn) {
        if (near != SIZE_MAX) return fn(near, 1.0);
        const std::vector<double>& w = high ? sub.wh : sub.wl;
        const size_t first = high ? 0 : size_t(n * n);
        for (size_t m = 0; m < w.size(); ++m) fn(first + m, w[m]);
      };
      for (int msk = 0; msk < nMsk; ++msk) {
        double v = 0;
        forEachWeight([&](size_t m, double w) { v += w * Q[m * 2 + size_t(msk)]; });
        // A sampled power may be negative (the pairwise estimate is unbiased, not positive):
        // dropping those would bias every weak order's bins upwards.
        if (sampled ? v == 0 : v <= 0) continue;
        const double perSub = v * secant / double(set.size());
        if (sampled && table != 2)
          for (const auto& [b, share] : spread) {
            const size_t at = size_t(l) * nB + size_t(b);
            const double c = secant / double(set.size()) * share;
            forEachWeight([&](size_t m, double w) { addMerged(coefficients, {m, msk, at, w * c}); });
          }
        for (const auto& [b, share] : spread) {
          addMerged(parts, {table, msk, size_t(l) * nB + size_t(b), perSub * share});
        }
      }
    }
  };
  for (const Sub& sub : fine) bin(sub, {0, 1}, fine);
  for (const Sub& sub : coarse) bin(sub, {2}, coarse);
  for (const NodeCoefficient& q : coefficients)
    parts.push_back(
        {q.node < size_t(n * n) ? 3 : 4, q.msk, q.at, q.value * q.value * np.var[q.node * 2 + size_t(q.msk)]});
}

static void binOverIncidenceBin(const WaveContext& ctx, const DirectionGrid& grid, int incidenceBin, bool fromAbove,
                                const wave::Media& media, const std::vector<NodePowers>& nodePower, bool masked,
                                WaveTileResult* r) {
  const int n = incidenceRuleOrder(incidenceDirectionsOf(ctx.settings, grid, incidenceBin));
  const QuadratureRule qh = gaussLegendre(n, 0.0, 1.0), ql = gaussLegendre(n - 1, 0.0, 1.0);
  const int M = ctx.settings.subdirections, nMsk = masked ? 2 : 1;
  // Monte Carlo node powers (orders): each bin's value is linear in them, Σ_m c_m q_m, so its
  // variance is Σ_m c_m² var_m, per order (tables 3 and 4: of tables 0 and 1).
  const bool sampled = !nodePower.empty() && !nodePower[0].var.empty();
  const IncidenceBinning binning{ctx,
                                 media,
                                 fromAbove,
                                 n,
                                 qh,
                                 ql,
                                 subDirections(grid, incidenceBin, qh, ql, M),
                                 subDirections(grid, incidenceBin, qh, ql, M / 2),
                                 nMsk,
                                 sampled};
  // Per order: (table, msk, λ·nB + bin, value) contributions, accumulated below in order.
  std::vector<std::vector<BinPart>> parts(nodePower.size());
  // Orders whose power stays below 1e-13 of the strongest order's at every node are left out (a flat
  // patch's orders G != 0 carry rounding noise of 1e-30: binning each of them over M x M
  // sub-directions was the whole cost of a flat mirror's tile); they change no bin by more than
  // 1e-13 of its value.
  double strongest = 0;
  for (const NodePowers& np : nodePower)
    for (double q : np.q) strongest = std::max(strongest, q);
  tbb::parallel_for(size_t(0), nodePower.size(), [&](size_t o) {
    const std::vector<double>& Q = nodePower[o].q;
    // (A sampled power below zero is as much a part of the estimate as one above.)
    if (std::all_of(Q.begin(), Q.end(), [&](double v) { return (sampled ? std::abs(v) : v) <= 1e-13 * strongest; }))
      return;  // negligible everywhere
    binOrder(binning, nodePower[o], parts[o]);
  });
  // table 0: the n-node interpolation on M × M sub-directions; 1: the (n − 1)-node one; 2: the
  // n-node one on M/2 × M/2.
  // 3, 4 (sampled powers): the variances of 0 and 1.
  const int tables = sampled ? 5 : 3;
  std::vector<std::vector<double>> acc(size_t(tables * nMsk), std::vector<double>(r->fws.size(), 0.0));
  for (const auto& list : parts)
    for (const BinPart& p : list) acc[size_t(p.table * nMsk + p.msk)][p.at] += p.value;
  storeBinned(grid, nMsk, sampled, acc, r);
}

// One incidence sample's |Ĥ_G|² per order, its lobe shared among the bins: power and variance per
// (λ, bin), visible (pv, vv) and masked (pm, vm).
static void shareOrderLobes(const std::vector<Order>& orders, const std::vector<OrderPower>& op, bool masked, int nL,
                            int nB, std::vector<double>& pv, std::vector<double>& vv, std::vector<double>& pm,
                            std::vector<double>& vm) {
  pv.assign(size_t(nL) * nB, 0.0), vv.assign(size_t(nL) * nB, 0.0);
  if (masked) pm.assign(size_t(nL) * nB, 0.0), vm.assign(size_t(nL) * nB, 0.0);
  for (size_t o = 0; o < orders.size(); ++o)
    for (int msk = 0; msk < (masked ? 2 : 1); ++msk) {
      if (op[o].P[msk] == 0) continue;
      auto& pt = msk ? pm : pv;
      auto& vt = msk ? vm : vv;
      for (auto [bin, frac] : op[o].share) {
        pt[size_t(orders[o].lambda) * nB + bin] += op[o].P[msk] * frac;
        vt[size_t(orders[o].lambda) * nB + bin] += op[o].var[msk] * frac * frac;
      }
    }
}

WaveTileResult OrdersWaveEstimator::run(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                                        const std::vector<uint8_t>& exitMask) const {
  const int tile = request.tile, incidenceBin = request.incidenceBin;
  const std::optional<Vec3>& exactDirection = request.exactDirection;
  // The cost is per incidence sample and order, not per exit bin: every bin is computed and
  // `computed` stays empty (the mask is a permission to skip, not an obligation), except that the
  // transmitted orders are left out when the mask excludes the whole other hemisphere.
  auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = ctx_.grid;
  const int nL = int(ctx_.lambda_um.size()), nB = grid.binCount();
  const int N = std::max(2 * kGroups, ctx_.settings.samplesPerBin);
  // Incidence directions: one collimated beam, or the nodes of the Gauss–Legendre rules over the
  // incidence bin (wave::incidenceRule).
  const bool deterministic = amplitudes_ != OrderAmplitudes::MonteCarlo;
  const int directions = incidenceDirectionsOf(ctx_.settings, grid, incidenceBin);
  // Over an incidence bin every estimator takes the rule's nodes and bins their order powers through
  // the bin's sub-directions (binOverIncidenceBin): an exit bin that only a strip of the incidence
  // bin reaches gets its share of every order; K random directions, each lobe at its own, leave it
  // at 0 ± 0 in most runs (mean z² 447 on flat glass lit from inside, 3.1e3 on a dome lattice).
  const std::vector<wave::IncidenceNode> rule = wave::incidenceRule(grid, incidenceBin, exactDirection, directions);
  const bool quadrature = !exactDirection;
  const int K = int(rule.size());
  const bool masked = ctx_.settings.computeMasked;
  const bool fromAbove = exactDirection ? exactDirection->z >= 0 : grid.isUpper(incidenceBin);
  const bool transmissionWanted = wave::otherSideWanted(grid, fromAbove, exitMask);
  const wave::Media media(ctx_);

  WaveTileResult r(nL, nB, masked);
  // Per incidence sample k: power per (λ, bin) and its variance; averaged over k at the end.
  std::vector<std::vector<double>> pv(K), pm(K), vv(K), vm(K);
  std::atomic<uint64_t> rays{0};
  uint64_t pointOrderPairs = 0;

  // Over an incidence bin: every order's power at every node (P at node k, visible and masked, and
  // its variance where sampled), keyed by (λ, side, a, b); binned after the loop.
  std::map<std::tuple<int, int, long, long>, size_t> slotOf;
  std::vector<NodePowers> nodePower;
  for (int k = 0; k < K; ++k) {
    const Vec3 wi = rule[size_t(k)].wi;
    const std::vector<Order> orders = propagatingOrders(ctx_, media, cell_, wi, fromAbove, transmissionWanted, masked);
    const size_t nO = orders.size();
    pointOrderPairs += uint64_t(amplitudes_ == OrderAmplitudes::Exact ? cell_.facets.size()
                                : deterministic                       ? ctx_.geometry.triangles.size()
                                                                      : size_t(N)) *
                       nO;
    // Monte Carlo: accumulators per order, polarisation, group and visible/masked (groupSlot).
    // exact/fft: Ĥ_G (s, p; visible, masked) per order.
    std::vector<Complex> S(deterministic ? 0 : nO * 2 * kGroups * 2, 0.0);
    std::vector<Complex> H(deterministic ? nO * 4 : 0, 0.0);
    std::vector<uint64_t> blockRays(kGroups, 0);
    if (deterministic)
      rays += deterministicAmplitudes(
          ctx_, amplitudes_, spectrum_.get(), cell_, slope_, [this] { return visibilityTable(); }, orders, wi,
          fromAbove, media, masked, H);
    else
      accumulateGroupSums(ctx_, sampler_, orders, tile, k, N, wi, fromAbove, media, masked, S, blockRays);
    for (uint64_t b : blockRays) rays += b;
    // Per order (in parallel): power, jackknife variance and the lobe's share of each bin; then
    // accumulated into the bins in order (deterministic).
    std::vector<OrderPower> op(nO);
    throwIfStopped();
    tbb::parallel_for(size_t(0), nO, [&](size_t o) {
      const Order& ord = orders[o];
      bool any = false;
      for (int msk = 0; msk < (masked ? 2 : 1); ++msk) {
        if (deterministic) {
          const double P = 0.5 * (std::norm(H[4 * o + 2 * msk]) + std::norm(H[4 * o + 2 * msk + 1])) * ord.scale;
          if (P == 0) continue;
          op[o].P[msk] = P;
          any = true;
        } else {
          any = monteCarloPower(S, o, msk, N, ord.scale, &op[o].P[msk], &op[o].var[msk]) || any;
        }
      }
      if (any && !quadrature) lobeBins(grid, ord.wo.x, ord.wo.y, ord.sd, ord.wo.z >= 0 ? 1.0 : -1.0, &op[o].share);
    });
    if (quadrature) {
      // The node's order powers, binned after the loop over sub-directions (binOverIncidenceBin).
      for (size_t o = 0; o < nO; ++o) {
        const Order& ord = orders[o];
        const auto key = std::make_tuple(ord.lambda, int(ord.transmission) + 2 * int(ord.below), ord.a, ord.b);
        auto [it, fresh] = slotOf.emplace(key, nodePower.size());
        if (fresh)
          nodePower.push_back({ord, std::vector<double>(size_t(K) * 2, 0.0),
                               std::vector<double>(deterministic ? 0 : size_t(K) * 2, 0.0),
                               std::vector<uint8_t>(size_t(K), 0)});
        NodePowers& np = nodePower[it->second];
        np.q[size_t(k) * 2] = op[o].P[0];
        np.q[size_t(k) * 2 + 1] = op[o].P[1];
        if (!deterministic) np.var[size_t(k) * 2] = op[o].var[0], np.var[size_t(k) * 2 + 1] = op[o].var[1];
        np.present[size_t(k)] = 1;
      }
    } else {
      shareOrderLobes(orders, op, masked, nL, nB, pv[k], vv[k], pm[k], vm[k]);
    }
    if (progress) progress(uint64_t(k + 1) * uint64_t(N));
  }
  if (quadrature) {
    const auto tb = std::chrono::steady_clock::now();
    binOverIncidenceBin(ctx_, grid, incidenceBin, fromAbove, media, nodePower, masked, &r);
    r.binningSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - tb).count();
  } else {
    averageOverIncidences(grid, K, pv, vv, r.fws, r.fwsErr);
    if (masked) averageOverIncidences(grid, K, pm, vm, r.pmsk, r.pmskErr);
  }
  // Kirchhoff samples per wavelength: surface point x exit direction (an order).
  r.samples = pointOrderPairs / uint64_t(std::max(1, nL));
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace mbsdf
