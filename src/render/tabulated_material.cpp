#include "render/tabulated_material.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/error.h"

namespace mbsdf {

namespace {

constexpr double kDefensive = 0.1;  // share of cosine-weighted draws
// Of the table's draws, the share from a tent twice as wide: the lobe of f(wi → wo) over wi (the
// slices of wi) sits up to a bin or so from that of f(wo → wi) over wi (the slice of wo, sampled) when
// a lobe is a bin wide, and the wide tent covers that offset.
constexpr double kWide = 0.25;

// The direction at grid coordinates (u, v) (io/bsdf_lookup.h gridCoords) on the upper (lower)
// hemisphere; empty outside it.
std::optional<Vec3> directionAt(const DirectionGrid& grid, double u, double v, bool upper) {
  Vec3 w;
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout())) {
    const double theta = (u + 0.5) / g->nTheta * 0.5 * kPi;
    if (!(theta >= 0 && theta < 0.5 * kPi)) return std::nullopt;
    w = sphericalDirection(theta, (v + 0.5) / g->nPhi * 2 * kPi);
  } else {
    const auto& d = std::get<DiskGrid>(grid.layout());
    const double x = 2 * (u + 0.5) / d.width - 1, y = 2 * (v + 0.5) / d.height - 1;
    if (!(x * x + y * y < 1)) return std::nullopt;
    w = {x, y, std::sqrt(1 - x * x - y * y)};
  }
  if (!upper) w.z = -w.z;
  return w;
}

// dω / (du dv) at w.
double jacobian(const DirectionGrid& grid, const Vec3& w) {
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout()))
    return safeSqrt(1 - w.z * w.z) * (0.5 * kPi / g->nTheta) * (2 * kPi / g->nPhi);
  const auto& d = std::get<DiskGrid>(grid.layout());
  return (2.0 / d.width) * (2.0 / d.height) / std::abs(w.z);
}

std::pair<int, int> binCoords(const DirectionGrid& grid, int bin) {
  const int b = bin % grid.binsPerHemisphere();
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout())) return {b / g->nPhi, b % g->nPhi};
  const auto& d = std::get<DiskGrid>(grid.layout());
  return {b % d.width, b / d.width};
}

// Inverse CDF of the tent density (1 − |x|/h)/h on [−h, h].
double tentOffset(double u, double h) {
  return h * (u < 0.5 ? std::sqrt(2 * u) - 1 : 1 - std::sqrt(2 * (1 - u)));
}
double tent(double x, double h) {
  return std::max(0.0, 1 - std::abs(x) / h) / h;
}

Vec3 cosineHemisphere(double u1, double u2, bool upper) {
  const double r = std::sqrt(u1), phi = 2 * kPi * u2;
  const double z = safeSqrt(1 - u1);
  return {r * std::cos(phi), r * std::sin(phi), upper ? z : -z};
}

}  // namespace

TabulatedMaterial::TabulatedMaterial(const BsdfFileReader& file, const std::string& model, double insideIor)
    : file_(file), lookup_(file, model), insideIor_(insideIor) {
  const int nL = file.channelCount();
  try {
    toRgb_ = file.toColour().linearSrgbPerSample();
  } catch (const std::invalid_argument&) {  // no visible wavelength: the mean of the rows, grey
    toRgb_.assign(size_t(nL), Colour3{1.0 / nL, 1.0 / nL, 1.0 / nL});
  }
  slices_.resize(size_t(file.incidenceCount()));
  once_ = std::make_unique<std::once_flag[]>(size_t(file.incidenceCount()));
  if (file.doneCount() == 0) throw InputError("the file holds no finished slice to render");
  std::vector<Vec3> direction;
  for (int i = 0; i < file.incidenceCount(); ++i)
    direction.push_back(sphericalDirection(radians(file.incidenceTheta(i)), radians(file.incidencePhi(i))));
  nearestFinished_.assign(size_t(file.incidenceCount()), -1);
  for (int i = 0; i < file.incidenceCount(); ++i) {
    if (file.done(i)) {
      nearestFinished_[size_t(i)] = i;
      (direction[size_t(i)].z >= 0 ? finishedAbove_ : finishedBelow_) = true;
      continue;
    }
    double best = -2;
    for (int j = 0; j < file.incidenceCount(); ++j)
      if (file.done(j) && (direction[size_t(j)].z >= 0) == (direction[size_t(i)].z >= 0) &&
          dot(direction[size_t(i)], direction[size_t(j)]) > best)
        best = dot(direction[size_t(i)], direction[size_t(j)]), nearestFinished_[size_t(i)] = j;
  }
}

