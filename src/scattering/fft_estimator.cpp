#include "scattering/fft_estimator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <cstdio>
#include <cmath>
#include <stdexcept>
#include <variant>

#include "core/stop.h"
#include "core/quadrature.h"
#include "scattering/area_estimator.h"
#include "scattering/heightfield_spectrum.h"
#include "scattering/orders_estimator.h"
#include "scattering/wave_common.h"

namespace mbsdf {

namespace {

constexpr double kWindowCut = 6.0;  // ŵ is dropped beyond σ|q − G| = 6 (e^{−18}: 1.5e-8)
constexpr int kRuleHigh = 3;        // Gauss–Legendre nodes per pixel and axis (and kRuleHigh − 1)

// One axis of the tensor grid of exit directions: the nodes of every pixel's n-point rule, their
// weights (pixel width x GL weight), and per node the band of orders whose window term counts.
struct Axis {
  std::vector<double> x, w;
  std::vector<int> pixel;
  // Banded ŵ factor: for node i, orders [first[i], first[i] + count[i]) with values band[i][...].
  std::vector<long> first;
  std::vector<std::vector<double>> band;
};

// The orders a (G = 2π a / L) with |q − G| <= reach along one axis.
std::pair<long, long> ordersWithin(double q, double reach, double L) {
  return {long(std::ceil((q - reach) * L / (2 * kPi))), long(std::floor((q + reach) * L / (2 * kPi)))};
}

// `sub` cells per pixel, each with an n-point rule.
Axis makeAxis(int pixels, int sub, int n, double qOffset, double nOk0, double sigma, double L) {
  Axis ax;
  const QuadratureRule q = compositeGaussLegendre(n, sub);
  for (int p = 0; p < pixels; ++p)
    for (size_t i = 0; i < q.x.size(); ++i) {
      ax.x.push_back(-1 + 2.0 * (p + q.x[i]) / pixels);
      ax.w.push_back(2.0 / pixels * q.w[i]);
      ax.pixel.push_back(p);
    }
  for (double x : ax.x) {
    // q_xy = −n_i k0 ωi_xy − n_o k0 ωo_xy; orders G = 2π a / L with σ|q − G| <= kWindowCut.
    const double qv = qOffset - nOk0 * x;
    const auto [a0, a1] = ordersWithin(qv, kWindowCut / sigma, L);
    ax.first.push_back(a0);
    std::vector<double> v;
    for (long a = a0; a <= a1; ++a) {
      const double d = sigma * (qv - 2 * kPi * double(a) / L);
      v.push_back(std::exp(-0.5 * d * d));
    }
    ax.band.push_back(std::move(v));
  }
  return ax;
}

// The speckle regime (header): tensor grid of exit directions over a disk grid.
class FftSpeckleEstimator : public WaveEstimator {
 public:
  explicit FftSpeckleEstimator(const WaveContext& ctx)
      : ctx_(ctx),
        grid_(*heightGridOf(ctx.geometry)),
        spectrum_(ctx.geometry, grid_, ctx.scene, fourierMaxTexel(ctx.material, ctx.lambda_um)) {
    if (!ctx.material.isConductor()) denseSide_ = std::make_unique<AreaWaveEstimator>(ctx);
  }
  std::string name() const override { return "fft"; }
  std::string notes() const override {
    const double theta = 90.0 - std::atan(spectrum_.maxSlope()) * 180.0 / kPi;
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "deterministic (error: 3x3 vs 2x2 Gauss-Legendre per cell, cells <= speckle size); %d x %d FFT of "
                  "the facets (texels split %d x %d); "
                  "window narrower than the patch: masking not modelled, exact for exits below theta = %.1f deg "
                  "(steepest facet slope %.3f)",
                  spectrum_.nx(), spectrum_.ny(), spectrum_.refinement(), spectrum_.refinement(), theta,
                  spectrum_.maxSlope());
    return std::string(buf) +
           (denseSide_ ? "; transmission from the denser medium by the area estimator (Monte Carlo)" : "");
  }
  bool deterministic() const override { return true; }
  double memoryBytes() const override;
  using WaveEstimator::run;
  WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const override;

