#include "scattering/area_estimator.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <cmath>

#include "core/rng.h"
#include "core/stop.h"
#include "scattering/wave_common.h"

using mbsdf::wave::ExitVisibility;

namespace mbsdf {

namespace {
constexpr uint32_t kWaveStream = 0x57A7E;  // keeps the wave samples apart from the path tracer's
constexpr double kUniformFraction = 0.2;   // share of exit directions drawn uniformly in the bin
constexpr size_t kMaxLobes = 4096;

// Exit directions inside one bin. A periodic patch under a coherence window much wider than the
// patch scatters into narrow lobes around the grating orders G = 2π(a/Lx, b/Ly): by Poisson
// summation of the copy sum, |C(x, q)|² ≈ Σ_G c_G exp(−σ²|q_xy − G|²), i.e. Gaussian lobes of
// standard deviation 1/(√2 σ n_o k0) in (x, y) of ωo around ωo_xy = −(G + n_i k0 ωi_xy)/(n_o k0),
// for every wavelength. Uniform sampling of a bin would rarely hit them, so ωo is drawn from a
// mixture of the uniform density and these lobes; the estimate divides by the mixture density,
// which keeps it unbiased whatever the lobes really look like. Used with a collimated incidence
// (one ωi per bin); with bin-averaged incidence the lobes sweep across the incidence bin and the
// uniform density is used.
class ExitDirectionSampler {
 public:
  struct Lobe {
    double cx, cy, sd;
  };
  ExitDirectionSampler(const DirectionGrid& grid, int bin) : grid_(grid), bin_(bin) {}

  void findLobes(const WaveContext& ctx, const wave::Media& media, const Vec3& wi, bool fromAbove) {
    lobes_.clear();
    const CoherenceWindow& w = ctx.window;
    if (!w.active() || !ctx.scene.periodic()) return;
    const bool transmission = !media.conductor() && grid_.isUpper(bin_) != fromAbove;
    const double Lx = ctx.scene.sizeX(), Ly = ctx.scene.sizeY();
    double x0, x1, y0, y1;
    grid_.xyBounds(bin_, &x0, &x1, &y0, &y1);
    const double zs = grid_.isUpper(bin_) ? 1.0 : -1.0;
    for (size_t l = 0; l < ctx.lambda_um.size(); ++l) {
      const double k0 = 2 * kPi / ctx.lambda_um[l];
      const double nI = media.incident(int(l), fromAbove);
      const double nO = transmission ? media.other(int(l), fromAbove) : nI;
      const double sd = 1.0 / (std::sqrt(2.0) * w.sigma() * nO * k0);
      const double m = 4 * sd;
      // ωo_xy = −(G + nI k0 ωi_xy)/(nO k0) inside the widened box <=> G in this range:
      const double gx0 = -nO * k0 * (x1 + m) - nI * k0 * wi.x, gx1 = -nO * k0 * (x0 - m) - nI * k0 * wi.x;
      const double gy0 = -nO * k0 * (y1 + m) - nI * k0 * wi.y, gy1 = -nO * k0 * (y0 - m) - nI * k0 * wi.y;
      const long a0 = long(std::ceil(gx0 * Lx / (2 * kPi))), a1 = long(std::floor(gx1 * Lx / (2 * kPi)));
      const long b0 = long(std::ceil(gy0 * Ly / (2 * kPi))), b1 = long(std::floor(gy1 * Ly / (2 * kPi)));
      if ((a1 - a0 + 1) * (b1 - b0 + 1) > long(kMaxLobes)) {
        lobes_.clear();
        return;
      }
      for (long a = a0; a <= a1; ++a)
        for (long b = b0; b <= b1; ++b) {
          double cx = -(2 * kPi * a / Lx + nI * k0 * wi.x) / (nO * k0);
          double cy = -(2 * kPi * b / Ly + nI * k0 * wi.y) / (nO * k0);
          // Keep lobes that reach into this bin (probe the centre and ±3 sd).
          bool reaches = false;
          for (int dx = -1; dx <= 1 && !reaches; ++dx)
            for (int dy = -1; dy <= 1 && !reaches; ++dy) {
              double px = cx + 3 * sd * dx, py = cy + 3 * sd * dy, r2 = px * px + py * py;
              if (r2 < 1 && grid_.binOf({px, py, zs * std::sqrt(1 - r2)}) == bin_) reaches = true;
            }
          if (reaches) lobes_.push_back({cx, cy, sd});
          if (lobes_.size() > kMaxLobes) {
            lobes_.clear();
            return;
          }
        }
    }
  }

