#include "scattering/area_estimator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <tuple>

#include "core/rng.h"
#include "core/stop.h"
#include "scattering/lobe_shares.h"
#include "scattering/wave_common.h"

using mbsdf::wave::ExitVisibility;

namespace mbsdf {

namespace {
constexpr uint32_t kWaveStream = 0x57A7E;  // keeps the wave samples apart from the path tracer's
constexpr double kUniformFraction = 0.2;   // share of a bin's directions drawn without the lobes
constexpr size_t kMaxLobes = 4096;
constexpr double kMinLobeShare = 1e-4;      // a lobe with less of itself in a bin is not drawn there
constexpr uint32_t kPilotStream = 0x57A7F;  // the order-power pilot's points
constexpr int kPilotPoints = 8;             // points per order in that pilot
constexpr double kWeightFloor = 1e-3;       // an order's weight, at least, against the largest

// A grating order's weight, by its indices (a, b).
using OrderPrior = std::function<double(long, long)>;

// What the coherence window makes of the patch: one copy (no window, or a patch that does not
// repeat) scatters into the mean plane's aperture lobe; a repeating patch under a window much wider
// than it into separate grating-order lobes; under a narrower window the orders overlap into speckle.
enum class LobeRegime { Aperture, Orders, Speckle };
LobeRegime lobeRegime(const WaveContext& ctx) {
  if (!ctx.window.active() || !ctx.scene.periodic()) return LobeRegime::Aperture;
  return orderLobesSeparate(ctx.window.sigma(), ctx.scene.sizeX(), ctx.scene.sizeY()) ? LobeRegime::Orders
                                                                                      : LobeRegime::Speckle;
}

// The direction cosines (x, y) of grating order G = 2π(a/Lx, b/Ly) scattered from direction w in a
// medium of index nFrom into one of index nTo: nTo k0 ω_xy = −(G + nFrom k0 w_xy).
std::pair<double, double> orderDirectionXY(long a, long b, double Lx, double Ly, double nFrom, double nTo, double k0,
                                           const Vec3& w) {
  return {-(2 * kPi * a / Lx + nFrom * k0 * w.x) / (nTo * k0), -(2 * kPi * b / Ly + nFrom * k0 * w.y) / (nTo * k0)};
}
// How a pair's incidence direction is drawn over the incidence bin (BinDirectionSampler::sampleMixture).
enum class IncidenceDraw { Cosine, Lobes };

// Directions inside one bin. A periodic patch under a coherence window much wider than the
// patch scatters into narrow lobes around the grating orders G = 2π(a/Lx, b/Ly): by Poisson
// summation of the copy sum, |C(x, q)|² ≈ Σ_G c_G exp(−σ²|q_xy − G|²), i.e. Gaussian lobes of
// standard deviation 1/(√2 σ n_o k0) in (x, y) of ωo around ωo_xy = −(G + n_i k0 ωi_xy)/(n_o k0),
// for every wavelength. Uniform sampling of a bin would rarely hit them, so ωo is drawn from a
// mixture of the uniform density and these lobes; the estimate divides by the mixture density,
// which keeps it unbiased whatever the lobes really look like. The condition is symmetric in ωi and
// ωo: in an incidence bin, the lobes found from an exit direction hold the incidence directions
// whose orders reach it (averagedPair, with bin-averaged incidence).
class BinDirectionSampler {
 public:
  // A Gaussian spot in the plane of direction cosines, its share of this bin (0: unknown, the spot
  // is then drawn whole and a draw outside the bin counts 0), and the weight of its grating order
  // when a lobe is chosen (GratingOrderWeights).
  struct Lobe {
    double cx, cy, sd;
    double inBin = 0;
    double prior = 1;
  };
  BinDirectionSampler(const DirectionGrid& grid, int bin) : grid_(grid), bin_(bin) {}

  void findLobes(const WaveContext& ctx, const wave::Media& media, const Vec3& wi, bool fromAbove) {
    const bool transmission = !media.conductor() && grid_.isUpper(bin_) != fromAbove;
    std::vector<double> nFrom, nTo;
    for (size_t l = 0; l < ctx.lambda_um.size(); ++l) {
      nFrom.push_back(media.incident(int(l), fromAbove));
      nTo.push_back(transmission ? media.other(int(l), fromAbove) : nFrom.back());
    }
    findLobesFrom(ctx, wi, nFrom, nTo);
  }
  // The lobes in this bin of light scattered from direction w (in a medium of index nFrom[l]) into
  // this bin's medium (nTo[l]): n_to k0 ω_xy = −(G + n_from k0 w_xy). The condition is symmetric in
  // the two directions, so the same lobes give the incidence directions whose orders reach an exit
  // direction w (nFrom the exit side's index, nTo the incident side's).
  void findLobesFrom(const WaveContext& ctx, const Vec3& w, const std::vector<double>& nFrom,
                     const std::vector<double>& nTo, const OrderPrior& prior = {}) {
    lobes_.clear();
    const CoherenceWindow& win = ctx.window;
    if (lobeRegime(ctx) == LobeRegime::Aperture) {
      findApertureLobes(ctx, w, nFrom, nTo);
      return;
    }
    const double Lx = ctx.scene.sizeX(), Ly = ctx.scene.sizeY();
    double x0, x1, y0, y1;
    grid_.xyBounds(bin_, &x0, &x1, &y0, &y1);
    const double zs = grid_.isUpper(bin_) ? 1.0 : -1.0;
    for (size_t l = 0; l < ctx.lambda_um.size(); ++l) {
      const double k0 = 2 * kPi / ctx.lambda_um[l];
      const double nI = nFrom[l], nO = nTo[l];
      const double sd = 1.0 / (std::sqrt(2.0) * win.sigma() * nO * k0);
      const double m = 4 * sd;
      // ω_xy = −(G + nI k0 w_xy)/(nO k0) inside the widened box <=> G in this range:
      const double gx0 = -nO * k0 * (x1 + m) - nI * k0 * w.x, gx1 = -nO * k0 * (x0 - m) - nI * k0 * w.x;
      const double gy0 = -nO * k0 * (y1 + m) - nI * k0 * w.y, gy1 = -nO * k0 * (y0 - m) - nI * k0 * w.y;
      const long a0 = long(std::ceil(gx0 * Lx / (2 * kPi))), a1 = long(std::floor(gx1 * Lx / (2 * kPi)));
      const long b0 = long(std::ceil(gy0 * Ly / (2 * kPi))), b1 = long(std::floor(gy1 * Ly / (2 * kPi)));
      if ((a1 - a0 + 1) * (b1 - b0 + 1) > long(kMaxLobes)) {
        lobes_.clear();
        return;
      }
      for (long a = a0; a <= a1; ++a)
        for (long b = b0; b <= b1; ++b) {
          const auto [cx, cy] = orderDirectionXY(a, b, Lx, Ly, nI, nO, k0, w);
          addIfReaching({cx, cy, sd, 0.0, prior ? prior(a, b) : 1.0}, zs);
          if (lobes_.size() > kMaxLobes) {
            lobes_.clear();
            return;
          }
        }
    }
  }