 private:
  // Adds Σ_nodes w p / cos θo per bin of one exit hemisphere for one incidence direction and
  // wavelength, for each rule n x n per pixel in `rules`, to (*out)[rule] (per bin, λ-major). The
  // FFT tables of each q_z node are shared by the rules.
  void exitIntegral(const HeightfieldSpectrum::FacetFields& fields, const Vec3& wi, int l, double nI, double nO,
                    bool transmission, bool fromAbove, const std::vector<int>& rules,
                    std::vector<std::vector<double>>* out) const;
  // The same for any grid: per bin, its cosine-weighted sample space (DirectionGrid::sampleCosine)
  // cut into cells no wider than about two speckles 1/(σ n_o k0), with a 3 x 3 and a 2 x 2
  // Gauss–Legendre rule in each; I(q) summed directly over the orders within the window's reach.
  // (*out)[0], [1]: the two rules' ∫ p dω per bin.
  void binIntegral(const HeightfieldSpectrum::FacetFields& fields, const Vec3& wi, int l, double nI, double nO,
                   bool transmission, bool fromAbove, std::vector<std::vector<double>>* out) const;

  // p(ωo) = (n_o/n_i) |I|² / (16π² W2 cos θi) with I = (2πσ²/A_fp) Σ_G ŵ-weights × Ĥ_G: the factor
  // that turns |Σ_G e^{−σ²|q−G|²/2} Ĥ_G|² (mean of s and p) into p.
  double powerScale(const Vec3& wi, double nI, double nO) const {
    const double sigma = ctx_.window.sigma();
    const double amp = 2 * kPi * sigma * sigma / (ctx_.scene.sizeX() * ctx_.scene.sizeY());
    return kirchhoffPowerScale(ctx_.window.w2(), std::abs(wi.z), nI, nO) * amp * amp;
  }

