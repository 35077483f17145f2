#include "scattering/heightfield_spectrum.h"

#include <tbb/info.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include "core/fftw.h"

namespace mbsdf {

namespace {
// Offsets of the two facet lattices in texels: the triangles (i,j)(i+1,j)(i+1,j+1) and
// (i,j)(i+1,j+1)(i,j+1) of heightfieldMesh.
constexpr double kLatticeOffset[2][2] = {{2.0 / 3.0, 1.0 / 3.0}, {1.0 / 3.0, 2.0 / 3.0}};
constexpr double kInterpolationError = 1e-7;  // relative, on the amplitude
}  // namespace

double indexSum(const Material& material, double lambda_um) {
  const double reflection = 2 * material.outsideIor;
  return material.isConductor() ? reflection
                                : std::max(reflection, material.outsideIor + material.ior(lambda_um).real());
}

double fourierMaxTexel(const Material& material, const std::vector<double>& lambda_um) {
  double texel = 1e300;
  for (double l : lambda_um) texel = std::min(texel, l / (kFourierTexelsPerPeriod * indexSum(material, l)));
  return texel;
}

int fourierRefinement(double texel, double maxTexel) {
  int r = 1;
  while (maxTexel > 0 && texel / r > maxTexel && r < (1 << 16)) r *= 2;
  return r;
}

HeightfieldSpectrum::HeightfieldSpectrum(const Microgeometry& g, const HeightGrid& grid, const PeriodicScene& scene,
                                         double maxTexel_um)
    : scene_(scene), sizeX_(g.sizeX), sizeY_(g.sizeY) {
  if (g.triangles.size() != 2 * size_t(grid.nx) * size_t(grid.ny)) throw std::invalid_argument("heightfield layout");
  // Refinement: each texel split into r x r with the heights of the same planar facets, so the
  // surface is unchanged and only the one-point rule gets finer.
  refine_ = fourierRefinement(std::max(g.sizeX / grid.nx, g.sizeY / grid.ny), maxTexel_um);
  const int r = refine_;
  nx_ = grid.nx * r;
  ny_ = grid.ny * r;
  auto h0 = [&](int i, int j) {
    return grid.h[size_t((j % grid.ny + grid.ny) % grid.ny) * grid.nx + size_t((i % grid.nx + grid.nx) % grid.nx)];
  };
  // Height of the refined vertex (I, J): on the original triangle that contains it.
  auto height = [&](int I, int J) {
    const int i = I / r, j = J / r;
    const double fu = double(I % r) / r, fv = double(J % r) / r;
    const double a = h0(i, j), b = h0(i + 1, j), c = h0(i + 1, j + 1), d = h0(i, j + 1);
    return fv <= fu ? a + fu * (b - a) + fv * (c - b) : a + fv * (d - a) + fu * (c - d);
  };
  const double dx = g.sizeX / nx_, dy = g.sizeY / ny_;
  const size_t n = 2 * size_t(nx_) * size_t(ny_);
  centroid_.resize(n);
  normal_.resize(n);
  area_.resize(n);
  parent_.resize(n);
  double zMin = 1e300, zMax = -1e300;
  for (int J = 0; J < ny_; ++J)
    for (int I = 0; I < nx_; ++I) {
      const Vec3 v00{-g.sizeX / 2 + I * dx, -g.sizeY / 2 + J * dy, height(I, J)};
      const Vec3 v10{v00.x + dx, v00.y, height(I + 1, J)}, v11{v00.x + dx, v00.y + dy, height(I + 1, J + 1)},
          v01{v00.x, v00.y + dy, height(I, J + 1)};
      const int si = I % r, sj = J % r;
      for (int o = 0; o < 2; ++o) {
        const size_t t = 2 * (size_t(J) * nx_ + I) + size_t(o);
        const Vec3 b = o ? v11 : v10, c = o ? v01 : v11;
        centroid_[t] = (v00 + b + c) * (1.0 / 3.0);
        const Vec3 N = cross(b - v00, c - v00);  // length 2A, facing up (counter-clockwise as heightfieldMesh)
        area_[t] = N * 0.5;
        normal_[t] = normalize(N);
        // The original facet: below the sub-cell diagonal (si > sj) lies in triangle 0, above in 1.
        const int po = si > sj ? 0 : si < sj ? 1 : o;
        parent_[t] = uint32_t(2 * (size_t(J / r) * grid.nx + size_t(I / r)) + size_t(po));
        zMin = std::min(zMin, centroid_[t].z);
        zMax = std::max(zMax, centroid_[t].z);
        maxSlope_ = std::max(maxSlope_, std::hypot(N.x, N.y) / N.z);
      }
    }
  zc_ = 0.5 * (zMin + zMax);
  zHalf_ = 0.5 * (zMax - zMin);
  // Children of each original triangle (counting sort by parent).
  childStart_.assign(g.triangles.size() + 1, 0);
  for (uint32_t p : parent_) ++childStart_[p + 1];
  for (size_t p = 0; p < g.triangles.size(); ++p) childStart_[p + 1] += childStart_[p];
  children_.resize(n);
  std::vector<uint32_t> next(childStart_.begin(), childStart_.end() - 1);
  for (size_t t = 0; t < n; ++t) children_[next[parent_[t]]++] = uint32_t(t);
  const size_t cells = size_t(nx_) * ny_;
  auto scratch = fftw::allocate<fftw_complex>(cells);
  std::lock_guard<std::mutex> lock(fftw::planMutex());
  // FFTW_ESTIMATE: the plan (and so every rounding) depends only on the sizes, never on timings as
  // FFTW_MEASURE's would, so all ranks and runs compute identical tables (determinism).
  rowPlan_.reset(fftw_plan_many_dft(1, &nx_, ny_, scratch.get(), nullptr, 1, nx_, scratch.get(), nullptr, 1, nx_,
                                    FFTW_BACKWARD, FFTW_ESTIMATE));
}

fftw_plan HeightfieldSpectrum::columnPlan(int columns) const {
  std::lock_guard<std::mutex> lock(columnPlanMutex_);
  fftw::Plan& p = columnPlans_[columns];
  if (!p) {
    auto scratch = fftw::allocate<fftw_complex>(size_t(columns) * size_t(ny_));
    std::lock_guard<std::mutex> planLock(fftw::planMutex());
    p.reset(fftw_plan_many_dft(1, &ny_, columns, scratch.get(), nullptr, 1, ny_, scratch.get(), nullptr, 1, ny_,
                               FFTW_BACKWARD, FFTW_ESTIMATE));
  }
  return p.get();
}

double HeightfieldSpectrum::memoryBytes() const {
  const double facetsN = double(facets()), cells = double(nx_) * ny_;
  const double facetData = facetsN * (3 * sizeof(Vec3) + 3 * sizeof(uint32_t));
  const double fields = facetsN * 8 * sizeof(Complex) + facetsN * sizeof(Complex) + facetsN;  // + phases + lit
  const double buffers = double(tbb::info::default_concurrency()) * 2 * cells * sizeof(Complex);
  return facetData + fields + buffers;
}

std::vector<uint8_t> HeightfieldSpectrum::lit(const Vec3& wi, bool fromAbove, uint64_t* rays) const {
  std::vector<uint8_t> v(facets(), 0);
  std::atomic<uint64_t> count{0};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, facets()), [&](const tbb::blocked_range<size_t>& r) {
    uint64_t local = 0;
    for (size_t t = r.begin(); t < r.end(); ++t) {
      const Vec3 m = fromAbove ? normal_[t] : -normal_[t];
      if (dot(m, wi) <= 0) continue;
      ++local;
      v[t] = wave::escapes(scene_, centroid_[t], m, wi, parent_[t], fromAbove);
    }
    count += local;
  });
  *rays += count.load();
  return v;
}