  // One copy of the patch (no window, or a patch that does not repeat): no grating orders, but the
  // mean plane's specular lobe, the Fourier transform of the lit aperture. |∫_{−L/2}^{L/2} e^{iqx}|²
  // = (2 sin(qL/2)/q)² ≈ L²(1 − q²L²/12): a Gaussian of the same curvature has σ_q = √6/L; under
  // a window narrower than the patch, σ_q = 1/(√2 σ). The wider of the two, on the shorter side.
  void findApertureLobes(const WaveContext& ctx, const Vec3& w, const std::vector<double>& nFrom,
                         const std::vector<double>& nTo) {
    const double L = std::min(ctx.scene.sizeX(), ctx.scene.sizeY());
    const double sigmaQ =
        std::max(std::sqrt(6.0) / L, ctx.window.active() ? 1 / (std::sqrt(2.0) * ctx.window.sigma()) : 0.0);
    const double zs = grid_.isUpper(bin_) ? 1.0 : -1.0;
    for (size_t l = 0; l < ctx.lambda_um.size(); ++l) {
      const double k0 = 2 * kPi / ctx.lambda_um[l];
      addIfReaching({-nFrom[l] * w.x / nTo[l], -nFrom[l] * w.y / nTo[l], sigmaQ / (nTo[l] * k0)}, zs);
    }
  }
  // Keeps a lobe that reaches into this bin (probes at its centre and ±3 sd). It is drawn within the
  // bin, and carries its share of the bin where the grid gives it in closed form (gaussianLobeShares):
  // every draw lands in the bin, and the density is divided by that share. A lobe drawn whole puts
  // most draws outside a bin it only grazes: a technique whose draws all fell outside reported
  // 0 ± 0 for a bin that held a lobe's tail.
  void addIfReaching(Lobe L, double zs) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy) {
        const double px = L.cx + 3 * L.sd * dx, py = L.cy + 3 * L.sd * dy, r2 = px * px + py * py;
        if (r2 < 1 && grid_.binOf({px, py, zs * std::sqrt(1 - r2)}) == bin_) {
          std::vector<std::pair<int, double>> shares;
          if (gaussianLobeShares(grid_, L.cx, L.cy, L.sd, zs > 0, &shares)) {
            for (const auto& [b, share] : shares)
              if (b == bin_) L.inBin += share;
            if (L.inBin < kMinLobeShare) return;  // the uniform directions see so small a tail
          }
          lobes_.push_back(L);
          return;
        }
      }
  }

