#include "core/overloaded.h"
#include "core/direction_grid.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

#ifdef __SSE2__
#include <emmintrin.h>
#endif
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace mbsdf {
namespace {

// da / √(1 − r²) for two values of r² (NaN where r² > 1, which the caller skips): packed where
// the CPU has it, each lane rounded as the scalar operations round.
void inverseCosines(const double r2[2], double da, double out[2]) {
#ifdef __SSE2__
  const __m128d c = _mm_sub_pd(_mm_set1_pd(1.0), _mm_loadu_pd(r2));
  _mm_storeu_pd(out, _mm_div_pd(_mm_set1_pd(da), _mm_sqrt_pd(c)));
#else
  for (int l = 0; l < 2; ++l) out[l] = da / std::sqrt(1.0 - r2[l]);
#endif
}

// Disk pixel (i, j) covers x in [-1 + 2i/W, -1 + 2(i+1)/W], y likewise. Its projected solid
// angle is the area of (pixel ∩ unit disk); its solid angle is the integral of 1/cos theta over
// that area. Both are computed by midpoint quadrature on a sub-grid; the solid-angle integrand
// is integrable but singular at the rim, so the rim pixels use a finer sub-grid.
void diskPixelMeasures(const DiskGrid& g, int i, int j, double* omega, double* omegaProj, double* cx_, double* cy_) {
  double x0 = -1 + 2.0 * i / g.width, y0 = -1 + 2.0 * j / g.height;
  double dx = 2.0 / g.width, dy = 2.0 / g.height;
  // Corner test: fully inside, fully outside, or on the rim.
  double rmin2 = 1e9, rmax2 = 0;
  for (int c = 0; c < 4; ++c) {
    double x = x0 + dx * (c & 1), y = y0 + dy * (c >> 1);
    rmax2 = std::max(rmax2, x * x + y * y);
  }
  double cx = std::clamp(0.0, x0, x0 + dx), cy = std::clamp(0.0, y0, y0 + dy);
  rmin2 = cx * cx + cy * cy;
  *cx_ = x0 + dx / 2;
  *cy_ = y0 + dy / 2;
  if (rmin2 >= 1.0) {
    *omega = 0;
    *omegaProj = 0;
    return;
  }
  // Sub-grids of a power of two, so that dividing by `sub` is multiplying by 1/sub exactly.
  const int sub = rmax2 <= 1.0 ? 16 : 256;
  const double perSub = 1.0 / sub;
  double a = 0, s = 0, da = dx * dy / (double(sub) * sub), mx = 0, my = 0;
  for (int u = 0; u < sub; ++u) {
    const double x = x0 + dx * (u + 0.5) * perSub;
    for (int v = 0; v < sub; v += 2) {
      // Two sub-points at a time: their square roots and divisions side by side, each rounded as
      // alone, and the sums in the sub-points' order.
      double y[2], r2[2], term[2];
      for (int l = 0; l < 2; ++l) {
        y[l] = y0 + dy * (v + l + 0.5) * perSub;
        r2[l] = x * x + y[l] * y[l];
      }
      inverseCosines(r2, da, term);
      for (int l = 0; l < 2; ++l) {
        if (r2[l] >= 1.0) continue;
        a += da;
        s += term[l];
        mx += x * da;
        my += y[l] * da;
      }
    }
  }
  // Representative point: centroid of (pixel ∩ disk), which lies inside the disk.
  if (a > 0) {
    *cx_ = mx / a;
    *cy_ = my / a;
  }
  *omega = s;
  *omegaProj = a;
}

// A disk grid's pixel measures, computed once per size in a process: the job's parser, the
// planner, the writer's schema and the runner each build the job's grid, and the rim pixels' fine
// quadrature costs about 0.1 s of one core for 128 x 128. A grid asks for them when its measures
// are first needed (DirectionGrid::measures).
const GridMeasures& diskMeasures(const DiskGrid& g) {
  static std::mutex mutex;
  static std::map<std::pair<int, int>, std::unique_ptr<const GridMeasures>> cache;
  const std::lock_guard<std::mutex> lock(mutex);
  auto& slot = cache[{g.width, g.height}];
  if (slot) return *slot;
  auto m = std::make_unique<GridMeasures>();
  const size_t n = size_t(g.width) * size_t(g.height);
  m->omega.resize(n);
  m->omegaProj.resize(n);
  m->centre.resize(2 * n);
  // Rows in parallel; each pixel is computed alone, so the values do not depend on the threads.
  // Isolated: while it waits under the lock this thread must not pick up an outer task that could
  // build a grid and ask for the lock again.
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(0, g.height, [&](int j) {
      for (int i = 0; i < g.width; ++i) {
        const size_t k = size_t(j) * size_t(g.width) + size_t(i);
        diskPixelMeasures(g, i, j, &m->omega[k], &m->omegaProj[k], &m->centre[2 * k], &m->centre[2 * k + 1]);
      }
    });
  });
  slot = std::move(m);
  return *slot;
}