int TabulatedMaterial::finished(int incidence) const {
  const int i = nearestFinished_[size_t(incidence)];
  if (i != incidence) unfinishedReplaced_.store(true);
  if (i < 0) throw InputError("no finished slice on the side of incidence " + std::to_string(incidence));
  return i;
}

const TabulatedMaterial::Slice& TabulatedMaterial::slice(int incidence) const {
  std::call_once(once_[size_t(incidence)], [&] {
    std::vector<double> rows;
    {
      const std::lock_guard<std::mutex> lock(fileMutex_);
      rows = lookup_.slice(incidence);
    }
    const DirectionGrid& grid = file_.grid();
    const int nB = grid.binCount(), nL = int(toRgb_.size());
    auto s = std::make_unique<Slice>();
    s->rgb.assign(size_t(3) * nB, 0.f);
    s->prob.assign(size_t(nB), 0.0);
    double upper = 0, total = 0;
    for (int b = 0; b < nB; ++b) {
      Colour3 c{0, 0, 0};
      for (int l = 0; l < nL; ++l) {
        const double f = rows[size_t(l) * nB + size_t(b)];
        if (!std::isfinite(f))
          throw InputError("slice " + std::to_string(incidence) + " holds a non-finite value in bin " +
                           std::to_string(b));
        for (int k = 0; k < 3; ++k) c[size_t(k)] += toRgb_[size_t(l)][size_t(k)] * f;
      }
      // Colours outside the sRGB gamut (a diffraction order's pure spectral colour) are clipped
      // to it per bin: a renderer carries no negative radiance.
      for (int k = 0; k < 3; ++k) s->rgb[size_t(k) * nB + size_t(b)] = float(std::max(0.0, c[size_t(k)]));
      const double e =
          (std::max(0.0, c[0]) + std::max(0.0, c[1]) + std::max(0.0, c[2])) / 3 * grid.projectedSolidAngle(b);
      s->prob[size_t(b)] = e;
      total += e;
      if (grid.isUpper(b)) upper += e;
    }
    s->cdf.assign(size_t(nB) + 1, 0.0);
    if (total > 0) {
      s->empty = false;
      s->upperShare = upper / total;
      for (int b = 0; b < nB; ++b) {
        s->prob[size_t(b)] /= total;
        s->cdf[size_t(b) + 1] = s->cdf[size_t(b)] + s->prob[size_t(b)];
      }
      s->cdf[size_t(nB)] = 1;
    }
    slices_[size_t(incidence)] = std::move(s);
  });
  return *slices_[size_t(incidence)];
}

Colour3 TabulatedMaterial::evalAt(int incidence, const Vec3& wo) const {
  const Slice& s = slice(incidence);
  const size_t nB = size_t(file_.grid().binCount());
  Colour3 f{0, 0, 0};
  for (const auto& [b, wt] : interpolationWeights(file_.grid(), wo))
    for (int k = 0; k < 3; ++k) f[size_t(k)] += wt * s.rgb[size_t(k) * nB + size_t(b)];
  return f;
}

Colour3 TabulatedMaterial::evalFrom(const Vec3& wi, const Vec3& wo) const {
  Colour3 f{0, 0, 0};
  for (const BsdfLookup::IncidenceWeight& iw : lookup_.incidenceWeights(wi)) {
    const Colour3 c = evalAt(finished(iw.incidence), turnedAboutZ(wo, iw.turn));
    for (int k = 0; k < 3; ++k) f[size_t(k)] += iw.weight * c[size_t(k)];
  }
  return f;
}

