#include "geometry/topography_conditioning.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace mbsdf {

std::string ConditioningReport::describe() const {
  std::string s = fmt::format("{} x {} texels meshed", nx, ny);
  if (filled)
    s += fmt::format(", {} unmeasured points ({:.3g} %) filled by Laplace interpolation", filled, 100 * filledFraction);
  if (removedForm_um > 0)
    s += fmt::format(", levelled (tilt {:.3g}°, form {:.3g} µm rms removed)", removedTilt_deg, removedForm_um);
  return s;
}

Levelling parseLevelling(const std::string& s, const std::string& where) {
  if (s == "none") return Levelling::None;
  if (s == "plane") return Levelling::Plane;
  if (s == "polynomial") return Levelling::Polynomial;
  throw InputError(where + ": unknown levelling '" + s + "' (none, plane, polynomial)");
}
EdgeTreatment parseEdgeTreatment(const std::string& s, const std::string& where) {
  if (s == "wrap") return EdgeTreatment::Wrap;
  if (s == "mirror") return EdgeTreatment::Mirror;
  if (s == "window") return EdgeTreatment::Window;
  throw InputError(where + ": unknown edge treatment '" + s + "' (wrap, mirror, window)");
}
std::string toString(Levelling l) {
  return l == Levelling::None ? "none" : l == Levelling::Plane ? "plane" : "polynomial";
}
std::string toString(EdgeTreatment e) {
  return e == EdgeTreatment::Wrap ? "wrap" : e == EdgeTreatment::Mirror ? "mirror" : "window";
}

namespace {

Topography cropped(const Topography& t, const std::array<int, 4>& c, const std::string& where) {
  const auto [i0, j0, w, h] = c;
  if (i0 < 0 || j0 < 0 || w < 2 || h < 2 || int64_t(i0) + w > t.nx || int64_t(j0) + h > t.ny)
    throw InputError(where + ": crop [" + std::to_string(i0) + ", " + std::to_string(j0) + ", " + std::to_string(w) +
                     ", " + std::to_string(h) + "] is not inside the " + std::to_string(t.nx) + " x " +
                     std::to_string(t.ny) + " grid of " + t.source + " (at least 2 x 2 texels)");
  Topography out;
  out.nx = w;
  out.ny = h;
  out.dx_um = t.dx_um;
  out.dy_um = t.dy_um;
  out.source = t.source;
  out.z_um.resize(out.size());
  if (!t.valid.empty()) out.valid.resize(out.size());
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const size_t from = size_t(j0 + j) * t.nx + (i0 + i), to = size_t(j) * w + i;
      out.z_um[to] = t.z_um[from];
      if (!t.valid.empty()) out.valid[to] = t.valid[from];
    }
  if (out.invalidCount() == 0) out.valid.clear();
  return out;
}

// Legendre polynomials P_0..P_n at u in [-1, 1]: an orthogonal basis keeps the normal equations of
// the fit well conditioned at every order.
void legendre(double u, int n, double* p) {
  p[0] = 1;
  if (n >= 1) p[1] = u;
  for (int k = 2; k <= n; ++k) p[k] = ((2 * k - 1) * u * p[k - 1] - (k - 1) * p[k - 2]) / k;
}

// Solves the symmetric positive definite system A x = b (n ≤ 28) by Gaussian elimination with
// partial pivoting; returns false when A is singular (too few measured points for the order).
bool solve(std::vector<double> a, std::vector<double> b, int n, std::vector<double>* x) {
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int r = c + 1; r < n; ++r)
      if (std::abs(a[r * n + c]) > std::abs(a[piv * n + c])) piv = r;
    if (!(std::abs(a[piv * n + c]) > 1e-12 * std::abs(a[0]))) return false;
    for (int k = 0; k < n; ++k) std::swap(a[c * n + k], a[piv * n + k]);
    std::swap(b[c], b[piv]);
    for (int r = c + 1; r < n; ++r) {
      const double f = a[r * n + c] / a[c * n + c];
      for (int k = c; k < n; ++k) a[r * n + k] -= f * a[c * n + k];
      b[r] -= f * b[c];
    }
  }
  x->assign(n, 0.0);
  for (int r = n - 1; r >= 0; --r) {
    double s = b[r];
    for (int k = r + 1; k < n; ++k) s -= a[r * n + k] * (*x)[k];
    (*x)[r] = s / a[r * n + r];
  }
  return true;
}

}  // namespace