// floor(x) for a bin coordinate x known to within ±err; −1 when a bin edge lies within reach, and
// then the caller applies the exact rule.
int floorAwayFromEdges(double x, double err) {
  const double f = std::floor(x);
  if (!(x - f > err && f + 1 - x > err)) return -1;
  return int(f);
}

// The grid's rule for a unit direction: θ = acos|z| and φ = atan2(y, x) in [0, 2π), each scaled to
// its bin count and truncated.
int exactThetaPhiBin(const ThetaPhiGrid& g, const Vec3& w) {
  const double theta = safeAcos(std::abs(w.z));
  const int t = std::min(g.nTheta - 1, int(theta / (0.5 * kPi) * g.nTheta));
  const int p = std::min(g.nPhi - 1, int(sphericalPhi(w) / (2 * kPi) * g.nPhi));
  return t * g.nPhi + p;
}

// The octant of a direction's azimuth (bit 0: x < 0, bit 1: y < 0, bit 2: |y| > |x|), and the
// azimuth in [0, 2π) of a direction in octant o whose ratio min(|x|, |y|) / max(|x|, |y|) has the
// arctangent a: the polynomial search and the cell tables compose φ alike.
int octantOf(const Vec3& w, double ax, double ay) {
  return int(w.x < 0) | int(w.y < 0) << 1 | int(ay > ax) << 2;
}
double octantPhi(int o, double a) {
  const double b = (o & 4) ? 0.5 * kPi - a : a;
  return !(o & 1) ? (!(o & 2) ? b : 2 * kPi - b) : (!(o & 2) ? kPi - b : kPi + b);
}

// The same bin from polynomial angles (about 3x cheaper than acos and atan2, which were a fifth
// of a short microflake walk): the polynomials are within kApproxAngleError, so away from a bin
// edge by more than that they give the exact rule's bin; directions closer to an edge (including
// those exactly on one, such as an incidence on a ring edge) and non-finite ones take the exact
// rule, so every direction lands where the exact rule puts it.
// `w` may be a direction that is unit only to within kUnitLength2 in |w|² (what normalize() makes):
// the exact rule sees normalize(w), whose θ differs from w's by at most √(2 δz) ≈ 6.2e-8 (at the
// pole, acos being ½-Hölder; δz ≤ 1.9e-15) and whose φ differs by rounding only, so the margin
// grows by kUnitAngleError; a direction the polynomials cannot place takes the rule on normalize(w)
// (on w itself when `normalised` says w is that already).
constexpr double kUnitLength2 = 0x1p-48;
constexpr double kUnitAngleError = 1e-7;
int fastThetaPhiBin(const ThetaPhiGrid& g, const Vec3& w, bool normalised) {
  const double err = detail::kApproxAngleError + kUnitAngleError;
  const double thetaScale = g.nTheta / (0.5 * kPi), phiScale = g.nPhi / (2 * kPi);
  const int t = floorAwayFromEdges(detail::approxAcos(std::abs(w.z)) * thetaScale, err * thetaScale);
  const double ax = std::abs(w.x), ay = std::abs(w.y), big = std::max(ax, ay);
  if (t < 0 || t >= g.nTheta || !(big > 0)) return exactThetaPhiBin(g, normalised ? w : normalize(w));
  // Angle in the first quadrant by the octant's arctangent, then the quadrant of (x, y).
  const double phi = octantPhi(octantOf(w, ax, ay), detail::approxAtan(std::min(ax, ay) / big));
  const int p = floorAwayFromEdges(phi * phiScale, err * phiScale);
  if (p < 0 || p >= g.nPhi) return exactThetaPhiBin(g, normalised ? w : normalize(w));
  return t * g.nPhi + p;
}

