#include "geometry/random_field.h"

#include <cmath>
#include <complex>
#include <memory>

#include "core/fftw.h"
#include "core/rng.h"
#include "core/vecmath.h"

namespace mbsdf {
namespace {

// Stream ids of the geometry random numbers (distinct from the path tracer's tiles).
constexpr uint32_t kGeometryTile = 0xFFFFFF00u;

void normaliseRms(std::vector<double>& h, double rms) {
  double mean = 0;
  for (double v : h) mean += v;
  mean /= double(h.size());
  double s2 = 0;
  for (double& v : h) {
    v -= mean;
    s2 += v * v;
  }
  double cur = std::sqrt(s2 / double(h.size()));
  double scale = cur > 0 ? rms / cur : 0.0;
  for (double& v : h) v *= scale;
}

}  // namespace

std::vector<double> gaussianRandomField(int nx, int ny, double sizeX, double sizeY, double rms, double corr,
                                        uint64_t seed) {
  size_t n = size_t(nx) * ny;
  int nxc = nx / 2 + 1;
  auto real = fftw::allocate<double>(n);
  auto spec = fftw::allocate<fftw_complex>(size_t(ny) * nxc);
  // Plans are made before the data is written (FFTW_ESTIMATE does not touch the arrays).
  fftw::Plan fwd, inv;
  {
    std::lock_guard<std::mutex> lock(fftw::planMutex());
    fwd.reset(fftw_plan_dft_r2c_2d(ny, nx, real.get(), spec.get(), FFTW_ESTIMATE));
    inv.reset(fftw_plan_dft_c2r_2d(ny, nx, spec.get(), real.get(), FFTW_ESTIMATE));
  }
  Sampler rng(seed, kGeometryTile, 0);
  for (size_t i = 0; i < n; ++i) {
    // Box–Muller: white Gaussian noise.
    double u1 = std::max(rng.get1D(), 1e-300), u2 = rng.get1D();
    real.get()[i] = std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2);
  }
  fftw_execute(fwd.get());
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nxc; ++i) {
      double kx = 2 * kPi * i / sizeX;
      double ky = 2 * kPi * (j <= ny / 2 ? j : j - ny) / sizeY;
      double filt = std::exp(-(kx * kx + ky * ky) * corr * corr / 8.0);
      spec.get()[size_t(j) * nxc + i][0] *= filt;
      spec.get()[size_t(j) * nxc + i][1] *= filt;
    }
  fftw_execute(inv.get());
  std::vector<double> h(real.get(), real.get() + n);
  normaliseRms(h, rms);
  return h;
}

std::vector<double> sparseConvolutionNoise(int nx, int ny, double sizeX, double sizeY, double rms, double radius,
                                           double density, uint64_t seed) {
  Sampler rng(seed, kGeometryTile, 1);
  double kernelArea = kPi * radius * radius;
  // Poisson count with the requested mean (inverse-transform for small means, normal above).
  double mean = density * sizeX * sizeY / kernelArea;
  long count = 0;
  if (mean < 500) {
    double l = std::exp(-mean), p = 1.0;
    do {
      ++count;
      p *= rng.get1D();
    } while (p > l);
    --count;
  } else {
    double u1 = std::max(rng.get1D(), 1e-300), u2 = rng.get1D();
    count =
        std::max(0L, long(std::lround(mean + std::sqrt(mean) * std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2))));
  }
  std::vector<double> h(size_t(nx) * ny, 0.0);
  double dx = sizeX / nx, dy = sizeY / ny;
  int rx = int(std::ceil(radius / dx)), ry = int(std::ceil(radius / dy));
  for (long k = 0; k < count; ++k) {
    double px = rng.get1D() * sizeX, py = rng.get1D() * sizeY, w = 2 * rng.get1D() - 1;
    int ci = int(px / dx), cj = int(py / dy);
    for (int dj = -ry; dj <= ry; ++dj)
      for (int di = -rx; di <= rx; ++di) {
        int i = ci + di, j = cj + dj;
        double x = i * dx, y = j * dy;
        double r = std::hypot(x - px, y - py);
        if (r >= radius) continue;
        int ii = ((i % nx) + nx) % nx, jj = ((j % ny) + ny) % ny;
        h[size_t(jj) * nx + ii] += w * 0.5 * (1 + std::cos(kPi * r / radius));
      }
  }
  normaliseRms(h, rms);
  return h;
}

double periodicLookup(const std::vector<double>& h, int nx, int ny, double sizeX, double sizeY, double x, double y) {
  double fx = (x + sizeX / 2) / sizeX * nx, fy = (y + sizeY / 2) / sizeY * ny;
  double ix = std::floor(fx), iy = std::floor(fy);
  double tx = fx - ix, ty = fy - iy;
  auto at = [&](long i, long j) {
    long ii = ((i % nx) + nx) % nx, jj = ((j % ny) + ny) % ny;
    return h[size_t(jj) * nx + ii];
  };
  long i0 = long(ix), j0 = long(iy);
  return (1 - tx) * (1 - ty) * at(i0, j0) + tx * (1 - ty) * at(i0 + 1, j0) + (1 - tx) * ty * at(i0, j0 + 1) +
         tx * ty * at(i0 + 1, j0 + 1);
}

}  // namespace mbsdf