HeightfieldSpectrum::FacetFields HeightfieldSpectrum::fields(const Vec3& wi, bool fromAbove, int l, double k0,
                                                             double nI, double nO, bool transmission,
                                                             const wave::Media& media,
                                                             const std::vector<uint8_t>& lit) const {
  FacetFields f;
  f.cells = facets() / 2;
  for (auto& v : f.v) v.assign(facets(), 0.0);
  const Vec3 k1 = wi * (-nI * k0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, facets()), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t < r.end(); ++t) {
      if (!lit[t]) continue;
      const Vec3 m = fromAbove ? normal_[t] : -normal_[t];
      const Vec3 a = fromAbove ? area_[t] : -area_[t];  // m A
      const FresnelAmplitudes F = media.fresnel(l, dot(m, wi), fromAbove);
      auto set = [&](int pol, Complex x, Complex b) {
        f.at(pol * 4, t) = x;
        f.at(pol * 4 + 1, t) = b * a.x;
        f.at(pol * 4 + 2, t) = b * a.y;
        f.at(pol * 4 + 3, t) = b * a.z;
      };
      if (!transmission) {
        // g A = (r − 1)(a·k1) − (r + 1)(a·k2)   (kirchhoff.h, reflection)
        const double ak1 = dot(a, k1);
        set(0, (F.rs - 1.0) * ak1, -(F.rs + 1.0));
        set(1, (F.rp - 1.0) * ak1, -(F.rp + 1.0));
      } else {
        // g A = t (kt·m) A + t (a·k2)   (kirchhoff.h, transmission; total internal reflection: 0)
        const double k1m = dot(k1, m);
        const double rad = nO * k0 * nO * k0 - nI * k0 * nI * k0 + k1m * k1m;
        if (rad < 0) continue;
        const double ktmA = -std::sqrt(rad) * length(a);
        set(0, F.ts * ktmA, F.ts);
        set(1, F.tp * ktmA, F.tp);
      }
    }
  });
  return f;
}