// The bin search by table (DirectionGrid::thetaPhiBin): |z| in kThetaCells cells, and per octant of
// the azimuth the ratio r = min(|x|, |y|) / max(|x|, |y|) in kPhiCells cells (powers of two, so that
// a coordinate's cell index is exact). A cell's entry is the rule's bin for every direction that
// can look it up, when that is one bin: the rule sees normalize(w), whose |z| and ratio lie within
// kCellSlack of the coordinate looked up (normalising again, the ratio's division), and its own
// angle within a few ulps of the true angle, which is monotone in the cell's coordinate; so the true
// angles at the cell's ends widened by kCellSlack, in bin units, and a margin of 1e-9 + 1e-14 n bins
// for both roundings bound what the rule can give. Cells an edge crosses hold kNoCellBin and their
// directions take the polynomials (fastThetaPhiBin).
constexpr int kThetaCells = 4096, kPhiCells = 1024;
constexpr double kCellSlack = 1e-14;
constexpr uint16_t kNoCellBin = 0xffff;

uint16_t cellBin(double x0, double x1, int n) {
  const double margin = 1e-9 + 1e-14 * n;
  const int lo = std::clamp(int(std::floor(std::min(x0, x1) - margin)), 0, n - 1);
  const int hi = std::clamp(int(std::floor(std::max(x0, x1) + margin)), 0, n - 1);
  return lo == hi ? uint16_t(lo) : kNoCellBin;
}

std::vector<uint16_t> thetaCells(const ThetaPhiGrid& g) {
  std::vector<uint16_t> cells(kThetaCells + 1);
  auto x = [&](double z) { return std::acos(std::clamp(z, -1.0, 1.0)) / (0.5 * kPi) * g.nTheta; };
  for (int k = 0; k <= kThetaCells; ++k)
    cells[size_t(k)] =
        cellBin(x(double(k) / kThetaCells - kCellSlack), x(double(k + 1) / kThetaCells + kCellSlack), g.nTheta);
  return cells;
}

std::vector<uint16_t> phiCells(const ThetaPhiGrid& g) {
  std::vector<uint16_t> cells(8 * size_t(kPhiCells + 1));
  auto x = [&](int o, double r) { return octantPhi(o, std::atan(r)) / (2 * kPi) * g.nPhi; };
  for (int o = 0; o < 8; ++o)
    for (int k = 0; k <= kPhiCells; ++k)
      cells[size_t(o) * (kPhiCells + 1) + size_t(k)] =
          cellBin(x(o, double(k) / kPhiCells - kCellSlack), x(o, double(k + 1) / kPhiCells + kCellSlack), g.nPhi);
  return cells;
}

}  // namespace

namespace detail {
double approxAcos(double x) {
  // Abramowitz & Stegun 1964, Eq. 4.4.46: |error| <= 2.2e-8 with these 10-digit coefficients.
  constexpr double a[8] = {1.5707963050, -0.2145988016, 0.0889789874, -0.0501743046,
                           0.0308918810, -0.0170881256, 0.0066700901, -0.0012624911};
  double p = a[7];
  for (int i = 6; i >= 0; --i) p = p * x + a[i];
  return std::sqrt(1 - x) * p;
}
double approxAtan(double x) {
  // Abramowitz & Stegun 1964, Eq. 4.4.49: |error| <= 1.4e-8 on [0, 1].
  constexpr double a[9] = {1.0,           -0.3333314528, 0.1999355085,  -0.1420889944, 0.1065626393,
                           -0.0752896400, 0.0429096138,  -0.0161657367, 0.0028662257};
  const double x2 = x * x;
  double p = a[8];
  for (int i = 7; i >= 0; --i) p = p * x2 + a[i];
  return x * p;
}
}  // namespace detail

