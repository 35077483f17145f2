#include "geometry/topography_stats.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/fftw.h"

namespace mbsdf {

namespace {

// The shortest lag at which the circular autocorrelation of the heights falls to 0.2 of its value at
// zero lag (Wiener–Khinchin: the inverse transform of |Z(k)|²).
double autocorrelationLength(const Topography& t, double mean) {
  const int nx = t.nx, ny = t.ny, nxc = nx / 2 + 1;
  auto real = fftw::allocate<double>(t.size());
  auto spec = fftw::allocate<fftw_complex>(size_t(ny) * nxc);
  fftw::Plan fwd, inv;
  {
    std::lock_guard<std::mutex> lock(fftw::planMutex());
    fwd.reset(fftw_plan_dft_r2c_2d(ny, nx, real.get(), spec.get(), FFTW_ESTIMATE));
    inv.reset(fftw_plan_dft_c2r_2d(ny, nx, spec.get(), real.get(), FFTW_ESTIMATE));
  }
  for (size_t k = 0; k < t.size(); ++k) real.get()[k] = t.z_um[k] - mean;
  fftw_execute(fwd.get());
  for (size_t k = 0; k < size_t(ny) * nxc; ++k) {
    double* c = spec.get()[k];
    c[0] = c[0] * c[0] + c[1] * c[1];
    c[1] = 0;
  }
  fftw_execute(inv.get());
  const double acf0 = real.get()[0];
  if (!(acf0 > 0)) return 0;
  double best = std::hypot(nx * t.dx_um, ny * t.dy_um);  // never falls to 0.2: the patch's size bounds it
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      if (real.get()[size_t(j) * nx + i] > 0.2 * acf0) continue;
      const double lx = std::min(i, nx - i) * t.dx_um, ly = std::min(j, ny - j) * t.dy_um;
      best = std::min(best, std::hypot(lx, ly));
    }
  return best;
}

double percentile(std::vector<double>& v, double q) {
  const size_t k = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

}  // namespace

TopographyStats topographyStats(const Topography& t, bool withSal) {
  TopographyStats s;
  s.nx = t.nx;
  s.ny = t.ny;
  s.dx_um = t.dx_um;
  s.dy_um = t.dy_um;
  const double n = double(t.size());
  double mean = 0, lo = 1e300, hi = -1e300;
  for (double z : t.z_um) mean += z, lo = std::min(lo, z), hi = std::max(hi, z);
  mean /= n;
  double m2 = 0, m3 = 0, m4 = 0, a = 0;
  for (double z : t.z_um) {
    const double d = z - mean;
    a += std::abs(d);
    m2 += d * d;
    m3 += d * d * d;
    m4 += d * d * d * d;
  }
  s.Sq_um = std::sqrt(m2 / n);
  s.Sa_um = a / n;
  s.Sz_um = hi - lo;
  s.Ssk = m2 > 0 ? (m3 / n) / std::pow(m2 / n, 1.5) : 0;
  s.Sku = m2 > 0 ? (m4 / n) / ((m2 / n) * (m2 / n)) : 0;

  // Slopes of the periodic mesh's texels; the wrap's steps and the inside ones kept apart.
  std::vector<double> angles;
  angles.reserve(t.size());
  double grad2 = 0, seamX = 0, seamY = 0, insideX = 0, insideY = 0;
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) {
      const double z = t.z_um[size_t(j) * t.nx + i];
      const double zx = t.z_um[size_t(j) * t.nx + (i + 1) % t.nx] - z;
      const double zy = t.z_um[size_t((j + 1) % t.ny) * t.nx + i] - z;
      (i + 1 == t.nx ? seamX : insideX) += zx * zx;
      (j + 1 == t.ny ? seamY : insideY) += zy * zy;
      const double gx = zx / t.dx_um, gy = zy / t.dy_um;
      grad2 += gx * gx + gy * gy;
      angles.push_back(std::atan(std::sqrt(gx * gx + gy * gy)) * 180 / M_PI);
    }
  s.Sdq = std::sqrt(grad2 / n);
  auto seamRatio = [](double seam, double nSeam, double inside, double nInside) {
    const double in = inside / nInside;
    return in > 0 ? std::sqrt((seam / nSeam) / in) : (seam > 0 ? INFINITY : 1.0);
  };
  s.seamRatioX = seamRatio(seamX, t.ny, insideX, double(t.ny) * (t.nx - 1));
  s.seamRatioY = seamRatio(seamY, t.nx, insideY, double(t.nx) * (t.ny - 1));
  s.slope_deg[0] = percentile(angles, 0.5);
  s.slope_deg[1] = percentile(angles, 0.9);
  s.slope_deg[2] = percentile(angles, 0.99);
  s.slope_deg[3] = *std::max_element(angles.begin(), angles.end());
  if (withSal) s.Sal_um = autocorrelationLength(t, mean);
  return s;
}

std::string TopographyStats::describe(double lambdaMin_um) const {
  std::string out = fmt::format(
      "  topography {} x {} texels of {:.4g} x {:.4g} µm: Sq {:.4g} µm, Sa {:.4g} µm, Sz {:.4g} µm, Ssk {:.3g}, "
      "Sku {:.3g}, Sdq {:.3g}, Sal {:.4g} µm\n"
      "  slope angles: median {:.3g}°, 90 % {:.3g}°, 99 % {:.3g}°, max {:.3g}°\n",
      nx, ny, dx_um, dy_um, Sq_um, Sa_um, Sz_um, Ssk, Sku, Sdq, Sal_um, slope_deg[0], slope_deg[1], slope_deg[2],
      slope_deg[3]);
  // The finest period the grid holds is two texels; at normal incidence it scatters light to
  // sin θ = λ / (2 texel). Structure finer than the texel (which the instrument did not resolve)
  // would scatter beyond that angle, and is missing from the table.
  const double texel = std::max(dx_um, dy_um);
  const double sinMax = lambdaMin_um / (2 * texel);
  if (sinMax >= 1)
    out += fmt::format(
        "  the texel ({:.4g} µm) resolves every period that scatters λ = {:.4g} µm into the "
        "hemisphere at normal incidence\n",
        texel, lambdaMin_um);
  else
    out += fmt::format(
        "  the texel ({:.4g} µm) resolves the scatter of λ = {:.4g} µm only out to θ = {:.3g}° at "
        "normal incidence: structure finer than 2 texels, if the surface has it, is missing beyond\n",
        texel, lambdaMin_um, std::asin(sinMax) * 180 / M_PI);
  out += fmt::format(
      "  periodic edges: the step across the wrap is {:.3g} (x) and {:.3g} (y) times the steps inside{}\n", seamRatioX,
      seamRatioY,
      seamStands() ? " — the seam is a ridge of the surface; edges = \"mirror\" or \"window\" removes it" : "");
  return out;
}

}  // namespace mbsdf