void removePolynomial(Topography& t, int order, ConditioningReport* report) {
  // Terms P_a(u) P_b(v) with a + b <= order, u and v the grid's coordinates mapped to [-1, 1].
  std::vector<std::array<int, 2>> terms;
  for (int d = 0; d <= order; ++d)
    for (int a = d; a >= 0; --a) terms.push_back({a, d - a});
  const int n = int(terms.size());
  std::vector<double> pu(size_t(t.nx) * (order + 1)), pv(size_t(t.ny) * (order + 1));
  for (int i = 0; i < t.nx; ++i) legendre(2.0 * i / (t.nx - 1) - 1, order, &pu[size_t(i) * (order + 1)]);
  for (int j = 0; j < t.ny; ++j) legendre(2.0 * j / (t.ny - 1) - 1, order, &pv[size_t(j) * (order + 1)]);
  auto basis = [&](int i, int j, int k) {
    return pu[size_t(i) * (order + 1) + terms[k][0]] * pv[size_t(j) * (order + 1) + terms[k][1]];
  };
  std::vector<double> ata(size_t(n) * n, 0.0), atz(n, 0.0), phi(n);
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) {
      const size_t k = size_t(j) * t.nx + i;
      if (!t.isValid(k)) continue;
      for (int r = 0; r < n; ++r) phi[r] = basis(i, j, r);
      for (int r = 0; r < n; ++r) {
        atz[r] += phi[r] * t.z_um[k];
        for (int c = 0; c < n; ++c) ata[size_t(r) * n + c] += phi[r] * phi[c];
      }
    }
  std::vector<double> coef;
  if (!solve(ata, atz, n, &coef))
    throw InputError(t.source + ": too few measured points to fit a polynomial of order " + std::to_string(order));
  double removed2 = 0;
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) {
      double p = 0;
      for (int r = 1; r < n; ++r) p += coef[r] * basis(i, j, r);  // the constant stays: heights keep their level
      t.z_um[size_t(j) * t.nx + i] -= p;
      removed2 += p * p;
    }
  if (report) {
    // Terms 1 and 2 are P_1(u) = u and P_1(v) = v: the plane's slopes per µm.
    const double sx = order >= 1 ? coef[1] * 2 / ((t.nx - 1) * t.dx_um) : 0;
    const double sy = order >= 1 ? coef[2] * 2 / ((t.ny - 1) * t.dy_um) : 0;
    report->removedTilt_deg = std::atan(std::hypot(sx, sy)) * 180 / M_PI;
    report->removedForm_um = std::sqrt(removed2 / double(t.size()));
  }
}

void fillInvalidPoints(Topography& t, ConditioningReport* report) {
  std::vector<size_t> holes;
  double mean = 0;
  size_t measured = 0;
  for (size_t k = 0; k < t.size(); ++k)
    if (t.isValid(k)) {
      mean += t.z_um[k];
      ++measured;
    } else {
      holes.push_back(k);
    }
  if (report) {
    report->filled = holes.size();
    report->filledFraction = double(holes.size()) / double(t.size());
  }
  if (holes.empty()) return;
  if (measured == 0) throw InputError(t.source + ": no point of the height map was measured");
  mean /= double(measured);
  for (size_t k : holes) t.z_um[k] = mean;
  // Successive over-relaxation of Laplace's equation on the holes, the measured points fixed and the
  // grid's border a mirror (zero normal derivative); deterministic order, so the result is too.
  double lo = 1e300, hi = -1e300;
  for (size_t k = 0; k < t.size(); ++k)
    if (t.isValid(k)) lo = std::min(lo, t.z_um[k]), hi = std::max(hi, t.z_um[k]);
  const double tol = 1e-10 * std::max(hi - lo, 1e-12);
  const double omega = 1.9;
  int sweep = 0;
  for (; sweep < 100000; ++sweep) {
    double change = 0;
    for (size_t k : holes) {
      const int i = int(k % t.nx), j = int(k / t.nx);
      double s = 0;
      int m = 0;
      for (auto [di, dj] : {std::array{-1, 0}, std::array{1, 0}, std::array{0, -1}, std::array{0, 1}}) {
        const int ii = i + di, jj = j + dj;
        if (ii < 0 || jj < 0 || ii >= t.nx || jj >= t.ny) continue;
        s += t.z_um[size_t(jj) * t.nx + ii];
        ++m;
      }
      const double next = t.z_um[k] + omega * (s / m - t.z_um[k]);
      change = std::max(change, std::abs(next - t.z_um[k]));
      t.z_um[k] = next;
    }
    if (change <= tol) break;
  }
  if (report) report->fillSweeps = sweep + 1;
  t.valid.clear();
}

namespace {

Topography mirrored(const Topography& t) {
  Topography out = t;
  out.nx = 2 * (t.nx - 1);
  out.ny = 2 * (t.ny - 1);
  out.z_um.resize(out.size());
  auto fold = [](int i, int n) { return i < n ? i : 2 * (n - 1) - i; };
  for (int j = 0; j < out.ny; ++j)
    for (int i = 0; i < out.nx; ++i)
      out.z_um[size_t(j) * out.nx + i] = t.z_um[size_t(fold(j, t.ny)) * t.nx + fold(i, t.nx)];
  return out;
}

void windowed(Topography& t, double fraction, const std::string& where) {
  if (!(fraction > 0 && fraction <= 0.5)) throw InputError(where + ": window_fraction must be in (0, 0.5]");
  double mean = 0;
  for (double z : t.z_um) mean += z;
  mean /= double(t.size());
  // Tukey window: 1 inside, a half cosine over `fraction` of the side at each end, 0 on the edge.
  auto taper = [fraction](int i, int n) {
    const double x = double(i) / (n - 1), w = fraction;
    const double d = std::min(x, 1 - x);
    return d >= w ? 1.0 : 0.5 * (1 - std::cos(M_PI * d / w));
  };
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) {
      double& z = t.z_um[size_t(j) * t.nx + i];
      z = mean + taper(i, t.nx) * taper(j, t.ny) * (z - mean);
    }
}

}  // namespace

Topography conditionTopography(Topography t, const TopographyConditioning& c, const std::string& where,
                               ConditioningReport* report) {
  ConditioningReport local;
  if (!report) report = &local;
  if (c.crop) t = cropped(t, *c.crop, where);
  if (c.level != Levelling::None) {
    if (c.levelOrder < 1 || c.levelOrder > 6) throw InputError(where + ": level_order must be 1 to 6");
    removePolynomial(t, c.level == Levelling::Plane ? 1 : c.levelOrder, report);
  }
  fillInvalidPoints(t, report);
  if (c.edges == EdgeTreatment::Mirror) t = mirrored(t);
  if (c.edges == EdgeTreatment::Window) windowed(t, c.windowFraction, where);
  report->nx = t.nx;
  report->ny = t.ny;
  return t;
}

}  // namespace mbsdf