HeightfieldSpectrum::QzNodes HeightfieldSpectrum::qzNodes(double qzMin, double qzMax) const {
  // Chebyshev points of the first kind; interpolating e^{i c t} on [−1, 1] with N of them errs by
  // at most c^N / (2^{N−1} N!) (c = Q · max|z − z̄|).
  QzNodes nodes;
  nodes.zc = zc_;
  const double Q = 0.5 * std::max(0.0, qzMax - qzMin), qm = 0.5 * (qzMin + qzMax), c = Q * zHalf_;
  int N = 1;
  for (double bound = c; N < 200 && bound >= kInterpolationError;) bound *= c / (2.0 * ++N);
  for (int n = 0; n < N; ++n) {
    const double th = (2 * n + 1) * kPi / (2 * N);
    nodes.q.push_back(qm + Q * std::cos(th));
    nodes.bw.push_back((n % 2 ? -1.0 : 1.0) * std::sin(th));
  }
  return nodes;
}

HeightfieldSpectrum::QzNodes::State HeightfieldSpectrum::QzNodes::state(double qz) const {
  State s;
  s.qz = qz;
  s.phase = std::polar(1.0, qz * zc);
  for (size_t n = 0; n < q.size(); ++n)
    if (std::abs(qz - q[n]) <= 1e-14 * (1 + std::abs(qz))) {  // on a node
      s.hit = int(n);
      return s;
    }
  for (size_t n = 0; n < q.size(); ++n) s.sum += bw[n] / (qz - q[n]);
  return s;
}

void HeightfieldSpectrum::QzNodes::weights(double qz, Complex* w) const {
  const State s = state(qz);
  for (size_t n = 0; n < q.size(); ++n) w[n] = weight(n, s);
}