  // Techniques are allocated deterministically over the M directions of a bin (multi-sample MIS,
  // balance heuristic; Veach 1997 §9.2): the first nUniform draw uniformly in the bin, the others go
  // round-robin over the lobes. Requires one incidence direction for the whole bin.
  static int uniformCount(int M) { return std::max(2, int(std::lround(kUniformFraction * M))); }
  void allocate(int M) {
    M_ = M;
    nUniform_ = lobes_.empty() ? M : uniformCount(M);
    counts_.assign(lobes_.size(), 0);
    for (int k = nUniform_; k < M; ++k) counts_[size_t(k - nUniform_) % lobes_.size()]++;
  }
  int technique(int k) const { return k < nUniform_ ? -1 : int(size_t(k - nUniform_) % lobes_.size()); }
  // Draws ωo with technique t (−1: uniform) from (u1, u2) and, for a lobe restricted to the bin,
  // as many further pairs from `next` as it takes; false if the draw fell outside the bin
  // (estimate 0).
  template <class Next>
  bool sample(int t, double u1, double u2, Next next, Vec3* wo) const {
    if (t < 0) {
      *wo = grid_.sampleUniform(bin_, u1, u2).w;
      return true;
    }
    const Lobe& L = lobes_[size_t(t)];
    // Restricted to the bin: drawn until a draw lands in it (on average 1 / inBin draws; more
    // than 50 / inBin fail with probability e^−50).
    const int tries = L.inBin > 0 ? int(std::ceil(50 / L.inBin)) : 1;
    for (int i = 0; i < tries; ++i) {
      if (i > 0) u1 = next(), u2 = next();
      double r = L.sd * std::sqrt(-2 * std::log(std::max(u1, 1e-300))), a = 2 * kPi * u2;
      double x = L.cx + r * std::cos(a), y = L.cy + r * std::sin(a), r2 = x * x + y * y;
      if (r2 >= 1) continue;
      *wo = Vec3{x, y, (grid_.isUpper(bin_) ? 1.0 : -1.0) * std::sqrt(1 - r2)};
      if (grid_.binOf(*wo) == bin_) return true;
    }
    return false;
  }
  // The effective density of a direction drawn with technique t (−1: uniform) under the power
  // heuristic (β = 2; Veach 1997 §9.2.4): f / density averaged over the M directions is
  //   Σ_t (1/n_t) Σ_{j∈t} w_t f / pdf_t,  w_t = (n_t pdf_t)² / Σ_s (n_s pdf_s)²,
  // so density = Σ_s (n_s pdf_s)² / (M n_t pdf_t). Against the balance heuristic it leaves the
  // uniform directions almost nothing of a narrow lobe's core, which they would hit rarely and then
  // with a large value (a skewed estimate whose spread the error misses).
  double density(int t, const Vec3& wo) const {
    const double uniform = double(nUniform_) / grid_.solidAngle(bin_);
    double sum2 = uniform * uniform, own = t < 0 ? uniform : 0;
    for (size_t c = 0; c < lobes_.size(); ++c) {
      if (!counts_[c]) continue;
      const Lobe& L = lobes_[c];
      double dx = wo.x - L.cx, dy = wo.y - L.cy;
      const double nc = counts_[c] * std::exp(-(dx * dx + dy * dy) / (2 * L.sd * L.sd)) /
                        (2 * kPi * L.sd * L.sd * (L.inBin > 0 ? L.inBin : 1.0)) * std::abs(wo.z);
      sum2 += nc * nc;
      if (int(c) == t) own = nc;
    }
    return own > 0 ? sum2 / (M_ * own) : std::numeric_limits<double>::infinity();
  }
  // Over this bin as an incidence bin, for one exit direction: ω drawn cosine-weighted in the bin
  // (also for `Lobes` where no lobe reaches it) or from one lobe restricted to the bin, chosen with
  // probability proportional to its share of the bin times its order's prior. False: a lobe's
  // draws missed the bin.
  bool sampleMixture(IncidenceDraw draw, Sampler& s, Vec3* w) const {
    if (draw == IncidenceDraw::Cosine || lobes_.empty()) {
      *w = grid_.sampleCosine(bin_, s).w;
      return true;
    }
    double pick = s.get1D() * lobeShares();
    size_t t = 0;
    while (t + 1 < lobes_.size() && (pick -= weight(lobes_[t])) > 0) ++t;
    const double u1 = s.get1D(), u2 = s.get1D();
    return sample(
        int(t), u1, u2, [&] { return s.get1D(); }, w);
  }
  // The density in the plane of direction cosines at w (in the bin; cos θ dω = dx dy) of the two
  // draws mixed in proportions cosineShare : 1 − cosineShare: a lobe restricted to the bin has
  // density N(w; lobe) / share there, and is chosen with probability share × prior / Σ share × prior.
  double mixtureDensity(const Vec3& w, double cosineShare) const {
    const double alpha = lobes_.empty() ? 1.0 : cosineShare, shares = lobeShares();
    double density = alpha / grid_.projectedSolidAngle(bin_);
    for (const Lobe& L : lobes_) {
      const double dx = w.x - L.cx, dy = w.y - L.cy;
      density +=
          (1 - alpha) * L.prior / shares * std::exp(-(dx * dx + dy * dy) / (2 * L.sd * L.sd)) / (2 * kPi * L.sd * L.sd);
    }
    return density;
  }
  void clearLobes() { lobes_.clear(); }
  int techniques() const { return int(lobes_.size()) + 1; }
  size_t lobeCount() const { return lobes_.size(); }

 private:
  static double weight(const Lobe& L) { return (L.inBin > 0 ? L.inBin : 1.0) * L.prior; }
  double lobeShares() const {
    double shares = 0;
    for (const Lobe& L : lobes_) shares += weight(L);
    return shares;
  }
  const DirectionGrid& grid_;
  int bin_;
  std::vector<Lobe> lobes_;
  std::vector<int> counts_;
  int M_ = 1, nUniform_ = 1;
};