Colour3 TabulatedMaterial::eval(const Vec3& wi, const Vec3& wo) const {
  // A list of incidences is read from the viewer's side (see the header); otherwise from the light's
  // side when the table holds it.
  const bool fromViewer = lookup_.nearestOnly() && holds(wo.z >= 0);
  if (!fromViewer && holds(wi.z >= 0)) {
    const Colour3 f = evalFrom(wi, wo);
    if (lookup_.nearestOnly() && (f[0] > 0 || f[1] > 0 || f[2] > 0)) lightSliceInside_.store(true);
    return f;
  }
  if (!holds(wo.z >= 0)) return {0, 0, 0};
  Colour3 f = evalFrom(wo, wi);  // reciprocity
  if (!(f[0] > 0 || f[1] > 0 || f[2] > 0)) return f;
  if (!fromViewer) reciprocityUsed_.store(true);
  if ((wi.z >= 0) != (wo.z >= 0)) {
    if (insideIor_ > 0) {
      // (η_o/η_i)²: η = 1 above the surface, insideIor below.
      const double ratio = wo.z >= 0 ? 1 / insideIor_ : insideIor_;
      for (double& c : f) c *= ratio * ratio;
    } else {
      etaFactorMissing_.store(true);
    }
  }
  return f;
}

TabulatedMaterial::Drawn TabulatedMaterial::drawnFrom(const Vec3& wo) const {
  if (!holds(wo.z >= 0)) return {};
  const auto weights = lookup_.incidenceWeights(wo);
  const auto best = std::max_element(weights.begin(), weights.end(),
                                     [](const auto& a, const auto& b) { return a.weight < b.weight; });
  return {&slice(finished(best->incidence)), best->turn};
}

double TabulatedMaterial::tentPdf(const Slice& s, const Vec3& w) const {
  const DirectionGrid& grid = file_.grid();
  const GridCoords c = gridCoords(grid, w);
  const int i0 = int(std::floor(c.u)), j0 = int(std::floor(c.v));
  double q = 0;
  for (int i = i0 - 1; i <= i0 + 2; ++i)
    for (int j = j0 - 1; j <= j0 + 2; ++j) {
      const int b = binAtCoords(grid, i, j, w.z >= 0);
      if (b < 0 || s.prob[size_t(b)] == 0) continue;
      q += s.prob[size_t(b)] *
           ((1 - kWide) * tent(c.u - i, 1) * tent(c.v - j, 1) + kWide * tent(c.u - i, 2) * tent(c.v - j, 2));
    }
  const double jac = jacobian(grid, w);
  return jac > 0 ? q / jac : 0.0;
}

double TabulatedMaterial::pdfIn(const Drawn& d, const Vec3& wi) const {
  const double cosine = (wi.z >= 0 ? d.upperShare() : 1 - d.upperShare()) * std::abs(wi.z) / kPi;
  if (!d.fromTable()) return cosine;
  return (1 - kDefensive) * tentPdf(*d.slice, turnedAboutZ(wi, d.turn)) + kDefensive * cosine;
}

double TabulatedMaterial::pdf(const Vec3& wo, const Vec3& wi) const {
  return pdfIn(drawnFrom(wo), wi);
}

std::optional<MaterialSample> TabulatedMaterial::sample(const Vec3& wo, Sampler& sampler) const {
  const double uChoice = sampler.get1D(), uBin = sampler.get1D();  // the branch, the bin (or side)
  const double u1 = sampler.get1D(), u2 = sampler.get1D();
  const Drawn d = drawnFrom(wo);
  MaterialSample out;
  if (!d.fromTable() || uChoice < kDefensive) {
    out.wi = cosineHemisphere(u1, u2, uBin < d.upperShare());
  } else {
    const Slice& s = *d.slice;
    const int b = std::clamp(int(std::upper_bound(s.cdf.begin(), s.cdf.end(), uBin) - s.cdf.begin()) - 1, 0,
                             file_.grid().binCount() - 1);
    const auto [i, j] = binCoords(file_.grid(), b);
    // uChoice beyond the defensive share picks the tent's width.
    const double h = uChoice < kDefensive + (1 - kDefensive) * kWide ? 2 : 1;
    const auto w = directionAt(file_.grid(), i + tentOffset(u1, h), j + tentOffset(u2, h), file_.grid().isUpper(b));
    if (!w) return std::nullopt;
    out.wi = turnedAboutZ(*w, -d.turn);
  }
  out.pdf = pdfIn(d, out.wi);
  if (!(out.pdf > 0)) return std::nullopt;
  const Colour3 f = eval(out.wi, wo);
  for (int k = 0; k < 3; ++k) out.weight[size_t(k)] = f[size_t(k)] * std::abs(out.wi.z) / out.pdf;
  return out;
}

}  // namespace mbsdf