  // Techniques are allocated deterministically over the M directions of a bin (multi-sample MIS,
  // balance heuristic; Veach 1997 §9.2): the first nUniform draw uniformly in the bin, the others go
  // round-robin over the lobes. Requires one incidence direction for the whole bin.
  void allocate(int M) {
    M_ = M;
    nUniform_ = lobes_.empty() ? M : std::max(1, int(std::lround(kUniformFraction * M)));
    counts_.assign(lobes_.size(), 0);
    for (int k = nUniform_; k < M; ++k) counts_[size_t(k - nUniform_) % lobes_.size()]++;
  }
  int technique(int k) const { return k < nUniform_ ? -1 : int(size_t(k - nUniform_) % lobes_.size()); }
  // Draws ωo with technique t (−1: uniform); false if the draw fell outside the bin (estimate 0).
  bool sample(int t, double u1, double u2, Vec3* wo) const {
    if (t < 0) {
      *wo = grid_.sampleUniform(bin_, u1, u2).w;
      return true;
    }
    const Lobe& L = lobes_[size_t(t)];
    double r = L.sd * std::sqrt(-2 * std::log(std::max(u1, 1e-300))), a = 2 * kPi * u2;
    double x = L.cx + r * std::cos(a), y = L.cy + r * std::sin(a), r2 = x * x + y * y;
    if (r2 >= 1) return false;
    *wo = Vec3{x, y, (grid_.isUpper(bin_) ? 1.0 : -1.0) * std::sqrt(1 - r2)};
    return grid_.binOf(*wo) == bin_;
  }
  // Effective density Σ_t (n_t / M) pdf_t in solid angle: f / density, averaged over the M
  // directions, is the balance-heuristic estimate of ∫_bin f dω.
  double density(const Vec3& wo) const {
    double d = double(nUniform_) / M_ / grid_.solidAngle(bin_);
    if (lobes_.empty()) return d;
    double lobe = 0;
    for (size_t c = 0; c < lobes_.size(); ++c) {
      if (!counts_[c]) continue;
      const Lobe& L = lobes_[c];
      double dx = wo.x - L.cx, dy = wo.y - L.cy;
      lobe += counts_[c] * std::exp(-(dx * dx + dy * dy) / (2 * L.sd * L.sd)) / (2 * kPi * L.sd * L.sd);
    }
    return d + lobe * std::abs(wo.z) / M_;
  }
  int techniques() const { return int(lobes_.size()) + 1; }
  size_t lobeCount() const { return lobes_.size(); }