DirectionGrid::DirectionGrid(Layout layout) : layout_(layout) {
  std::visit(Overloaded{[&](const ThetaPhiGrid& g) {
                          if (g.nTheta < 1 || g.nPhi < 1 || int64_t(g.nTheta) * g.nPhi > (int64_t(1) << 30))
                            throw std::invalid_argument("grid size must be between 1 and 2^30 bins per hemisphere");
                          perHemisphere_ = g.nTheta * g.nPhi;
                          auto m = std::make_shared<GridMeasures>();
                          m->omega.resize(size_t(perHemisphere_));
                          m->omegaProj.resize(size_t(perHemisphere_));
                          double dPhi = 2 * kPi / g.nPhi, dTheta = 0.5 * kPi / g.nTheta;
                          for (int t = 0; t < g.nTheta; ++t) {
                            double t0 = t * dTheta, t1 = (t + 1) * dTheta;
                            double om = dPhi * (std::cos(t0) - std::cos(t1));
                            double s0 = std::sin(t0), s1 = std::sin(t1);
                            double op = dPhi * (s1 * s1 - s0 * s0) / 2;  // docs/physics.md §2
                            for (int p = 0; p < g.nPhi; ++p) {
                              m->omega[size_t(t * g.nPhi + p)] = om;
                              m->omegaProj[size_t(t * g.nPhi + p)] = op;
                            }
                          }
                          thetaPhiMeasures_ = std::move(m);
                          measures_.store(thetaPhiMeasures_.get());
                          if (g.nTheta < kNoCellBin && g.nPhi < kNoCellBin) {
                            thetaCells_ = thetaCells(g);
                            phiCells_ = phiCells(g);
                          }
                          ringSin_.resize(size_t(g.nTheta) + 1);
                          for (int t = 0; t <= g.nTheta; ++t) ringSin_[size_t(t)] = std::sin(t * 0.5 * kPi / g.nTheta);
                        },
                        [&](const DiskGrid& g) {
                          if (g.width < 1 || g.height < 1 || int64_t(g.width) * g.height > (int64_t(1) << 30))
                            throw std::invalid_argument("grid size must be between 1 and 2^30 bins per hemisphere");
                          perHemisphere_ = g.width * g.height;
                        }},
             layout_);
}

std::string DirectionGrid::kind() const {
  return std::holds_alternative<ThetaPhiGrid>(layout_) ? "theta-phi" : "disk";
}

int DirectionGrid::binOf(const Vec3& wIn) const {
  // A direction already unit (as the walk and the tracer pass theirs) skips the square root and the
  // division on the way to its θ–φ bin: fastThetaPhiBin's margin covers normalising it again.
  const bool asGiven = std::holds_alternative<ThetaPhiGrid>(layout_) && std::abs(dot(wIn, wIn) - 1) <= kUnitLength2;
  const Vec3 w = asGiven ? wIn : normalize(wIn);
  int hemi = w.z >= 0 ? 0 : 1;
  int local = std::visit(Overloaded{[&](const ThetaPhiGrid& g) { return thetaPhiBin(g, w, !asGiven); },
                                    [&](const DiskGrid& g) {
                                      int i = std::clamp(int((w.x + 1) * 0.5 * g.width), 0, g.width - 1);
                                      int j = std::clamp(int((w.y + 1) * 0.5 * g.height), 0, g.height - 1);
                                      return j * g.width + i;
                                    }},
                         layout_);
  return hemi * perHemisphere_ + local;
}