void HeightfieldSpectrum::nodeTables(const FacetFields& f, double qn, long a0, long a1, long b0, long b1,
                                     std::vector<Complex>* out) const {
  const long na = a1 - a0 + 1, nb = b1 - b0 + 1;
  out->assign(size_t(8 * na * nb), 0.0);
  const size_t cells = size_t(nx_) * ny_;
  // Phase factors of the lattices: e^{i G·c} = (−1)^a e^{2πi a (i + ox)/nx} (−1)^b e^{2πi b (j + oy)/ny}
  // for a centroid at x = −Lx/2 + (i + ox) Lx/nx; the FFT supplies the e^{2πi a i/nx} part.
  auto wrap = [](long k, int n) { return size_t(((k % n) + n) % n); };
  // e^{i q_n (z − z̄)} per facet, lattice by lattice, shared by the 8 transforms.
  std::vector<Complex> zPhase(facets());
  tbb::parallel_for(size_t(0), facets(),
                    [&](size_t t) { zPhase[(t & 1) * cells + t / 2] = std::polar(1.0, qn * (centroid_[t].z - zc_)); });
  // The columns (a mod nx) the orders need, in the order of a.
  const int columns = int(std::min<long>(na, nx_));
  const fftw_plan colPlan = columnPlan(columns);
  tbb::parallel_for(0, 8, [&](int task) {
    const Complex* F = f.v[size_t(task)].data();
    Scratch& sc = scratch_.local();
    if (!sc.grid) sc.grid = fftw::allocate<fftw_complex>(cells);
    if (sc.columnCapacity < size_t(columns) * ny_) {
      sc.columns = fftw::allocate<fftw_complex>(size_t(columns) * ny_);
      sc.columnCapacity = size_t(columns) * ny_;
    }
    Complex* data = reinterpret_cast<Complex*>(sc.grid.get());
    Complex* col = reinterpret_cast<Complex*>(sc.columns.get());
    Complex* dst = out->data() + size_t(task) * size_t(na * nb);
    for (int o = 0; o < 2; ++o) {
      const Complex* Fo = F + size_t(o) * cells;
      const Complex* zo = zPhase.data() + size_t(o) * cells;
      for (size_t c = 0; c < cells; ++c) data[c] = Fo[c] * zo[c];
      fftw_execute_dft(rowPlan_.get(), sc.grid.get(), sc.grid.get());
      for (int k = 0; k < columns; ++k) {
        const size_t ia = wrap(a0 + k, nx_);
        for (int j = 0; j < ny_; ++j) col[size_t(k) * ny_ + size_t(j)] = data[size_t(j) * nx_ + ia];
      }
      fftw_execute_dft(colPlan, sc.columns.get(), sc.columns.get());
      std::vector<Complex> pb(static_cast<size_t>(nb));
      for (long b = b0; b <= b1; ++b)
        pb[size_t(b - b0)] = std::polar(1.0, kPi * double(b) * (2 * kLatticeOffset[o][1] / ny_ - 1));
      for (long a = a0; a <= a1; ++a) {
        const Complex pa = std::polar(1.0, kPi * double(a) * (2 * kLatticeOffset[o][0] / nx_ - 1));
        const Complex* column = col + size_t((a - a0) % columns) * size_t(ny_);  // a and a + nx share a column
        Complex* row = dst + size_t(a - a0) * size_t(nb);
        for (long b = b0; b <= b1; ++b) row[b - b0] += pa * pb[size_t(b - b0)] * column[wrap(b, ny_)];
      }
    }
  });
}

std::array<Complex, 2> HeightfieldSpectrum::facetTerm(const FacetFields& f, size_t t, const Vec3& q,
                                                      const Vec3& k2) const {
  const Complex phase = std::polar(1.0, dot(q, centroid_[t]));
  auto term = [&](int pol) {
    return (f.at(pol * 4, t) + f.at(pol * 4 + 1, t) * k2.x + f.at(pol * 4 + 2, t) * k2.y +
            f.at(pol * 4 + 3, t) * k2.z) *
           phase;
  };
  return {term(0), term(1)};
}

}  // namespace mbsdf