// A pair of directions for exit bin `bin` under bin-averaged incidence. Drawing ωi first and ωo from
// its lobes leaves most ωi with no lobe in a given exit bin, and the few that have one carry the bin
// (a heavy-tailed estimate whose spread hid its error). The lobes' condition is symmetric, so ωo
// is drawn first, cosine-weighted in the exit bin (the bin-averaged BSDF is a cosine-weighted
// average, and p / cos θo is bounded), and ωi from the incidence bin's mixture around the incidence
// directions whose orders reach that ωo (sampleMixture): every lobe that reaches the exit bin is
// found. pdf: the pair's density relative to the bin integral's measure dωo × cos θi dωi /
// Ω⊥(incidence bin).
struct DirectionPair {
  Vec3 wi, wo;
  bool transmission;
  double pdf;
};
struct PairDraw {
  IncidenceDraw draw;
  double cosineShare;  // of the bin's pairs drawn with IncidenceDraw::Cosine
};
// What the pairs of one exit bin share: its hemisphere fixes reflection or transmission, the
// indices on both sides and the weights of the orders that reach it. Where the orders' lobes
// overlap into speckle the integrand is smooth in ωi: cosine-weighted directions alone (the lobes'
// shares cost more than they save there).
struct ExitBinPairs {
  int incidenceBin, bin;
  bool transmission;
  std::vector<double> nExit, nIncident;
  OrderPrior prior;
  bool drawLobes;
};
ExitBinPairs exitBinPairs(const WaveContext& ctx, const wave::Media& media, int incidenceBin, int bin, bool fromAbove,
                          const GratingOrderWeights& weights) {
  const bool upper = ctx.grid.isUpper(bin);
  ExitBinPairs e;
  e.incidenceBin = incidenceBin, e.bin = bin;
  e.transmission = wave::isTransmission(media.conductor(), fromAbove, Vec3{0, 0, upper ? 1.0 : -1.0});
  e.drawLobes = lobeRegime(ctx) != LobeRegime::Speckle;
  for (size_t l = 0; l < ctx.lambda_um.size(); ++l) {
    e.nIncident.push_back(media.incident(int(l), fromAbove));
    e.nExit.push_back(e.transmission ? media.other(int(l), fromAbove) : e.nIncident.back());
  }
  const int hemisphere = upper ? 0 : 1;
  e.prior = [&weights, hemisphere](long a, long b) { return weights.of(hemisphere, a, b); };
  return e;
}
std::optional<DirectionPair> averagedPair(const WaveContext& ctx, const ExitBinPairs& e, PairDraw how,
                                          BinDirectionSampler& incidence, Sampler& s) {
  const DirectionGrid& grid = ctx.grid;
  DirectionPair d;
  d.wo = grid.sampleCosine(e.bin, s).w;
  d.transmission = e.transmission;
  if (e.drawLobes)
    incidence.findLobesFrom(ctx, d.wo, e.nExit, e.nIncident, e.prior);
  else
    incidence.clearLobes();
  if (!incidence.sampleMixture(how.draw, s, &d.wi)) return std::nullopt;
  // cos θo / Ω⊥(bin) × the mixture's density in dx_i dy_i (cos θi dωi = dx_i dy_i), × Ω⊥(incidence):
  // the balance heuristic over the two draws in their fixed proportions (Veach 1997 §9.2).
  d.pdf = std::abs(d.wo.z) / grid.projectedSolidAngle(e.bin) * incidence.mixtureDensity(d.wi, how.cosineShare) *
          grid.projectedSolidAngle(e.incidenceBin);
  return d;
}

}  // namespace

// The unbiased pairwise power (|Σ Y|² − Σ |Y|²) / (N (N − 1)) of wavelength l's Y_j (s and p,
// averaged: unpolarised light), × scale, and its jackknife variance over the N points (Efron and
// Stein 1981: (N − 1)/N Σ_i (U_(i) − Ū)², U_(i) the same power without point i). The jackknife
// holds the variance of a signal's power; where E[Y] ≈ 0 (a bin of noise) it is about twice the
// variance (the degenerate part of a U-statistic is counted 2 (N − 1)/(N − 2) times): conservative.
static std::pair<double, double> pairwisePower(const std::vector<Complex>& y, int N, int nL, int l, double scale) {
  Complex S[2] = {0, 0};
  double Q[2] = {0, 0};
  for (int j = 0; j < N; ++j)
    for (int c = 0; c < 2; ++c) {
      const Complex v = y[(size_t(j) * nL + size_t(l)) * 2 + size_t(c)];
      S[c] += v;
      Q[c] += std::norm(v);
    }
  auto power = [&](const Complex* s, const double* q, double n) {
    return 0.5 * ((std::norm(s[0]) - q[0]) + (std::norm(s[1]) - q[1])) / (n * (n - 1)) * scale;
  };
  const double P = power(S, Q, N);
  if (N < 3) return {P, 0.0};
  std::vector<double> loo(static_cast<size_t>(N));
  double mean = 0;
  for (int j = 0; j < N; ++j) {
    Complex s[2];
    double q[2];
    for (int c = 0; c < 2; ++c) {
      const Complex v = y[(size_t(j) * nL + size_t(l)) * 2 + size_t(c)];
      s[c] = S[c] - v;
      q[c] = Q[c] - std::norm(v);
    }
    loo[size_t(j)] = power(s, q, N - 1);
    mean += loo[size_t(j)] / N;
  }
  double var = 0;
  for (double u : loo) var += (u - mean) * (u - mean);
  return {P, var * (N - 1) / N};
}

AreaWaveEstimator::AreaWaveEstimator(const WaveContext& ctx)
    : ctx_(ctx),
      sampler_(ctx.geometry),
      control_(ctx.settings.controlVariate == WaveControlVariate::MeanPlane ? MeanPlaneControl(ctx.geometry)
                                                                            : MeanPlaneControl()) {}

