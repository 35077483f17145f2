#include "io/bsdf_lookup.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/error.h"
#include "io/slice_export.h"

namespace mbsdf {

BsdfLookup::BsdfLookup(const BsdfFileReader& file, const std::string& model)
    : file_(file), grid_(file.grid()), model_(model), isotropic_(tableIsIsotropic(file)) {
  nL_ = file.channelCount();
  nB_ = grid_.binCount();
  slices_.resize(size_t(file.incidenceCount()));
  incidenceOfBin_.assign(size_t(nB_), -1);
  bool checked = false;
  for (int i = 0; i < file.incidenceCount(); ++i) {
    if (!file.done(i)) continue;
    if (!checked) slice(i);  // the model's components exist (InputError otherwise); the rest on demand
    checked = true;
    incidenceOfBin_[size_t(file.incidenceBin(i))] = i;
  }
  // Every bin with directions in each hemisphere that holds an incidence.
  bool& upper = hasUpper_;
  bool& lower = hasLower_;
  bool complete = true;
  for (int i = 0; i < file.incidenceCount(); ++i) (grid_.isUpper(file.incidenceBin(i)) ? upper : lower) = true;
  for (int b = 0; b < nB_; ++b)
    if (grid_.projectedSolidAngle(b) > 0 && (grid_.isUpper(b) ? upper : lower) && incidenceOfBin_[size_t(b)] < 0)
      complete = false;
  allIncidenceBins_ = complete && (upper || lower);
  if (!isotropic_) return;
  // An isotropic table's rings: one finished incidence per distinct θ on each side (the first).
  for (int i = 0; i < file.incidenceCount(); ++i) {
    if (!file.done(i)) continue;
    const bool fromAbove = file.incidenceTheta(i) < 90;
    const double theta = radians(fromAbove ? file.incidenceTheta(i) : 180 - file.incidenceTheta(i));
    std::vector<Ring>& rings = fromAbove ? ringsUpper_ : ringsLower_;
    if (std::none_of(rings.begin(), rings.end(), [&](const Ring& r) { return std::abs(r.theta - theta) < 1e-12; }))
      rings.push_back({theta, radians(file.incidencePhi(i)), i});
  }
  for (auto* rings : {&ringsUpper_, &ringsLower_})
    std::sort(rings->begin(), rings->end(), [](const Ring& a, const Ring& b) { return a.theta < b.theta; });
  hasUpper_ = !ringsUpper_.empty();
  hasLower_ = !ringsLower_.empty();
}

bool tableIsIsotropic(const BsdfFileReader& file) {
  return file.hasAttribute("symmetry") && file.attribute("symmetry").rfind("isotropic", 0) == 0;
}

GridCoords gridCoords(const DirectionGrid& grid, const Vec3& w) {
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout()))
    return {safeAcos(std::abs(w.z)) / (0.5 * kPi) * g->nTheta - 0.5, sphericalPhi(w) / (2 * kPi) * g->nPhi - 0.5};
  const auto& d = std::get<DiskGrid>(grid.layout());
  return {(w.x + 1) * 0.5 * d.width - 0.5, (w.y + 1) * 0.5 * d.height - 0.5};
}

int binAtCoords(const DirectionGrid& grid, int i, int j, bool upper) {
  const int offset = upper ? 0 : grid.binsPerHemisphere();
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout())) {
    if (i < 0 || i >= g->nTheta) return -1;
    return offset + i * g->nPhi + ((j % g->nPhi) + g->nPhi) % g->nPhi;
  }
  const auto& d = std::get<DiskGrid>(grid.layout());
  if (i < 0 || i >= d.width || j < 0 || j >= d.height) return -1;
  return offset + j * d.width + i;
}

std::vector<std::pair<int, double>> interpolationWeights(const DirectionGrid& grid, const Vec3& wIn) {
  const Vec3 w = normalize(wIn);
  const bool upper = w.z >= 0;
  auto bin = [&](int i, int j) { return binAtCoords(grid, i, j, upper); };
  const GridCoords c = gridCoords(grid, w);
  std::vector<std::pair<int, double>> out;
  if (const auto* g = std::get_if<ThetaPhiGrid>(&grid.layout())) {
    const double u = std::clamp(c.u, 0.0, g->nTheta - 1.0);
    const int t0 = std::min(int(std::floor(u)), g->nTheta - 1), t1 = std::min(t0 + 1, g->nTheta - 1);
    const int p0 = int(std::floor(c.v)), p1 = p0 + 1;
    const double fu = u - t0, fv = c.v - p0;
    // Inside the first ring's centres the value tends to the ring's mean at the pole, where every
    // azimuth meets (continuous across the pole).
    const double toPole = c.u < 0 ? std::min(1.0, -2 * c.u) : 0.0;
    out = {{bin(t0, p0), (1 - toPole) * (1 - fu) * (1 - fv)},
           {bin(t0, p1), (1 - toPole) * (1 - fu) * fv},
           {bin(t1, p0), (1 - toPole) * fu * (1 - fv)},
           {bin(t1, p1), (1 - toPole) * fu * fv}};
    if (toPole > 0)
      for (int p = 0; p < g->nPhi; ++p) out.emplace_back(bin(0, p), toPole / g->nPhi);
  } else {
    const auto& d = std::get<DiskGrid>(grid.layout());
    const double x = std::clamp(c.u, 0.0, d.width - 1.0), y = std::clamp(c.v, 0.0, d.height - 1.0);
    const int i0 = std::min(int(std::floor(x)), d.width - 1), i1 = std::min(i0 + 1, d.width - 1);
    const int j0 = std::min(int(std::floor(y)), d.height - 1), j1 = std::min(j0 + 1, d.height - 1);
    const double fx = x - i0, fy = y - j0;
    out = {{bin(i0, j0), (1 - fx) * (1 - fy)},
           {bin(i1, j0), fx * (1 - fy)},
           {bin(i0, j1), (1 - fx) * fy},
           {bin(i1, j1), fx * fy}};
  }
  // Bins without directions (the disk's corners) carry no value: the others share their weight;
  // where none is left (outside the disk's last ring of pixels) the bin of w itself stands.
  double total = 0;
  for (auto& [b, wt] : out) {
    if (grid.projectedSolidAngle(b) <= 0) wt = 0;
    total += wt;
  }
  if (total <= 0) return {{grid.binOf(w), 1.0}};
  for (auto& bw : out) bw.second /= total;
  return out;
}

