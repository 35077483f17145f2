#include "job/scalar_validity.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "job/job.h"

namespace mbsdf {
namespace {

constexpr double kSame = 1e-9;

// The structure's shortest period: the lattice cell along each axis the surface varies along (a
// surface invariant along y, a 1-D grating, has no facet normal with a y component).
double shortestPeriod(const Job& job) {
  bool variesX = false, variesY = false;
  for (size_t t = 0; t < job.geometry.triangles.size(); ++t) {
    const Vec3 n = job.geometry.triangleNormal(t);
    const double len = length(n);
    if (len <= 0) continue;
    variesX = variesX || std::abs(n.x) > 1e-9 * len;
    variesY = variesY || std::abs(n.y) > 1e-9 * len;
  }
  double p = 0;
  if (variesX) p = job.cellSizeX();
  if (variesY) p = p > 0 ? std::min(p, job.cellSizeY()) : job.cellSizeY();
  return p;
}

// Where x lies among the validated values (ascending): the two that bracket it and x's weight on the
// upper one (linear, or in log x for periods). Beyond the values on their safe side (longer periods,
// shallower ridges, smaller angles) the nearest value stands in; beyond the unsafe side nothing does.
struct Bracket {
  double lo = 0, hi = 0, w = 0;
};
enum class SafeSide { Below, Above };
enum class Scale { Linear, Log };
std::optional<Bracket> bracket(const std::vector<double>& values, double x, SafeSide safe, Scale scale) {
  if (values.empty()) return std::nullopt;
  if (x <= values.front() + kSame) {
    if (safe == SafeSide::Above && x < values.front() - kSame) return std::nullopt;
    return Bracket{values.front(), values.front(), 0};
  }
  if (x >= values.back() - kSame) {
    if (safe == SafeSide::Below && x > values.back() + kSame) return std::nullopt;
    return Bracket{values.back(), values.back(), 0};
  }
  size_t i = 1;
  while (values[i] < x) ++i;
  const double lo = values[i - 1], hi = values[i];
  const double w = scale == Scale::Log ? std::log(x / lo) / std::log(hi / lo) : (x - lo) / (hi - lo);
  return Bracket{lo, hi, w};
}

// The distinct values of one coordinate of the cases that pass `keep`, ascending.
template <typename Keep, typename Get>
std::vector<double> distinct(Keep keep, Get get) {
  std::vector<double> out;
  for (const ValidatedCase& c : validatedCases())
    if (keep(c) && std::none_of(out.begin(), out.end(), [&](double v) { return std::abs(v - get(c)) < kSame; }))
      out.push_back(get(c));
  std::sort(out.begin(), out.end());
  return out;
}

const char* sideName(ValidityMaterial m, ValiditySide s) {
  if (m == ValidityMaterial::Conductor) return "a conductor (Al)";
  return s == ValiditySide::Outside ? "a dielectric lit from outside" : "a dielectric lit from inside";
}

// Where on the map one incidence and wavelength of the job lie.
struct Placement {
  ValiditySide side;
  double theta_deg, periodOverLambda, heightOverLambda;
  std::optional<double> error;
};

// The worse of two placements: outside the map first, then the larger figure.
bool worse(const Placement& a, const Placement& b) {
  if (!a.error != !b.error) return !a.error;
  return a.error && *a.error > *b.error;
}

// The validated figure at exactly (θ, period/λ, depth/λ), if that case was measured.
std::optional<double> caseAt(ValidityMaterial material, ValiditySide side, double theta_deg, double periodOverLambda,
                             double depthOverLambda, ScalarModel model) {
  for (const ValidatedCase& c : validatedCases())
    if (c.material == material && c.side == side && std::abs(c.theta_deg - theta_deg) < kSame &&
        std::abs(c.periodOverLambda - periodOverLambda) < kSame &&
        std::abs(c.depthOverLambda - depthOverLambda) < kSame)
      return model == ScalarModel::Wm ? c.maxDeltaWm : c.maxDeltaWs;
  return std::nullopt;
}

// Bilinear in (log period, depth) among the cases measured at one validated angle.
std::optional<double> atAngle(ValidityMaterial material, ValiditySide side, double theta_deg, double periodOverLambda,
                              double depthOverLambda, ScalarModel model) {
  auto atTheta = [&](const ValidatedCase& c) {
    return c.material == material && c.side == side && std::abs(c.theta_deg - theta_deg) < kSame;
  };
  const auto p = bracket(distinct(atTheta, [](const ValidatedCase& c) { return c.periodOverLambda; }), periodOverLambda,
                         SafeSide::Above, Scale::Log);
  const auto d = bracket(distinct(atTheta, [](const ValidatedCase& c) { return c.depthOverLambda; }), depthOverLambda,
                         SafeSide::Below, Scale::Linear);
  if (!p || !d) return std::nullopt;
  double sum = 0;
  for (const auto& [period, wp] : {std::pair{p->lo, 1 - p->w}, std::pair{p->hi, p->w}})
    for (const auto& [depth, wd] : {std::pair{d->lo, 1 - d->w}, std::pair{d->hi, d->w}}) {
      if (wp * wd <= 0) continue;
      const std::optional<double> e = caseAt(material, side, theta_deg, period, depth, model);
      if (!e) return std::nullopt;
      sum += wp * wd * *e;
    }
  return sum;
}

}  // namespace

std::optional<double> validatedError(ValidityMaterial material, ValiditySide side, double theta_deg,
                                     double periodOverLambda, double depthOverLambda, ScalarModel model) {
  auto ofClass = [&](const ValidatedCase& c) { return c.material == material && c.side == side; };
  const auto t = bracket(distinct(ofClass, [](const ValidatedCase& c) { return c.theta_deg; }), theta_deg,
                         SafeSide::Below, Scale::Linear);
  if (!t) return std::nullopt;
  double sum = 0;
  for (const auto& [theta, w] : {std::pair{t->lo, 1 - t->w}, std::pair{t->hi, t->w}}) {
    if (w <= 0) continue;
    const std::optional<double> e = atAngle(material, side, theta, periodOverLambda, depthOverLambda, model);
    if (!e) return std::nullopt;
    sum += w * *e;
  }
  return sum;
}

namespace {

// The note for plan and the run log: where the job sits worst and what the map says there.
std::string validityNote(const ScalarValidity& v, const Job& job) {
  std::string where = fmt::format("{}, θi {:.3g}°, period {:.3g} λ, height {:.3g} λ", sideName(v.material, v.side),
                                  v.theta_deg, v.periodOverLambda, v.heightOverLambda);
  if (!v.maxOrderError)
    return where +
           ": outside the rigorously validated cases (docs/validation.md: binary gratings of glass and Al by "
           "angle, period and depth) — the scalar model's error here is unknown; compare the energy balance";
  std::string text =
      fmt::format("{}: binary gratings there are off by up to {:.3f} per order ({}) against FDTD (docs/validation.md)",
                  where, *v.maxOrderError, v.model == ScalarModel::Wm ? "WM" : "WS");
  if (v.beyondTolerance) text += fmt::format(", beyond the tolerance {}", job.scene.tolerance);
  // Geometric interreflection between walls about λ tall adds lobes the rigorous solution lacks.
  if (v.model == ScalarModel::Wm && v.singleScatteringError && *v.maxOrderError > 1.5 * *v.singleScatteringError &&
      *v.maxOrderError > job.scene.tolerance)
    text += fmt::format(
        "; most of it is geometric multiple scattering, which adds lobes the wave solution lacks (WS alone {:.3f})",
        *v.singleScatteringError);
  return text;
}

}  // namespace

ScalarValidity scalarValidity(const Job& job) {
  ScalarValidity v;
  if (job.statistical || !job.geometry.periodic || job.scene.coherenceLength_um <= 0 ||
      !(job.needsWave() || job.autoComponents))
    return v;
  const double period = shortestPeriod(job), height = job.geometry.zMax() - job.geometry.zMin();
  if (period <= 0 || height <= 0) return v;  // flat, or no variation: Fresnel, nothing to judge
  v.applies = true;
  v.material = job.material.isConductor() ? ValidityMaterial::Conductor : ValidityMaterial::Dielectric;
  v.model = job.components.has(Component::Multiple) || job.autoComponents ? ScalarModel::Wm : ScalarModel::Ws;
  const auto lambdas = job.lambda_um();
  std::optional<Placement> worst;
  for (const IncidenceDirection& in : job.incidence)
    for (double lambda :
         {*std::min_element(lambdas.begin(), lambdas.end()), *std::max_element(lambdas.begin(), lambdas.end())}) {
      const bool inside = in.theta_deg > 90;
      Placement p{inside ? ValiditySide::Inside : ValiditySide::Outside, inside ? 180 - in.theta_deg : in.theta_deg,
                  period / lambda, height / lambda, std::nullopt};
      p.error = validatedError(v.material, p.side, p.theta_deg, p.periodOverLambda, p.heightOverLambda, v.model);
      if (!worst || worse(p, *worst)) worst = p;
    }
  if (!worst) return ScalarValidity{};
  v.side = worst->side;
  v.theta_deg = worst->theta_deg;
  v.periodOverLambda = worst->periodOverLambda;
  v.heightOverLambda = worst->heightOverLambda;
  v.maxOrderError = worst->error;
  if (v.model == ScalarModel::Wm)
    v.singleScatteringError =
        validatedError(v.material, v.side, v.theta_deg, v.periodOverLambda, v.heightOverLambda, ScalarModel::Ws);
  v.beyondTolerance = !v.maxOrderError || *v.maxOrderError > job.scene.tolerance;
  v.note = validityNote(v, job);
  return v;
}

std::optional<std::string> scalarModelCaveat(const Job& job) {
  const ScalarValidity v = scalarValidity(job);
  if (!v.applies || !v.beyondTolerance) return std::nullopt;
  return "scalar model: " + v.note;
}

nlohmann::json toJson(const ScalarValidity& v) {
  if (!v.applies) return {{"applies", false}};
  nlohmann::json j = {{"applies", true},
                      {"material", v.material == ValidityMaterial::Conductor ? "conductor" : "dielectric"},
                      {"lit_from", v.side == ValiditySide::Outside ? "outside" : "inside"},
                      {"theta_i_deg", v.theta_deg},
                      {"period_over_lambda", v.periodOverLambda},
                      {"height_over_lambda", v.heightOverLambda},
                      {"model", v.model == ScalarModel::Wm ? "WM" : "WS"},
                      {"beyond_tolerance", v.beyondTolerance},
                      {"note", v.note}};
  j["max_order_error_fdtd"] = v.maxOrderError ? nlohmann::json(*v.maxOrderError) : nlohmann::json(nullptr);
  return j;
}

}  // namespace mbsdf