// Bin b's integral mean_k p_k / pdf_k over the M directions of each wavelength (p: [k * nL + l]) as a
// bin-averaged BSDF (× toF = 1/Ω⊥) into f, with the standard error of the stratified mean into e.
// stratum[k] (0 … T−1) names the group of directions drawn the same way.
//
// A stratum's variance is the spread of its directions' values, but never less than the mean of
// their variances over the points (the law of total variance: Var X = E Var(X|ω) + Var E(X|ω)).
// A stratum has a few directions, so its spread alone has a few degrees of freedom: two values
// that happened to agree gave a bin of noise −0.31 ± 0.004 where the truth is 0. The variance over
// a direction's N points (a jackknife) has N − 1 of them, and where the integrand hardly changes
// across the bin (noise, a flat lobe) it is nearly all of the variance.
//
// A stratum of kManyDirections or more has degrees of freedom enough in its spread, and its floor
// is half that mean: the jackknife counts the degenerate part of the pairwise power twice, so in a
// bin of noise half of it is about E Var(X|ω) (the full floor held the 1536 bins of a sine grating
// over an incidence bin at mean z² 0.39, half of it at 0.65; none at all let a dome lattice's
// heavy-tailed bins fall to 1.47).
constexpr int kManyDirections = 16;
static void binIntegral(const std::vector<int>& stratum, int T, int M, int nL, int nB, int b, double toF,
                        const std::vector<double>& p, const std::vector<double>& within, std::vector<double>& f,
                        std::vector<double>& e) {
  std::vector<double> sum(T), sum2(T), inner(T);
  std::vector<int> n(T);
  for (int l = 0; l < nL; ++l) {
    std::fill(sum.begin(), sum.end(), 0.0);
    std::fill(sum2.begin(), sum2.end(), 0.0);
    std::fill(inner.begin(), inner.end(), 0.0);
    std::fill(n.begin(), n.end(), 0);
    double mean = 0;
    for (int k = 0; k < M; ++k) {
      double v = p[size_t(k) * nL + l];
      int t = stratum[size_t(k)];
      sum[t] += v;
      sum2[t] += v * v;
      inner[t] += within[size_t(k) * nL + l];
      n[t]++;
      mean += v;
    }
    mean /= M;
    // Variance of a stratified sum: Σ_t n_t Var_t / M² (a stratum with one direction contributes
    // its square, or its variance over the points if larger: conservative).
    double var = 0;
    for (int t = 0; t < T; ++t) {
      if (n[t] == 0) continue;
      const double spread = n[t] > 1 ? std::max(0.0, (sum2[t] - sum[t] * sum[t] / n[t]) / (n[t] - 1)) : sum2[t];
      const double within = inner[t] / n[t] * (n[t] < kManyDirections ? 1.0 : 0.5);
      var += n[t] * std::max(spread, within);
    }
    f[size_t(l) * nB + b] = mean * toF;
    e[size_t(l) * nB + b] = std::sqrt(var) / M * toF;
  }
}

namespace {
// Directions M and points N per direction for a bin reached by `lobes` lobes: M = budget / N0,
// raised so that every lobe and the uniform technique get two directions or more where the budget
// allows (their errors are then estimated from their own spread, not bounded by a single value's
// square).
std::pair<int, int> directionsFor(uint64_t budget, int N0, size_t lobes) {
  uint64_t M = std::max<uint64_t>(2, budget / uint64_t(N0));
  // At most 4x the directions (a quarter of the points): the pairwise estimate's floor on a rough
  // surface grows as the points per direction fall.
  const uint64_t Mmax = std::max<uint64_t>(M, std::min(budget / 2, 4 * M));
  if (lobes > 0) {
    uint64_t wanted = uint64_t(BinDirectionSampler::uniformCount(int(std::min<uint64_t>(M, 1u << 20)))) + 2 * lobes;
    while (M < wanted && M < Mmax) {
      M = std::min(Mmax, wanted);
      wanted = uint64_t(BinDirectionSampler::uniformCount(int(M))) + 2 * lobes;
    }
  }
  return {int(M), int(std::max<uint64_t>(2, budget / M))};
}

// The control variate's pieces for one exit direction and wavelength (mean_plane_control.h):
// q = k1 − k2, c·h (s, p) and c·E[Z] (s, p). active = false: c is negligible, Y = X.
struct PlaneTerm {
  Vec3 q;
  Complex chS, chP, cEzS, cEzP;
  bool active = false;
};
// Below this |c| the control saves nothing worth its cost (it is fixed before sampling: no bias).
constexpr double kMinControl = 1e-3;
// Fewest points per direction a bin is given when the control variate leaves little variance (and
// never fewer than a quarter of wave_points_per_direction: shadowing and masking, which c does not
// see, keep some of the variance).
constexpr int kMinPoints = 4;

PlaneTerm planeTermOf(const WaveContext& ctx, const MeanPlaneControl& control, const wave::Media& media, int l,
                      const Vec3& wi, const Vec3& wo, bool fromAbove, bool transmission) {
  PlaneTerm t;
  const double k0 = 2 * kPi / ctx.lambda_um[size_t(l)];
  const double nI = media.incident(l, fromAbove), nO = transmission ? media.other(l, fromAbove) : nI;
  t.q = wi * (-nI * k0) - wo * (nO * k0);
  const Complex c = control.coefficient(t.q.z);
  if (std::abs(c) < kMinControl) return t;
  const Vec3 mPlane{0, 0, fromAbove ? 1.0 : -1.0};
  const KirchhoffValue h = wave::integrandAt(media, l, Vec3{0, 0, 0}, mPlane, wi, wo, k0, fromAbove, transmission);
  const double J = ctx.window.planeIntegral(t.q.x, t.q.y);
  t.chS = c * h.s;
  t.chP = c * h.p;
  t.cEzS = t.chS * J;
  t.cEzP = t.chP * J;
  t.active = true;
  return t;
}
}  // namespace