const std::vector<double>& BsdfLookup::slice(int incidence) const {
  if (!file_.done(incidence)) throw InputError("slice " + std::to_string(incidence) + " of the table is not finished");
  std::vector<double>& s = slices_.at(size_t(incidence));
  if (s.empty()) {
    try {
      s = modelSlice(file_, model_, incidence);
    } catch (const std::invalid_argument& e) {
      throw InputError(e.what());
    }
  }
  return s;
}

double BsdfLookup::eval(int incidence, const Vec3& wo, int l) const {
  const std::vector<double>& s = slice(incidence);
  double f = 0;
  for (const auto& [b, wt] : interpolationWeights(grid_, wo)) f += wt * s[size_t(l) * size_t(nB_) + size_t(b)];
  return f;
}

double BsdfLookup::eval(const Vec3& wi, const Vec3& wo, int l) const {
  double f = 0;
  for (const IncidenceWeight& iw : incidenceWeights(wi))
    f += iw.weight * eval(iw.incidence, turnedAboutZ(wo, iw.turn), l);
  return f;
}

double BsdfLookup::hemisphericalIntegral(const Vec3& wi, int l, bool upper) const {
  double e = 0;
  for (const IncidenceWeight& iw : incidenceWeights(wi)) e += iw.weight * hemisphericalIntegral(iw.incidence, l, upper);
  return e;
}

std::vector<BsdfLookup::IncidenceWeight> BsdfLookup::incidenceWeights(const Vec3& wi) const {
  // The nearest incidence of the other side would be another experiment altogether.
  if (!(wi.z >= 0 ? hasUpper_ : hasLower_))
    throw InputError(std::string("the table holds no incidence from ") + (wi.z >= 0 ? "above" : "below") +
                     " the surface");
  if (isotropic_) {
    // f(R wi, R wo) = f(wi, wo) for every turn R about the normal: each ring of incidences is taken at
    // the pair turned so that wi lies at the azimuth of the ring's incidence, and the rings on either
    // side of θi are blended linearly in θi (held beyond the first and last). Interpolating between
    // incidence azimuths at a fixed wo instead would average lobes that point different ways.
    const std::vector<Ring>& rings = wi.z >= 0 ? ringsUpper_ : ringsLower_;
    const Vec3 n = normalize(wi);
    const double theta = safeAcos(std::abs(n.z)), phi = sphericalPhi(n);
    auto on = [&](const Ring& r, double w) { return IncidenceWeight{r.incidence, r.phi - phi, w}; };
    const auto above =
        std::lower_bound(rings.begin(), rings.end(), theta, [](const Ring& r, double t) { return r.theta < t; });
    if (above == rings.begin()) return {on(rings.front(), 1)};
    if (above == rings.end()) return {on(rings.back(), 1)};
    const Ring& below = *(above - 1);
    // On a ring (an exporter's node, up to rounding): that ring alone, not a blend read from two slices.
    if (above->theta - theta < 1e-9) return {on(*above, 1)};
    if (theta - below.theta < 1e-9) return {on(below, 1)};
    const double w = (theta - below.theta) / (above->theta - below.theta);
    return {on(below, 1 - w), on(*above, w)};
  }
  if (allIncidenceBins_) {
    std::vector<IncidenceWeight> out;
    for (const auto& [b, wt] : interpolationWeights(grid_, wi)) {
      const int i = incidenceOfBin_[size_t(b)];
      if (i < 0 || !file_.done(i)) {
        out.clear();
        break;
      }
      out.push_back({i, 0.0, wt});
    }
    if (!out.empty()) return out;
  }
  const Vec3 n = normalize(wi);
  return {{file_.nearestIncidence(degrees(safeAcos(n.z)), degrees(sphericalPhi(n))), 0.0, 1.0}};
}

double BsdfLookup::hemisphericalIntegral(int incidence, int l, bool upper) const {
  if (!file_.done(incidence)) return 0;
  const std::vector<double>& s = slice(incidence);
  double e = 0;
  for (int b = 0; b < nB_; ++b)
    if (grid_.isUpper(b) == upper) e += s[size_t(l) * size_t(nB_) + size_t(b)] * grid_.projectedSolidAngle(b);
  return e;
}

}  // namespace mbsdf
