#include "scattering/paper_estimator.h"

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
constexpr uint32_t kPaperStream = 0x9A9E5;
}

WaveTileResult PaperWaveEstimator::run(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                                       const std::vector<uint8_t>& exitMask) const {
  const int tile = request.tile, incidenceBin = request.incidenceBin;
  const std::optional<Vec3>& exactDirection = request.exactDirection;
  auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = ctx_.grid;
  const PeriodicScene& scene = ctx_.scene;
  const CoherenceWindow& window = ctx_.window;
  const int nL = int(ctx_.lambda_um.size()), nB = grid.binCount();
  const int P = std::max(2, ctx_.settings.samplesPerBin);
  const bool masked = ctx_.settings.computeMasked;
  // One incidence direction for the whole slice (Appendix A).
  Sampler s0(ctx_.settings.seed, uint32_t(tile), 0, kPaperStream);
  const Vec3 wi = exactDirection ? normalize(*exactDirection) : grid.sampleCosine(incidenceBin, s0).w;
  const bool fromAbove = wi.z >= 0;
  const double cosI = std::abs(wi.z);
  const wave::Media media(ctx_);
  const std::vector<int> bins = wave::exitBins(grid, fromAbove, !media.conductor(), masked, exitMask);
  const double Lx = scene.sizeX(), Ly = scene.sizeY(), sigma = window.sigma();

  WaveTileResult r(nL, nB, masked);
  r.computed = exitMask;
  std::atomic<uint64_t> rays{0};

  auto doBin = [&](int b) {
    Sampler s(ctx_.settings.seed, uint32_t(tile), uint64_t(b) + 1, kPaperStream);
    std::vector<Complex> sv(2 * nL), sm(2 * nL);
    std::vector<double> qv(2 * nL), qm(2 * nL);
    uint64_t localRays = 0;
    for (int pass = 0; pass < P; ++pass) {
      // Footprint point u on the plane; under a window it follows the window (pdf ∝ w).
      double ux, uy, pdfU;
      if (window.active()) {
        double a = std::max(s.get1D(), 1e-300), c = s.get1D();
        double rr = sigma * std::sqrt(-2 * std::log(a));
        ux = rr * std::cos(2 * kPi * c);
        uy = rr * std::sin(2 * kPi * c);
        pdfU = window.amplitude(ux, uy) / (2 * kPi * sigma * sigma);
      } else {
        ux = (s.get1D() - 0.5) * Lx;
        uy = (s.get1D() - 0.5) * Ly;
        pdfU = 1.0 / (Lx * Ly);
      }
      Vec3 wo = grid.sampleUniform(b, s).w;
      // Map u into the base patch (periodic copies) and trace to the first surface point.
      double shiftX = 0, shiftY = 0;
      if (scene.periodic()) {
        shiftX = std::floor(ux / Lx + 0.5) * Lx;
        shiftY = std::floor(uy / Ly + 0.5) * Ly;
      }
      const double zStart = fromAbove ? scene.zTop() : scene.zBottom();
      Vec3 o{ux - shiftX, uy - shiftY, zStart};
      if (!scene.periodic()) o = Vec3{ux, uy, scene.zMean()} + wi * ((zStart - scene.zMean()) / wi.z);
      ++localRays;
      TraceResult hit = scene.trace(o, -wi);
      if (hit.kind != TraceResult::Kind::Hit) continue;
      const Vec3 m = fromAbove ? hit.n : -hit.n;
      const double cosLocal = dot(m, wi);
      if (cosLocal <= 0) continue;
      const bool transmission = wave::isTransmission(media.conductor(), fromAbove, wo);
      const ExitVisibility vis = wave::visibleExit(scene, hit.p, m, wo, hit.prim, fromAbove, transmission, &localRays);
      if (vis == ExitVisibility::BackFacing || (vis == ExitVisibility::Blocked && !masked)) continue;
      const bool visible = vis == ExitVisibility::Visible;
      // Surface pdf of the traced point: pdf_u |m·ωi| / |n·ωi| (projection along ωi).
      const double jac = cosI / (cosLocal * pdfU);
      const double px = hit.p.x + shiftX, py = hit.p.y + shiftY;
      const double w = window.amplitude(px, py);
      auto& S = visible ? sv : sm;
      auto& Q = visible ? qv : qm;
      for (int l = 0; l < nL; ++l) {
        const double k0 = 2 * kPi / ctx_.lambda_um[l];
        KirchhoffValue kv = wave::integrandAt(media, l, hit.p, m, wi, wo, k0, fromAbove, transmission);
        const Complex wgt = jac * w * std::polar(1.0, kv.qx * shiftX + kv.qy * shiftY);
        const Complex xs = kv.s * wgt, xp = kv.p * wgt;
        S[2 * l] += xs;
        S[2 * l + 1] += xp;
        Q[2 * l] += std::norm(xs);
        Q[2 * l + 1] += std::norm(xp);
      }
    }
    const double toF = grid.solidAngle(b) / grid.projectedSolidAngle(b);
    auto reduce = [&](const std::vector<Complex>& S, const std::vector<double>& Q, std::vector<double>& f,
                      std::vector<double>& e, bool transmissionBin) {
      for (int l = 0; l < nL; ++l) {
        const double nI = media.incident(l, fromAbove), nO = transmissionBin ? media.other(l, fromAbove) : nI;
        const double scale = kirchhoffPowerScale(window.w2(), cosI, nI, nO) * toF;
        double mean2 = 0.5 * (std::norm(S[2 * l] / double(P)) + std::norm(S[2 * l + 1] / double(P)));
        double var = 0.5 * (Q[2 * l] + Q[2 * l + 1]) / P - mean2;
        f[size_t(l) * nB + b] = mean2 * scale;                   // |mean|² (biased, as in the paper)
        e[size_t(l) * nB + b] = std::max(0.0, var) / P * scale;  // its bias Var/P
      }
    };
    const bool tBin = !media.conductor() && grid.isUpper(b) != fromAbove;
    reduce(sv, qv, r.fws, r.fwsErr, tBin);
    if (masked) reduce(sm, qm, r.pmsk, r.pmskErr, tBin);
    rays += localRays;
  };

  constexpr size_t kBatch = 512;
  for (size_t b0 = 0; b0 < bins.size(); b0 += kBatch) {
    size_t b1 = std::min(bins.size(), b0 + kBatch);
    tbb::parallel_for(b0, b1, [&](size_t i) { doBin(bins[i]); });
    throwIfStopped();
    if (progress) progress(uint64_t(b1) * uint64_t(P));
  }
  r.samples = uint64_t(bins.size()) * uint64_t(P);
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace mbsdf