// The power of each grating order that carries light from the incidence bin's centre into an exit
// hemisphere, at the middle wavelength, from kPilotPoints points: the weight of its lobe when
// averagedPair chooses among the lobes that reach an exit direction. Chosen by their shares alone,
// the orders of a flat patch (all of zero power but the specular) drew as often as the specular,
// whose thin strip at the incidence bin's edge then went unsampled: an exit bin next to the
// incidence bin's image, holding 1.8 % of the energy, read 0 ± 0. A weight is the estimate plus
// two standard errors over |cos θo| n_o² (the lobe's peak to its power: its area in the plane of
// direction cosines goes as 1/n_o²), at least kWeightFloor of the largest (an order the pilot
// misses is still drawn). Any weights keep the estimate unbiased. None where the pilot would cost
// more than a quarter of the tile's budget, or the lobes overlap.
GratingOrderWeights AreaWaveEstimator::orderWeights(int tile, int incidenceBin, const wave::Media& media,
                                                    bool fromAbove, uint64_t budget, uint64_t* rays) const {
  GratingOrderWeights w;
  if (lobeRegime(ctx_) != LobeRegime::Orders) return w;
  const int nL = int(ctx_.lambda_um.size()), lm = nL / 2;
  const double k0 = 2 * kPi / ctx_.lambda_um[size_t(lm)], Lx = ctx_.scene.sizeX(), Ly = ctx_.scene.sizeY();
  const double nI = media.incident(lm, fromAbove), nOther = media.conductor() ? nI : media.other(lm, fromAbove);
  const double gMax = (nI + std::max(nI, nOther)) * k0;  // |G| of any order that leaves
  w.aMin = -long(std::ceil(gMax * Lx / (2 * kPi))), w.bMin = -long(std::ceil(gMax * Ly / (2 * kPi)));
  w.na = 1 - 2 * w.aMin, w.nb = 1 - 2 * w.bMin;
  const Vec3 wi = ctx_.grid.centre(incidenceBin);
  struct Order {
    int hemisphere;
    size_t at;
    Vec3 wo;
    bool transmission;
    double nO;
  };
  std::vector<Order> orders;
  for (int h = 0; h < 2; ++h) {
    const double zs = h == 0 ? 1.0 : -1.0;
    const bool transmission = wave::isTransmission(media.conductor(), fromAbove, Vec3{0, 0, zs});
    if (media.conductor() && (zs > 0) != fromAbove) continue;
    const double nO = transmission ? nOther : nI;
    for (long a = w.aMin; a < w.aMin + w.na; ++a)
      for (long b = w.bMin; b < w.bMin + w.nb; ++b) {
        const auto [x, y] = orderDirectionXY(a, b, Lx, Ly, nI, nO, k0, wi);
        const double r2 = x * x + y * y;
        if (r2 < 1)
          orders.push_back(
              {h, size_t((a - w.aMin) * w.nb + (b - w.bMin)), Vec3{x, y, zs * std::sqrt(1 - r2)}, transmission, nO});
      }
  }
  if (orders.empty() || uint64_t(orders.size()) * kPilotPoints > budget / 4) return w;
  std::vector<double> weight(orders.size());
  std::atomic<uint64_t> pilotRays{0};
  tbb::parallel_for(size_t(0), orders.size(), [&](size_t i) {
    const Order& o = orders[i];
    Sampler s(ctx_.settings.seed, uint32_t(tile), i, kPilotStream);
    Powers pv{std::vector<double>(size_t(nL), 0.0), std::vector<double>(size_t(nL), 0.0)}, pm;
    uint64_t localRays = 0;
    directionPowers({wi, o.wo, o.transmission, 1.0}, 0, nL, kPilotPoints, false, media, fromAbove, s, pv, pm,
                    &localRays);
    pilotRays += localRays;
    const double p = std::max(0.0, pv.p[size_t(lm)]) + 2 * std::sqrt(std::max(0.0, pv.within[size_t(lm)]));
    weight[i] = p / (std::abs(o.wo.z) * o.nO * o.nO);
  });
  *rays = pilotRays.load();
  const double largest = *std::max_element(weight.begin(), weight.end());
  if (!(largest > 0) || !std::isfinite(largest)) return w;
  for (int h = 0; h < 2; ++h) w.byHemisphere[h].assign(size_t(w.na * w.nb), kWeightFloor);
  for (size_t i = 0; i < orders.size(); ++i)
    w.byHemisphere[orders[i].hemisphere][orders[i].at] = std::max(kWeightFloor, weight[i] / largest);
  return w;
}

// Points per direction for exit bin b: the residual Y − E[Y] of the control variate has about
// (1 − |c|²) of the variance of X (mean_plane_control.h), so a bin where |c| is near 1 needs few
// points per direction and takes more directions instead. c at the bin's centre and the shortest
// wavelength (the largest q_z: the smallest |c|).
int AreaWaveEstimator::pointsFor(int b, int N0, const wave::Media& media, bool fromAbove,
                                 const std::optional<Vec3>& exactDirection, int incidenceBin) const {
  if (!control_.usable()) return N0;
  const Vec3 wi = exactDirection ? normalize(*exactDirection) : ctx_.grid.centre(incidenceBin);
  const Vec3 wo = ctx_.grid.centre(b);
  double lambdaMin = ctx_.lambda_um[0];
  int l0 = 0;
  for (size_t l = 0; l < ctx_.lambda_um.size(); ++l)
    if (ctx_.lambda_um[l] < lambdaMin) lambdaMin = ctx_.lambda_um[l], l0 = int(l);
  const bool transmission = wave::isTransmission(media.conductor(), fromAbove, wo);
  const double k0 = 2 * kPi / lambdaMin, nI = media.incident(l0, fromAbove);
  const double nO = transmission ? media.other(l0, fromAbove) : nI;
  const double qz = -k0 * (nI * wi.z + nO * wo.z);
  const double residual = std::max(0.0, 1 - std::norm(control_.coefficient(qz)));
  return std::max({kMinPoints, N0 / 4, std::min(N0, int(std::ceil(N0 * residual)))});
}