// By the cells' tables where both coordinates' cells lie inside one bin (all but a few per cent of
// directions; about a third of the polynomials' cost), otherwise by the polynomials.
int DirectionGrid::thetaPhiBin(const ThetaPhiGrid& g, const Vec3& w, bool normalised) const {
  const double az = std::abs(w.z), ax = std::abs(w.x), ay = std::abs(w.y), big = std::max(ax, ay);
  if (!thetaCells_.empty() && az <= 1.5 && big > 0) {  // (not for NaN)
    const uint16_t t = thetaCells_[size_t(std::min(kThetaCells, int(az * kThetaCells)))];
    const int o = octantOf(w, ax, ay);
    const uint16_t p = phiCells_[size_t(o) * (kPhiCells + 1) + size_t(std::min(ax, ay) / big * kPhiCells)];
    if (t != kNoCellBin && p != kNoCellBin) return int(t) * g.nPhi + int(p);
  }
  return fastThetaPhiBin(g, w, normalised);
}

bool DirectionGrid::atPoleOrHorizon(int bin) const {
  const int local = bin % perHemisphere_;
  return std::visit(Overloaded{[&](const ThetaPhiGrid& g) {
                                 const int t = local / g.nPhi;
                                 return t == 0 || t == g.nTheta - 1;
                               },
                               [&](const DiskGrid&) {
                                 double x0, x1, y0, y1;
                                 xyBounds(bin, &x0, &x1, &y0, &y1);
                                 const bool centre = x0 <= 0 && x1 >= 0 && y0 <= 0 && y1 >= 0;
                                 const double fx = std::max(x0 * x0, x1 * x1), fy = std::max(y0 * y0, y1 * y1);
                                 return centre || fx + fy > 1;
                               }},
                    layout_);
}

const GridMeasures& DirectionGrid::diskMeasuresNow() const {
  const GridMeasures& m = diskMeasures(std::get<DiskGrid>(layout_));
  measures_.store(&m);
  return m;
}

Vec3 DirectionGrid::centre(int bin) const {
  int hemi = bin / perHemisphere_, local = bin % perHemisphere_;
  Vec3 w =
      std::visit(Overloaded{[&](const ThetaPhiGrid& g) {
                              int t = local / g.nPhi, p = local % g.nPhi;
                              return sphericalDirection((t + 0.5) * 0.5 * kPi / g.nTheta, (p + 0.5) * 2 * kPi / g.nPhi);
                            },
                            [&](const DiskGrid&) {
                              const std::vector<double>& c = measures().centre;
                              double x = c[2 * size_t(local)], y = c[2 * size_t(local) + 1];
                              return Vec3{x, y, safeSqrt(1 - x * x - y * y)};
                            }},
                 layout_);
  if (hemi == 1) w.z = -w.z;
  return w;
}

DirectionSample DirectionGrid::sampleUniform(int bin, double u1, double u2) const {
  int hemi = bin / perHemisphere_, local = bin % perHemisphere_;
  double meanCos = projectedSolidAngle(local) / solidAngle(local);
  DirectionSample s = std::visit(
      Overloaded{[&](const ThetaPhiGrid& g) {
                   int t = local / g.nPhi, p = local % g.nPhi;
                   double c0 = std::cos(t * 0.5 * kPi / g.nTheta), c1 = std::cos((t + 1) * 0.5 * kPi / g.nTheta);
                   double cosT = c0 + (c1 - c0) * u1;  // uniform in cos theta = uniform in solid angle
                   double phi = (p + u2) * 2 * kPi / g.nPhi;
                   double sinT = safeSqrt(1 - cosT * cosT);
                   return DirectionSample{{sinT * std::cos(phi), sinT * std::sin(phi), cosT}, cosT / meanCos};
                 },
                 [&](const DiskGrid& g) {
                   // Uniform in solid angle = density ∝ 1/cos on the disk: rejection from the
                   // cosine-distributed sample would be unbounded at the rim, so use the cosine
                   // sample with weight 1 and report it as such (the weight makes it unbiased
                   // for the cosine-weighted bin averages that every caller needs).
                   return sampleCosine(local, u1, u2);
                 }},
      layout_);
  if (hemi == 1) s.w.z = -s.w.z;
  return s;
}

DirectionSample DirectionGrid::sampleUniform(int bin, Sampler& s) const {
  const double u2 = s.get1D(), u1 = s.get1D();
  return sampleUniform(bin, u1, u2);
}

DirectionSample DirectionGrid::sampleCosine(int bin, Sampler& s) const {
  const double u2 = s.get1D(), u1 = s.get1D();
  return sampleCosine(bin, u1, u2);
}

