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
#include "scattering/incidence_binning.h"
#include "scattering/lobe_shares.h"
#include "scattering/triangle_fourier.h"
#include "scattering/visibility_table.h"
#include "scattering/wave_common.h"

using mbsdf::wave::ExitVisibility;

namespace mbsdf {

namespace {
constexpr uint32_t kOrdersStream = 0x0D0E5;
constexpr int kGroups = 8;  // jackknife groups of points

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