WaveTileResult AreaWaveEstimator::run(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                                      const std::vector<uint8_t>& exitMask) const {
  const int tile = request.tile, incidenceBin = request.incidenceBin;
  const std::optional<Vec3>& exactDirection = request.exactDirection;
  auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = ctx_.grid;
  const int nL = int(ctx_.lambda_um.size()), nB = grid.binCount();
  // N points per direction, M = budget / N directions per bin (a bin with lobes takes more
  // directions, fewer points: directionsFor).
  const uint64_t budget = uint64_t(std::max(4, ctx_.settings.samplesPerBin));
  const int N0 = std::max(2, ctx_.settings.pointsPerDirection);
  const bool masked = ctx_.settings.computeMasked;
  const bool fromAbove = exactDirection ? exactDirection->z >= 0 : grid.isUpper(incidenceBin);
  const wave::Media media(ctx_);
  const std::vector<int> bins = wave::exitBins(grid, fromAbove, !media.conductor(), masked, exitMask);

  WaveTileResult r(nL, nB, masked);
  r.computed = exitMask;
  std::atomic<uint64_t> rays{0};
  uint64_t pilotRays = 0;
  const GratingOrderWeights weights =
      exactDirection ? GratingOrderWeights{}
                     : orderWeights(tile, incidenceBin, media, fromAbove, budget * uint64_t(bins.size()), &pilotRays);
  rays += pilotRays;
  auto doBin = [&](int b) {
    BinDirectionSampler dirs(grid, b), incidence(grid, incidenceBin);
    // The beam's lobes, or the lobes of the incidence bin's centre to size the allocation.
    dirs.findLobes(ctx_, media, exactDirection ? normalize(*exactDirection) : grid.centre(incidenceBin), fromAbove);
    // Over an incidence bin most of the variance lies between the pairs (which pair reaches a lobe,
    // and where in it), not among one pair's points: a quarter of the points, four times the pairs.
    // At a collimated beam's split, 4 or 5 pairs per bin on the dome lattice left bins at 0 ± 0
    // that held 0.39 (mean z² 1.4e3); with four times the pairs, 0.88.
    const int points = pointsFor(b, N0, media, fromAbove, exactDirection, incidenceBin);
    const auto [M, N] =
        directionsFor(budget, exactDirection ? points : std::max(kMinPoints, points / 4), dirs.lobeCount());
    // The first (budget − M N) directions take one point more: every bin spends the budget.
    const int extra = int(budget - uint64_t(M) * uint64_t(N));
    dirs.allocate(M);
    // p_k per (direction, λ) for the visible and the masked field.
    Powers pv{std::vector<double>(size_t(M) * nL, 0.0), std::vector<double>(size_t(M) * nL, 0.0)};
    Powers pm{std::vector<double>(masked ? size_t(M) * nL : 0, 0.0),
              std::vector<double>(masked ? size_t(M) * nL : 0, 0.0)};
    // Strata of the error estimate: per technique with a collimated beam (the same lobes for
    // every k); with bin-averaged incidence the cosine-drawn pairs and the lobe-drawn ones, in fixed
    // numbers. Chosen at random per pair, a bin whose pairs all happened to come from the lobes read
    // 16.1 ± 0.18 where the truth is 12.8: the spread of the lobes' near-equal values missed the
    // binomial count.
    std::vector<int> stratum(size_t(M), 0);
    const int T = exactDirection ? dirs.techniques() : 2;
    const int nCosine = std::clamp(BinDirectionSampler::uniformCount(M), 1, std::max(1, M - 1));
    uint64_t localRays = 0;
    const std::optional<ExitBinPairs> pairs =
        exactDirection ? std::nullopt
                       : std::optional<ExitBinPairs>(exitBinPairs(ctx_, media, incidenceBin, b, fromAbove, weights));
    for (int k = 0; k < M; ++k) {
      // Keyed by (bin, direction): M differs between bins.
      Sampler s(ctx_.settings.seed, uint32_t(tile), (uint64_t(b) << 32) | uint64_t(k), kWaveStream);
      const int N_k = N + (k < extra ? 1 : 0);
      if (!exactDirection) {
        const PairDraw how{k < nCosine ? IncidenceDraw::Cosine : IncidenceDraw::Lobes, double(nCosine) / M};
        stratum[size_t(k)] = k < nCosine ? 0 : 1;
        if (const std::optional<DirectionPair> d = averagedPair(ctx_, *pairs, how, incidence, s))
          directionPowers({d->wi, d->wo, d->transmission, d->pdf}, k, nL, N_k, masked, media, fromAbove, s, pv, pm,
                          &localRays);
        continue;
      }
      const Vec3 wi = normalize(*exactDirection);
      stratum[size_t(k)] = dirs.technique(k) + 1;
      double u1 = s.get1D(), u2 = s.get1D();
      Vec3 wo;
      if (!dirs.sample(
              dirs.technique(k), u1, u2, [&] { return s.get1D(); }, &wo))
        continue;  // outside: 0
      const double pdf = dirs.density(dirs.technique(k), wo);
      const bool transmission = wave::isTransmission(media.conductor(), fromAbove, wo);
      directionPowers({wi, wo, transmission, pdf}, k, nL, N_k, masked, media, fromAbove, s, pv, pm, &localRays);
    }
    // Bin integral mean_k p_k / pdf_k, as a bin-averaged BSDF (÷ Ω⊥), with the standard error of
    // the mean over the M independent directions.
    const double toF = 1.0 / grid.projectedSolidAngle(b);
    binIntegral(stratum, T, M, nL, nB, b, toF, pv.p, pv.within, r.fws, r.fwsErr);
    if (masked) binIntegral(stratum, T, M, nL, nB, b, toF, pm.p, pm.within, r.pmsk, r.pmskErr);
    rays += localRays;
  };

  constexpr size_t kBatch = 512;
  for (size_t b0 = 0; b0 < bins.size(); b0 += kBatch) {
    size_t b1 = std::min(bins.size(), b0 + kBatch);
    tbb::parallel_for(b0, b1, [&](size_t i) { doBin(bins[i]); });
    throwIfStopped();
    if (progress) progress(uint64_t(b1) * budget);
  }
  r.samples = uint64_t(bins.size()) * budget;  // M N + extra = budget in every bin
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

// p_k / pdf_k for direction k into pv (visible field, with the mean-plane control variate) and pm
// (masked field), per wavelength, from N points by the unbiased pairwise form of |E Y|², with its
// variance over the points.
void AreaWaveEstimator::directionPowers(const Direction& d, int k, int nL, int N, bool masked, const wave::Media& media,
                                        bool fromAbove, Sampler& s, Powers& pv, Powers& pm, uint64_t* rays) const {
  // Y_j per point, wavelength and polarisation: [(j nL + l) 2 + s|p].
  std::vector<Complex> yv(size_t(N) * nL * 2, Complex(0)), ym(masked ? yv.size() : 0, Complex(0));
  std::vector<PlaneTerm> plane(static_cast<size_t>(nL));
  for (int l = 0; l < nL; ++l)
    plane[size_t(l)] = planeTermOf(ctx_, control_, media, l, d.wi, d.wo, fromAbove, d.transmission);
  const double area = sampler_.totalArea();
  for (int j = 0; j < N; ++j) {
    const double u3 = s.get1D(), u2 = s.get1D(), u1 = s.get1D();  // in this order (the last argument's first)
    SurfaceSample sp = sampler_.sample(u1, u2, u3);
    const Vec3 m = fromAbove ? sp.n : -sp.n;          // facing the incident medium
    ExitVisibility vis = ExitVisibility::BackFacing;  // X_j = 0 unless it is seen both ways
    if (dot(m, d.wi) > 0) {
      ++*rays;
      if (wave::escapes(ctx_.scene, sp.x, m, d.wi, sp.prim, fromAbove))
        vis = wave::visibleExit(ctx_.scene, sp.x, m, d.wo, sp.prim, fromAbove, d.transmission, rays);
    }
    const bool visible = vis == ExitVisibility::Visible, blocked = vis == ExitVisibility::Blocked;
    for (int l = 0; l < nL; ++l) {
      const PlaneTerm& pt = plane[size_t(l)];
      if (!visible && !(blocked && masked) && !pt.active) continue;
      const Complex cf = area * ctx_.window.copyFactor(sp.x.x, sp.x.y, pt.q.x, pt.q.y);
      Complex ys = 0, yp = 0;
      const size_t at = (size_t(j) * nL + size_t(l)) * 2;
      if (visible || (blocked && masked)) {
        const double k0 = 2 * kPi / ctx_.lambda_um[size_t(l)];
        const KirchhoffValue kv = wave::integrandAt(media, l, sp.x, m, d.wi, d.wo, k0, fromAbove, d.transmission);
        ys = kv.s * cf;
        yp = kv.p * cf;
        if (blocked) {
          ym[at] = ys;
          ym[at + 1] = yp;
          ys = yp = 0;
        }
      }
      if (pt.active) {
        // Y = X − c (Z − E[Z]), Z = A n_z C(x, q) h e^{i q_xy·x_xy}.
        const Complex z = cf * sp.n.z * std::polar(1.0, pt.q.x * sp.x.x + pt.q.y * sp.x.y);
        ys -= pt.chS * z - pt.cEzS;
        yp -= pt.chP * z - pt.cEzP;
      }
      yv[at] = ys;
      yv[at + 1] = yp;
    }
  }
  const double cosI = std::abs(d.wi.z);
  for (int l = 0; l < nL; ++l) {
    const double nI = media.incident(l, fromAbove), nO = d.transmission ? media.other(l, fromAbove) : nI;
    // p(ωo) / pdf(ωo): an unbiased estimate of ∫_bin p dω.
    const double scale = kirchhoffPowerScale(ctx_.window.w2(), cosI, nI, nO) / d.pdf;
    const size_t at = size_t(k) * nL + size_t(l);
    std::tie(pv.p[at], pv.within[at]) = pairwisePower(yv, N, nL, l, scale);
    if (masked) std::tie(pm.p[at], pm.within[at]) = pairwisePower(ym, N, nL, l, scale);
  }
}

}  // namespace mbsdf
