#include "core/overloaded.h"
#include "optics/material.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "optics/material_data.h"

namespace mbsdf {
namespace {

double interpolate(const std::vector<double>& x, const std::vector<double>& y, double xv) {
  if (xv < x.front() || xv > x.back()) throw std::out_of_range("wavelength outside table");
  auto it = std::upper_bound(x.begin(), x.end(), xv);
  size_t i = std::min<size_t>(std::max<ptrdiff_t>(it - x.begin(), 1) - 1, x.size() - 2);
  double t = (xv - x[i]) / (x[i + 1] - x[i]);
  return y[i] + t * (y[i + 1] - y[i]);
}

double sellmeier(const SellmeierIndex& s, double lambda_um) {
  double l2 = lambda_um * lambda_um, n2 = 1.0;
  for (int i = 0; i < 3; ++i) n2 += s.B[i] * l2 / (l2 - s.C_um2[i]);
  return std::sqrt(n2);
}
}  // namespace

bool Material::isPerfectConductor() const {
  auto* c = std::get_if<Conductor>(&model);
  return c && std::holds_alternative<PerfectConductor>(c->index);
}

bool Material::lossless() const {
  if (isConductor()) return isPerfectConductor();
  const auto* c = std::get_if<ConstantIndex>(&std::get<Dielectric>(model).index);
  return !c || c->k == 0;
}

bool Material::directionsIndependentOfLambda() const {
  if (isConductor()) return true;
  return std::holds_alternative<ConstantIndex>(std::get<Dielectric>(model).index);
}

std::pair<double, double> Material::validRange_nm() const {
  const double inf = std::numeric_limits<double>::infinity();
  if (auto* c = std::get_if<Conductor>(&model))
    if (auto* t = std::get_if<TabulatedIndex>(&c->index)) return {t->lambda_nm.front(), t->lambda_nm.back()};
  if (auto* d = std::get_if<Dielectric>(&model))
    if (auto* s = std::get_if<SellmeierIndex>(&d->index)) {
      // Stay clear of the formula's UV pole: lambda^2 > 2 C1.
      return {std::sqrt(2 * std::max({s->C_um2[0], s->C_um2[1]})) * 1000.0, std::sqrt(s->C_um2[2]) * 500.0};
    }
  return {0.0, inf};
}

std::vector<Complex> Material::iorAt(const std::vector<double>& lambda_um) const {
  std::vector<Complex> out;
  out.reserve(lambda_um.size());
  for (double l : lambda_um) out.push_back(isPerfectConductor() ? Complex(0, 0) : ior(l));
  return out;
}

Complex Material::ior(double lambda_um) const {
  return std::visit(
      Overloaded{[&](const Conductor& c) {
                   return std::visit(Overloaded{[&](const TabulatedIndex& t) {
                                                  double l = lambda_um * 1000.0;
                                                  return Complex(interpolate(t.lambda_nm, t.eta, l),
                                                                 interpolate(t.lambda_nm, t.k, l));
                                                },
                                                [](const ConstantIndex& k) { return Complex(k.eta, k.k); },
                                                [](const PerfectConductor&) {
                                                  return Complex(0.0, std::numeric_limits<double>::infinity());
                                                }},
                                     c.index);
                 },
                 [&](const Dielectric& d) {
                   return std::visit(
                       Overloaded{[](const ConstantIndex& k) { return Complex(k.eta, k.k); },
                                  [&](const SellmeierIndex& s) { return Complex(sellmeier(s, lambda_um), 0.0); }},
                       d.index);
                 }},
      model);
}

std::string Material::describe() const {
  return std::visit(
      Overloaded{[](const Conductor& c) {
                   return std::visit(
                       Overloaded{[](const TabulatedIndex& t) { return "conductor " + t.name; },
                                  [](const ConstantIndex& k) {
                                    return "conductor eta=" + std::to_string(k.eta) + " k=" + std::to_string(k.k);
                                  },
                                  [](const PerfectConductor&) { return std::string("perfect conductor"); }},
                       c.index);
                 },
                 [](const Dielectric& d) {
                   return std::visit(
                       Overloaded{[](const ConstantIndex& k) { return "dielectric n=" + std::to_string(k.eta); },
                                  [](const SellmeierIndex& s) { return "dielectric " + s.name + " (Sellmeier)"; }},
                       d.index);
                 }},
      model);
}

bool builtinMaterial(const std::string& name, Material* out) {
  using namespace data;
  auto metal = [&](const char* n, const std::vector<double>& eta, const std::vector<double>& k) {
    out->model = Conductor{TabulatedIndex{n, kMetalLambda_nm, eta, k}};
    return true;
  };
  if (name == "Al") return metal("Al", kAlEta, kAlK);
  if (name == "Ag") return metal("Ag", kAgEta, kAgK);
  if (name == "Au") return metal("Au", kAuEta, kAuK);
  if (name == "Cu") return metal("Cu", kCuEta, kCuK);
  if (name == "mirror") {
    out->model = Conductor{PerfectConductor{}};
    return true;
  }
  if (name == "BK7") {
    // Schott N-BK7 Sellmeier coefficients (Schott optical glass data sheet).
    out->model = Dielectric{
        SellmeierIndex{"BK7", {1.03961212, 0.231792344, 1.01046945}, {0.00600069867, 0.0200179144, 103.560653}}};
    return true;
  }
  return false;
}

std::vector<std::string> builtinMaterialNames() {
  return {"Al", "Ag", "Au", "Cu", "mirror", "BK7"};
}

}  // namespace mbsdf