 private:
  const DirectionGrid& grid_;
  int bin_;
  std::vector<Lobe> lobes_;
  std::vector<int> counts_;
  int M_ = 1, nUniform_ = 1;
};

}  // namespace

AreaWaveEstimator::AreaWaveEstimator(const WaveContext& ctx) : ctx_(ctx), sampler_(ctx.geometry) {}

// Bin b's integral mean_k p_k / pdf_k over the M directions of each wavelength (p: [k * nL + l]) as a
// bin-averaged BSDF (× toF = 1/Ω⊥) into f, with the standard error of the stratified mean into e.
static void binIntegral(const ExitDirectionSampler& dirs, int M, int nL, int nB, int b, double toF,
                        const std::vector<double>& p, std::vector<double>& f, std::vector<double>& e) {
  const int T = dirs.techniques();
  std::vector<double> sum(T), sum2(T);
  std::vector<int> n(T);
  for (int l = 0; l < nL; ++l) {
    std::fill(sum.begin(), sum.end(), 0.0);
    std::fill(sum2.begin(), sum2.end(), 0.0);
    std::fill(n.begin(), n.end(), 0);
    double mean = 0;
    for (int k = 0; k < M; ++k) {
      double v = p[size_t(k) * nL + l];
      int t = dirs.technique(k) + 1;
      sum[t] += v;
      sum2[t] += v * v;
      n[t]++;
      mean += v;
    }
    mean /= M;
    // Variance of a stratified sum: Σ_t n_t Var_t / M², Var_t from each technique's own
    // samples (a technique with one sample contributes its square: conservative).
    double var = 0;
    for (int t = 0; t < T; ++t) {
      if (n[t] == 0) continue;
      double vt = n[t] > 1 ? std::max(0.0, (sum2[t] - sum[t] * sum[t] / n[t]) / (n[t] - 1)) : sum2[t];
      var += n[t] * vt;
    }
    f[size_t(l) * nB + b] = mean * toF;
    e[size_t(l) * nB + b] = std::sqrt(var) / M * toF;
  }
}

WaveTileResult AreaWaveEstimator::run(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                                      const std::vector<uint8_t>& exitMask) const {
  const int tile = request.tile, incidenceBin = request.incidenceBin;
  const std::optional<Vec3>& exactDirection = request.exactDirection;
  auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = ctx_.grid;
  const int nL = int(ctx_.lambda_um.size()), nB = grid.binCount();
  // N points per direction, M = budget / N directions (>= 2): the variance of the bin estimate
  // then falls as 1 / budget, the directions being independent.
  const int N = std::max(2, ctx_.settings.pointsPerDirection);
  const int M = std::max(2, ctx_.settings.samplesPerBin / N);
  const bool masked = ctx_.settings.computeMasked;
  const bool fromAbove = exactDirection ? exactDirection->z >= 0 : grid.isUpper(incidenceBin);
  const wave::Media media(ctx_);
  const std::vector<int> bins = wave::exitBins(grid, fromAbove, !media.conductor(), masked, exitMask);
  const double area = sampler_.totalArea();

  WaveTileResult r(nL, nB, masked);
  r.computed = exitMask;
  std::atomic<uint64_t> rays{0};

  auto doBin = [&](int b) {
    // p_k per (direction, λ) for the visible and the masked field.
    std::vector<double> pv(size_t(M) * nL, 0.0), pm(masked ? size_t(M) * nL : 0, 0.0);
    std::vector<Complex> sv(2 * nL), sm(2 * nL);
    std::vector<double> qv(2 * nL), qm(2 * nL);
    uint64_t localRays = 0;
    ExitDirectionSampler dirs(grid, b);
    if (exactDirection) dirs.findLobes(ctx_, media, normalize(*exactDirection), fromAbove);
    dirs.allocate(M);
    for (int k = 0; k < M; ++k) {
      Sampler s(ctx_.settings.seed, uint32_t(tile), uint64_t(b) * uint64_t(M) + uint64_t(k), kWaveStream);
      const Vec3 wi = exactDirection ? normalize(*exactDirection) : grid.sampleCosine(incidenceBin, s).w;
      double u1 = s.get1D(), u2 = s.get1D();
      Vec3 wo;
      if (!dirs.sample(dirs.technique(k), u1, u2, &wo)) continue;  // outside the bin: estimate 0
      const double pdf = dirs.density(wo);
      const bool transmission = wave::isTransmission(media.conductor(), fromAbove, wo);
      const double cosI = std::abs(wi.z);
      std::fill(sv.begin(), sv.end(), Complex(0));
      std::fill(sm.begin(), sm.end(), Complex(0));
      std::fill(qv.begin(), qv.end(), 0.0);
      std::fill(qm.begin(), qm.end(), 0.0);
      for (int j = 0; j < N; ++j) {
        const double u3 = s.get1D(), u2 = s.get1D(), u1 = s.get1D();  // in this order (the last argument's first)
        SurfaceSample sp = sampler_.sample(u1, u2, u3);
        const Vec3 m = fromAbove ? sp.n : -sp.n;  // facing the incident medium
        const double cosLocal = dot(m, wi);
        if (cosLocal <= 0) continue;  // back-facing: X_j = 0
        ++localRays;
        if (!wave::escapes(ctx_.scene, sp.x, m, wi, sp.prim, fromAbove)) continue;  // shadowed
        const ExitVisibility vis =
            wave::visibleExit(ctx_.scene, sp.x, m, wo, sp.prim, fromAbove, transmission, &localRays);
        if (vis == ExitVisibility::BackFacing || (vis == ExitVisibility::Blocked && !masked)) continue;
        const bool visible = vis == ExitVisibility::Visible;
        auto& S = visible ? sv : sm;
        auto& Q = visible ? qv : qm;
        for (int l = 0; l < nL; ++l) {
          const double k0 = 2 * kPi / ctx_.lambda_um[l];
          KirchhoffValue kv = wave::integrandAt(media, l, sp.x, m, wi, wo, k0, fromAbove, transmission);
          const Complex wgt = area * ctx_.window.copyFactor(sp.x.x, sp.x.y, kv.qx, kv.qy);
          const Complex xs = kv.s * wgt, xp = kv.p * wgt;
          S[2 * l] += xs;
          S[2 * l + 1] += xp;
          Q[2 * l] += std::norm(xs);
          Q[2 * l + 1] += std::norm(xp);
        }
      }
      // Unbiased |E X|² for s and p, then the mean of the two powers (unpolarised light).
      const double nn = double(N) * double(N - 1);
      for (int l = 0; l < nL; ++l) {
        const double nI = media.incident(l, fromAbove), nO = transmission ? media.other(l, fromAbove) : nI;
        // p(ωo) / pdf(ωo): an unbiased estimate of ∫_bin p dω.
        const double scale = kirchhoffPowerScale(ctx_.window.w2(), cosI, nI, nO) / pdf;
        auto power = [&](const std::vector<Complex>& S, const std::vector<double>& Q) {
          double ps = std::norm(S[2 * l]) - Q[2 * l], pp = std::norm(S[2 * l + 1]) - Q[2 * l + 1];
          return 0.5 * (ps + pp) / nn * scale;
        };
        pv[size_t(k) * nL + l] = power(sv, qv);
        if (masked) pm[size_t(k) * nL + l] = power(sm, qm);
      }
    }
    // Bin integral mean_k p_k / pdf_k, as a bin-averaged BSDF (÷ Ω⊥), with the standard error of
    // the mean over the M independent directions.
    const double toF = 1.0 / grid.projectedSolidAngle(b);
    auto reduce = [&](const std::vector<double>& p, std::vector<double>& f, std::vector<double>& e) {
      binIntegral(dirs, M, nL, nB, b, toF, p, f, e);
    };
    reduce(pv, r.fws, r.fwsErr);
    if (masked) reduce(pm, r.pmsk, r.pmskErr);
    rays += localRays;
  };

  constexpr size_t kBatch = 512;
  for (size_t b0 = 0; b0 < bins.size(); b0 += kBatch) {
    size_t b1 = std::min(bins.size(), b0 + kBatch);
    tbb::parallel_for(b0, b1, [&](size_t i) { doBin(bins[i]); });
    throwIfStopped();
    if (progress) progress(uint64_t(b1) * uint64_t(M) * uint64_t(N));
  }
  r.samples = uint64_t(bins.size()) * uint64_t(M) * uint64_t(N);
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace mbsdf
