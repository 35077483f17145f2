#include "job/scalar_validity.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "job/job.h"

namespace mbsdf {
namespace {

// Largest |Δ| of an order's efficiency (WM − FDTD), per validated period/λ (rows) and depth/λ
// (columns): docs/validation/fdtd.json's binary gratings at normal incidence, the worst over both
// sides and all orders.
constexpr ValidityMap kMap = {
    {2.0, 5.0, 10.0, 20.0},
    {0.2, 0.5, 1.0, 2.0},
    {
        {0.0093, 0.0539, 0.1382, 0.4032},
        {0.0037, 0.0154, 0.0231, 0.2814},
        {0.0022, 0.0082, 0.0074, 0.1624},
        {0.0016, 0.0068, 0.0053, 0.0838},
    },
};

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

// The map's value on the unsafe side of (period/λ, depth/λ); empty outside it.
std::optional<double> lookUp(double periodOverLambda, double depthOverLambda) {
  const int R = ValidityMap::kRows, C = ValidityMap::kCols;
  if (periodOverLambda < kMap.periodOverLambda[0] || depthOverLambda > kMap.depthOverLambda[C - 1]) return std::nullopt;
  int row = 0, col = 0;
  while (row + 1 < R && kMap.periodOverLambda[row + 1] <= periodOverLambda) ++row;
  while (col + 1 < C && kMap.depthOverLambda[col] < depthOverLambda) ++col;
  return kMap.maxDelta[row][col];
}

}  // namespace

const ValidityMap& validityMap() {
  return kMap;
}

ScalarValidity scalarValidity(const Job& job) {
  ScalarValidity v;
  if (job.statistical || !job.geometry.periodic || job.scene.coherenceLength_um <= 0 ||
      !(job.needsWave() || job.autoComponents))
    return v;
  const double period = shortestPeriod(job), height = job.geometry.zMax() - job.geometry.zMin();
  if (period <= 0 || height <= 0) return v;  // flat, or no variation: Fresnel, nothing to judge
  v.applies = true;
  // The worse of the shortest and longest wavelengths: outside the map first, then the larger error.
  const auto lambdas = job.lambda_um();
  bool first = true;
  for (double lambda :
       {*std::min_element(lambdas.begin(), lambdas.end()), *std::max_element(lambdas.begin(), lambdas.end())}) {
    const double p = period / lambda, h = height / lambda;
    const std::optional<double> e = lookUp(p, h);
    const bool worse = first || (!e && v.maxOrderError) || (e && v.maxOrderError && *e > *v.maxOrderError);
    if (worse) v.periodOverLambda = p, v.heightOverLambda = h, v.maxOrderError = e;
    first = false;
  }
  const std::string where = fmt::format("period {:.3g} λ, height {:.3g} λ", v.periodOverLambda, v.heightOverLambda);
  if (!v.maxOrderError) {
    v.beyondTolerance = true;
    v.note = where +
             ": outside the rigorously validated range (period ≥ 2 λ, height ≤ 2 λ; docs/validation.md) — "
             "scalar diffraction is not vouched for; compare the energy balance";
  } else {
    v.beyondTolerance = *v.maxOrderError > job.scene.tolerance;
    v.note = fmt::format(
        "{}: binary gratings there are off by up to {:.3f} per order against FDTD "
        "(docs/validation.md){}",
        where, *v.maxOrderError,
        v.beyondTolerance ? fmt::format(", beyond the tolerance {}", job.scene.tolerance) : "");
  }
  return v;
}

nlohmann::json toJson(const ScalarValidity& v) {
  if (!v.applies) return {{"applies", false}};
  nlohmann::json j = {{"applies", true},
                      {"period_over_lambda", v.periodOverLambda},
                      {"height_over_lambda", v.heightOverLambda},
                      {"beyond_tolerance", v.beyondTolerance},
                      {"note", v.note}};
  j["max_order_error_fdtd"] = v.maxOrderError ? nlohmann::json(*v.maxOrderError) : nlohmann::json(nullptr);
  return j;
}

}  // namespace mbsdf