  WaveContext ctx_;
  HeightGrid grid_;
  HeightfieldSpectrum spectrum_;
  // Transmission from the denser medium takes the reverse path's integrand (wave::integrandAt),
  // whose Fresnel factor depends on the exit direction: not a field the FFT can share across exit
  // directions. Those bins come from the area estimator.
  std::unique_ptr<AreaWaveEstimator> denseSide_;
};

void FftSpeckleEstimator::exitIntegral(const HeightfieldSpectrum::FacetFields& fields, const Vec3& wi, int l, double nI,
                                       double nO, bool transmission, bool fromAbove, const std::vector<int>& rules,
                                       std::vector<std::vector<double>>* out) const {
  const DiskGrid disk = std::get<DiskGrid>(ctx_.grid.layout());
  const double k0 = 2 * kPi / ctx_.lambda_um[size_t(l)], sigma = ctx_.window.sigma();
  const double Lx = ctx_.scene.sizeX(), Ly = ctx_.scene.sizeY();
  // The exit hemisphere: reflection on the incident side, transmission on the other.
  const double zs = (fromAbove != transmission) ? 1.0 : -1.0;
  // Per rule: the two axes, the interpolation weights of each exit node and the fields I_s, I_p.
  struct Rule {
    Axis X, Y;
    std::vector<HeightfieldSpectrum::QzNodes::State> w;  // per exit node (qz = NaN: evanescent)
    std::vector<Complex> Is, Ip, C;
    double cos2(size_t i, size_t j) const { return 1 - X.x[i] * X.x[i] - Y.x[j] * Y.x[j]; }
  };
  std::vector<Rule> R;
  double qMin = 1e300, qMax = -1e300;
  long a0 = std::numeric_limits<long>::max(), a1 = std::numeric_limits<long>::min(), b0 = a0, b1 = a1;
  // Pixels wider than the speckle 1/(σ n_o k0) are cut into that many cells per axis, each with the
  // rule: the specular lobe of a wide window is narrower than a pixel.
  const double speckle = 1.0 / (sigma * nO * k0);
  const int subX = std::max(1, int(std::ceil(2.0 / disk.width / speckle))),
            subY = std::max(1, int(std::ceil(2.0 / disk.height / speckle)));
  for (int n : rules) {
    Rule r{makeAxis(disk.width, subX, n, -nI * k0 * wi.x, nO * k0, sigma, Lx),
           makeAxis(disk.height, subY, n, -nI * k0 * wi.y, nO * k0, sigma, Ly),
           {},
           {},
           {},
           {}};
    for (size_t i = 0; i < r.X.x.size(); ++i)
      for (size_t j = 0; j < r.Y.x.size(); ++j) {
        const double c2 = r.cos2(i, j);
        if (c2 <= 0) continue;
        const double qz = -nI * k0 * wi.z - nO * k0 * zs * std::sqrt(c2);
        qMin = std::min(qMin, qz), qMax = std::max(qMax, qz);
      }
    auto extend = [](const Axis& ax, long* lo, long* hi) {
      for (size_t i = 0; i < ax.x.size(); ++i)
        *lo = std::min(*lo, ax.first[i]), *hi = std::max(*hi, ax.first[i] + long(ax.band[i].size()) - 1);
    };
    extend(r.X, &a0, &a1);
    extend(r.Y, &b0, &b1);
    R.push_back(std::move(r));
  }
  if (qMin > qMax) return;
  const size_t na = size_t(a1 - a0 + 1), nb = size_t(b1 - b0 + 1);
  const auto nodes = spectrum_.qzNodes(qMin, qMax);
  const size_t N = nodes.q.size();
  for (Rule& r : R) {
    const size_t nx = r.X.x.size(), ny = r.Y.x.size();
    r.w.assign(nx * ny, {});
    tbb::parallel_for(size_t(0), nx, [&](size_t i) {
      for (size_t j = 0; j < ny; ++j) {
        const double c2 = r.cos2(i, j);
        if (c2 > 0) r.w[i * ny + j] = nodes.state(-nI * k0 * wi.z - nO * k0 * zs * std::sqrt(c2));
      }
    });
    r.Is.assign(nx * ny, 0.0);
    r.Ip.assign(nx * ny, 0.0);
    r.C.resize(8 * na * ny);
  }
  std::vector<Complex> tab;
  for (size_t node = 0; node < N; ++node) {
    spectrum_.nodeTables(fields, nodes.q[node], a0, a1, b0, b1, &tab);
    for (Rule& r : R) {
      const size_t nx = r.X.x.size(), ny = r.Y.x.size();
      // First product, along y: C[t][a][j] = Σ_b T[t][a][b] ŵy(j, b).
      tbb::parallel_for(size_t(0), 8 * na, [&](size_t ta) {
        const Complex* row = &tab[ta * nb];
        Complex* c = &r.C[ta * ny];
        for (size_t j = 0; j < ny; ++j) {
          Complex sum = 0;
          const Complex* src = row + (r.Y.first[j] - b0);
          const std::vector<double>& band = r.Y.band[j];
          for (size_t k = 0; k < band.size(); ++k) sum += band[k] * src[k];
          c[j] = sum;
        }
      });
      // Second product, along x, and the combination X + k2·B at each node, weighted for q_z.
      tbb::parallel_for(size_t(0), nx, [&](size_t i) {
        std::vector<Complex> acc(8 * ny, 0.0);
        const size_t off = size_t(r.X.first[i] - a0);
        for (size_t k = 0; k < r.X.band[i].size(); ++k) {
          const double wx = r.X.band[i][k];
          for (size_t t = 0; t < 8; ++t) {
            const Complex* c = &r.C[(t * na + off + k) * ny];
            Complex* d = &acc[t * ny];
            for (size_t j = 0; j < ny; ++j) d[j] += wx * c[j];
          }
        }
        for (size_t j = 0; j < ny; ++j) {
          const double c2 = r.cos2(i, j);
          if (c2 <= 0) continue;
          const Vec3 k2 = Vec3{r.X.x[i], r.Y.x[j], zs * std::sqrt(c2)} * (nO * k0);
          const Complex wq = nodes.weight(node, r.w[i * ny + j]);
          r.Is[i * ny + j] += wq * HeightfieldSpectrum::combine(&acc[j], ny, k2);
          r.Ip[i * ny + j] += wq * HeightfieldSpectrum::combine(&acc[4 * ny + j], ny, k2);
        }
      });
    }
  }
  const double scale = powerScale(wi, nI, nO);
  const int hemi = zs > 0 ? 0 : 1;
  for (size_t k = 0; k < R.size(); ++k) {
    const Rule& r = R[k];
    const size_t nx = r.X.x.size(), ny = r.Y.x.size();
    for (size_t i = 0; i < nx; ++i)
      for (size_t j = 0; j < ny; ++j) {
        const double c2 = r.cos2(i, j);
        if (c2 <= 0) continue;
        const double p = scale * 0.5 * (std::norm(r.Is[i * ny + j]) + std::norm(r.Ip[i * ny + j]));
        const int bin = hemi * ctx_.grid.binsPerHemisphere() + r.Y.pixel[j] * disk.width + r.X.pixel[i];
        (*out)[k][size_t(l) * size_t(ctx_.grid.binCount()) + size_t(bin)] += r.X.w[i] * r.Y.w[j] * p / std::sqrt(c2);
      }
  }
}

double FftSpeckleEstimator::memoryBytes() const {
  // Beyond the spectrum: the order tables of every q_z node (other grids) or of one node plus the
  // exit nodes' interpolation weights and fields (disk grid), at the shortest wavelength.
  double lambda = 1e300, nSum = 0;
  for (double l : ctx_.lambda_um) lambda = std::min(lambda, l), nSum = std::max(nSum, indexSum(ctx_.material, l));
  const double k0 = 2 * kPi / lambda, sigma = ctx_.window.sigma(), nO = nSum / 2;
  const double reach = kWindowCut / sigma;
  const double na = 2 * (nO * k0 + reach) * ctx_.scene.sizeX() / (2 * kPi) + 2,
               nb = 2 * (nO * k0 + reach) * ctx_.scene.sizeY() / (2 * kPi) + 2;
  const double N = double(spectrum_.qzNodes(-2 * nO * k0, -nO * k0).q.size());
  double extra = 8 * na * nb * sizeof(Complex);
  if (const auto* disk = std::get_if<DiskGrid>(&ctx_.grid.layout())) {
    const double speckle = 1.0 / (sigma * nO * k0);
    const double nx = disk->width * std::max(1.0, std::ceil(2.0 / disk->width / speckle)) * kRuleHigh,
                 ny = disk->height * std::max(1.0, std::ceil(2.0 / disk->height / speckle)) * kRuleHigh;
    extra += nx * ny * (sizeof(HeightfieldSpectrum::QzNodes::State) + 2 * sizeof(Complex)) * (1 + 4.0 / 9) +
             8 * na * ny * sizeof(Complex) * 2;
  } else
    extra += 8 * na * nb * N * sizeof(Complex);
  return spectrum_.memoryBytes() + extra;
}

void FftSpeckleEstimator::binIntegral(const HeightfieldSpectrum::FacetFields& fields, const Vec3& wi, int l, double nI,
                                      double nO, bool transmission, bool fromAbove,
                                      std::vector<std::vector<double>>* out) const {
  const DirectionGrid& grid = ctx_.grid;
  const double k0 = 2 * kPi / ctx_.lambda_um[size_t(l)], sigma = ctx_.window.sigma();
  const double Lx = ctx_.scene.sizeX(), Ly = ctx_.scene.sizeY();
  const double zs = (fromAbove != transmission) ? 1.0 : -1.0;
  const int hemi = zs > 0 ? 0 : 1;
  // Orders within the window's reach of the exit disk; q_z over the whole hemisphere.
  const double reach = kWindowCut / sigma;
  const double qx0 = -nI * k0 * wi.x, qy0 = -nI * k0 * wi.y, qr = nO * k0 + reach;
  // Plain variables, not structured bindings: the lambdas below capture them (clang 14).
  const std::pair<long, long> aRange = ordersWithin(qx0, qr, Lx), bRange = ordersWithin(qy0, qr, Ly);
  const long a0 = aRange.first, a1 = aRange.second, b0 = bRange.first, b1 = bRange.second;
  const size_t na = size_t(a1 - a0 + 1), nb = size_t(b1 - b0 + 1);
  const auto nodes = spectrum_.qzNodes(std::min(-nI * k0 * wi.z, -nI * k0 * wi.z - zs * nO * k0),
                                       std::max(-nI * k0 * wi.z, -nI * k0 * wi.z - zs * nO * k0));
  const size_t N = nodes.q.size();
  // All node tables, reordered per order: T[((a * nb + b) * N + n) * 8 + table].
  std::vector<Complex> T(na * nb * N * 8), tab;
  for (size_t n = 0; n < N; ++n) {
    spectrum_.nodeTables(fields, nodes.q[n], a0, a1, b0, b1, &tab);
    tbb::parallel_for(size_t(0), na * nb, [&](size_t ab) {
      for (size_t t = 0; t < 8; ++t) T[(ab * N + n) * 8 + t] = tab[t * na * nb + ab];
    });
  }
  const double speckle = 1.0 / (sigma * nO * k0);
  const double scale = powerScale(wi, nI, nO);
  const int nBins = grid.binsPerHemisphere();
  tbb::parallel_for(0, nBins, [&](int local) {
    if (stopRequested()) return;
    const int bin = hemi * nBins + local;
    const double omegaP = grid.projectedSolidAngle(bin);
    if (omegaP <= 0) return;
    double x0, x1, y0, y1;
    grid.xyBounds(bin, &x0, &x1, &y0, &y1);
    // Cells of the bin's sample space no wider than about two speckles, a 3 x 3 (and 2 x 2) rule in each.
    const int sub = std::max(1, int(std::ceil(std::max(x1 - x0, y1 - y0) / (2 * speckle))));
    std::vector<Complex> w(N);
    for (int ruleIndex = 0; ruleIndex < 2; ++ruleIndex) {
      const QuadratureRule q = compositeGaussLegendre(kRuleHigh - ruleIndex, sub);
      double sum = 0;
      for (size_t i = 0; i < q.x.size(); ++i)
        for (size_t j = 0; j < q.x.size(); ++j) {
          const Vec3 wo = grid.sampleCosine(bin, q.x[i], q.x[j]).w;
          const double cosO = std::abs(wo.z);
          if (cosO <= 0) continue;
          const Vec3 k2 = wo * (nO * k0);
          const double qx = qx0 - k2.x, qy = qy0 - k2.y, qz = -nI * k0 * wi.z - k2.z;
          nodes.weights(qz, w.data());
          Complex Is = 0, Ip = 0;
          const auto [ia0, ia1] = ordersWithin(qx, reach, Lx);
          const auto [ib0, ib1] = ordersWithin(qy, reach, Ly);
          for (long a = std::max(a0, ia0); a <= std::min(a1, ia1); ++a) {
            const double dx = sigma * (qx - 2 * kPi * double(a) / Lx), wx = std::exp(-0.5 * dx * dx);
            for (long b = std::max(b0, ib0); b <= std::min(b1, ib1); ++b) {
              const double dy = sigma * (qy - 2 * kPi * double(b) / Ly), wab = wx * std::exp(-0.5 * dy * dy);
              const Complex* t = &T[(size_t(a - a0) * nb + size_t(b - b0)) * N * 8];
              Complex s = 0, p = 0;
              for (size_t m = 0; m < N; ++m, t += 8) {
                s += w[m] * HeightfieldSpectrum::combine(t, 1, k2);
                p += w[m] * HeightfieldSpectrum::combine(t + 4, 1, k2);
              }
              Is += wab * s;
              Ip += wab * p;
            }
          }
          sum += q.w[i] * q.w[j] * scale * 0.5 * (std::norm(Is) + std::norm(Ip)) / cosO;
        }
      (*out)[size_t(ruleIndex)][size_t(l) * size_t(grid.binCount()) + size_t(bin)] += sum * omegaP;
    }
  });
  throwIfStopped();
}

WaveTileResult FftSpeckleEstimator::run(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                                        const std::vector<uint8_t>& exitMask) const {
  const int tile = request.tile, incidenceBin = request.incidenceBin;
  const std::optional<Vec3>& exactDirection = request.exactDirection;
  const auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = ctx_.grid;
  const int nL = int(ctx_.lambda_um.size()), nB = grid.binCount();
  const wave::Media media(ctx_);
  const bool fromAbove = exactDirection ? exactDirection->z >= 0 : grid.isUpper(incidenceBin);
  const bool transmissionWanted = !media.conductor() && wave::otherSideWanted(grid, fromAbove, exitMask);
  bool denseSide = false;
  for (int l = 0; l < nL && transmissionWanted; ++l) denseSide = denseSide || media.reverseTransmission(l, fromAbove);
  const auto rule =
      wave::incidenceRule(grid, incidenceBin, exactDirection, incidenceDirectionsOf(ctx_.settings, grid, incidenceBin));
  WaveTileResult r(nL, nB, false);
  const size_t n = size_t(nL) * size_t(nB);
  // Per rule: incidence high/low x exit rule high/low.
  std::vector<double> hiHi(n, 0.0), hiLo(n, 0.0), loHi(n, 0.0);
  uint64_t rays = 0;
  for (size_t k = 0; k < rule.size(); ++k) {
    const Vec3& wi = rule[k].wi;
    const auto lit = spectrum_.lit(wi, fromAbove, &rays);
    for (int l = 0; l < nL; ++l)
      for (int trans = 0; trans < (transmissionWanted && !denseSide ? 2 : 1); ++trans) {
        const double k0 = 2 * kPi / ctx_.lambda_um[size_t(l)];
        const double nI = media.incident(l, fromAbove), nO = trans ? media.other(l, fromAbove) : nI;
        const auto fields = spectrum_.fields(wi, fromAbove, l, k0, nI, nO, bool(trans), media, lit);
        std::vector<std::vector<double>> q(2, std::vector<double>(n, 0.0));
        if (std::holds_alternative<DiskGrid>(grid.layout()))
          exitIntegral(fields, wi, l, nI, nO, bool(trans), fromAbove,
                       rule[k].high ? std::vector<int>{kRuleHigh, kRuleHigh - 1} : std::vector<int>{kRuleHigh}, &q);
        else
          binIntegral(fields, wi, l, nI, nO, bool(trans), fromAbove, &q);
        const std::vector<double>& hi = q[0];
        for (size_t i = 0; i < n; ++i) {
          if (rule[k].high) {
            hiHi[i] += rule[k].weight * hi[i];
            hiLo[i] += rule[k].weight * q[1][i];
          } else
            loHi[i] += rule[k].weight * hi[i];
        }
      }
    if (progress) progress(uint64_t(k + 1));
  }
  const bool incidenceRule = rule.size() > 1;
  for (size_t i = 0; i < n; ++i) {
    const double omega = grid.projectedSolidAngle(int(i % size_t(nB)));
    if (omega <= 0) continue;
    r.fws[i] = hiHi[i] / omega;
    const double eExit = std::abs(hiHi[i] - hiLo[i]), eInc = incidenceRule ? std::abs(hiHi[i] - loHi[i]) : 0.0;
    r.fwsErr[i] = std::hypot(eExit, eInc) / omega;
  }
  r.samples = uint64_t(spectrum_.facets()) * uint64_t(grid.binsPerHemisphere()) * rule.size();
  r.rays = rays;
  if (denseSide) {
    std::vector<uint8_t> other(size_t(nB), 0);
    for (int b = 0; b < nB; ++b)
      other[size_t(b)] = grid.isUpper(b) != fromAbove && (exitMask.empty() || exitMask[size_t(b)]);
    const WaveTileResult t = denseSide_->run(tile, incidenceBin, exactDirection, {}, other);
    for (size_t i = 0; i < n; ++i)
      if (other[i % size_t(nB)]) r.fws[i] = t.fws[i], r.fwsErr[i] = t.fwsErr[i];
    r.samples += t.samples;
    r.rays += t.rays;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace

std::string fftUnsuitable(const Microgeometry& g, const Material& material, const std::vector<double>& lambda_um,
                          double sigma, bool masked) {
  if (!g.periodic || sigma <= 0) return "needs a periodic patch and a coherence window";
  const std::optional<HeightGrid> hg = heightGridOf(g);
  if (!hg) return "needs a heightfield geometry (gaussian, noise, flat or heightmap)";
  const double texel = std::max(g.sizeX / hg->nx, g.sizeY / hg->ny), maxTexel = fourierMaxTexel(material, lambda_um);
  const int r = fourierRefinement(texel, maxTexel);
  const double cells = double(hg->nx) * hg->ny * double(r) * double(r);
  if (cells > double(kMaxFourierCells) || texel / r > maxTexel)
    return "would need " + std::to_string(static_cast<long long>(hg->nx) * r) + " x " +
           std::to_string(static_cast<long long>(hg->ny) * r) + " texels (texels split " + std::to_string(r) + " x " +
           std::to_string(r) + " for the shortest wavelength), above its limit of 2^22";
  if (orderLobesSeparate(sigma, g.sizeX, g.sizeY)) return "";
  if (masked) return "with a coherence length below 12 L / π does not model the masked field (the lost component)";
  return "";
}

std::unique_ptr<WaveEstimator> makeFftWaveEstimator(const WaveContext& ctx) {
  const std::string why = fftUnsuitable(ctx.geometry, ctx.material, ctx.lambda_um,
                                        ctx.window.active() ? ctx.window.sigma() : 0.0, ctx.settings.computeMasked);
  if (!why.empty() || !ctx.scene.periodic())
    throw std::invalid_argument("the fft estimator " + (why.empty() ? "needs a periodic patch" : why));
  if (orderLobesSeparate(ctx.window.sigma(), ctx.scene.sizeX(), ctx.scene.sizeY()))
    return std::make_unique<OrdersWaveEstimator>(ctx, OrderAmplitudes::Fourier);
  return std::make_unique<FftSpeckleEstimator>(ctx);
}

}  // namespace mbsdf