DirectionSample DirectionGrid::sampleCosine(int bin, double u1, double u2) const {
  int hemi = bin / perHemisphere_, local = bin % perHemisphere_;
  DirectionSample s =
      std::visit(Overloaded{[&](const ThetaPhiGrid& g) {
                              int t = local / g.nPhi, p = local % g.nPhi;
                              const double s0 = ringSin_[size_t(t)], s1 = ringSin_[size_t(t) + 1];
                              // density ∝ cos theta sin theta: uniform in sin^2 theta
                              double sin2 = s0 * s0 + (s1 * s1 - s0 * s0) * u1;
                              double sinT = std::sqrt(sin2), cosT = safeSqrt(1 - sin2);
                              double phi = (p + u2) * 2 * kPi / g.nPhi;
                              return DirectionSample{{sinT * std::cos(phi), sinT * std::sin(phi), cosT}, 1.0};
                            },
                            [&](const DiskGrid& g) {
                              // Uniform on (pixel ∩ disk) = cosine-distributed directions; rejection of the
                              // part of the pixel outside the disk with a deterministic fallback.
                              int i = local % g.width, j = local / g.width;
                              double x0 = -1 + 2.0 * i / g.width, y0 = -1 + 2.0 * j / g.height;
                              double dx = 2.0 / g.width, dy = 2.0 / g.height;
                              double a = u1, b = u2;
                              for (int k = 0; k < 64; ++k) {
                                double x = x0 + dx * a, y = y0 + dy * b;
                                if (x * x + y * y < 1)
                                  return DirectionSample{{x, y, std::sqrt(1 - x * x - y * y)}, 1.0};
                                // Low-discrepancy re-draw derived from the inputs (keeps determinism).
                                a = std::fmod(a + 0.7548776662466927, 1.0);
                                b = std::fmod(b + 0.5698402909980532, 1.0);
                              }
                              return DirectionSample{centre(local), 1.0};
                            }},
                 layout_);
  if (hemi == 1) s.w.z = -s.w.z;
  return s;
}

void DirectionGrid::xyBounds(int bin, double* xmin, double* xmax, double* ymin, double* ymax) const {
  int local = bin % perHemisphere_;
  std::visit(Overloaded{[&](const ThetaPhiGrid& g) {
                          int t = local / g.nPhi, p = local % g.nPhi;
                          double t0 = t * 0.5 * kPi / g.nTheta, t1 = (t + 1) * 0.5 * kPi / g.nTheta;
                          double p0 = p * 2 * kPi / g.nPhi, p1 = (p + 1) * 2 * kPi / g.nPhi;
                          double s0 = std::sin(t0), s1 = std::sin(t1);
                          *xmin = *ymin = 1e300;
                          *xmax = *ymax = -1e300;
                          auto add = [&](double r, double phi) {
                            double x = r * std::cos(phi), y = r * std::sin(phi);
                            *xmin = std::min(*xmin, x);
                            *xmax = std::max(*xmax, x);
                            *ymin = std::min(*ymin, y);
                            *ymax = std::max(*ymax, y);
                          };
                          for (double r : {s0, s1}) {
                            add(r, p0);
                            add(r, p1);
                            // Extremes of the arc where it crosses an axis.
                            for (int q = 0; q <= 4; ++q)
                              if (q * 0.5 * kPi > p0 && q * 0.5 * kPi < p1) add(r, q * 0.5 * kPi);
                          }
                        },
                        [&](const DiskGrid& g) {
                          int i = local % g.width, j = local / g.width;
                          *xmin = -1 + 2.0 * i / g.width;
                          *xmax = -1 + 2.0 * (i + 1) / g.width;
                          *ymin = -1 + 2.0 * j / g.height;
                          *ymax = -1 + 2.0 * (j + 1) / g.height;
                        }},
             layout_);
}

int DirectionGrid::binOfAngles(double theta_deg, double phi_deg) const {
  return binOf(sphericalDirection(radians(theta_deg), radians(phi_deg)));
}

}  // namespace mbsdf
