#include "scattering/incidence_binning.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <tuple>

#include "core/quadrature.h"
#include "core/rng.h"
#include "scattering/lobe_shares.h"

namespace mbsdf {

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
namespace {

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
}  // namespace

double lobeSecant(double cx, double cy, double sd) {
  const double rho2 = cx * cx + cy * cy, centre = rho2 < 1 ? 1.0 / std::sqrt(1.0 - rho2) : HUGE_VAL;
  if (std::sqrt(rho2) + 5 * sd < 1) return centre;  // the lobe stays clear of the horizon
  return std::min(centre, lobeMeanSecant(cx, cy, sd));
}

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

void binOverIncidenceBin(const WaveContext& ctx, const DirectionGrid& grid, int incidenceBin, bool fromAbove,
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

}  // namespace mbsdf
