#include "render/ggx_material.h"

#include <cmath>
#include <stdexcept>

namespace mbsdf {

GgxConductorMaterial::GgxConductorMaterial(double alpha, std::vector<Complex> eta, std::vector<Colour3> toRgb)
    : alpha_(alpha), ggx_(GgxNdf{alpha, alpha}), eta_(std::move(eta)), toRgb_(std::move(toRgb)) {
  if (eta_.size() != toRgb_.size() || eta_.empty() || !(alpha > 0))
    throw std::invalid_argument("GGX reference: one index per colour weight, alpha > 0");
}

Colour3 GgxConductorMaterial::eval(const Vec3& wi, const Vec3& wo) const {
  if (!(wi.z > 0 && wo.z > 0)) return {0, 0, 0};
  const Vec3 h = normalize(wi + wo);
  const double common = ggx_.D(h) * ggx_.G2(wi, wo) / (4 * wi.z * wo.z);
  Colour3 f{0, 0, 0};
  for (size_t l = 0; l < eta_.size(); ++l) {
    const double F = fresnelReflectance(dot(wi, h), 1.0, eta_[l]);
    for (int k = 0; k < 3; ++k) f[size_t(k)] += toRgb_[l][size_t(k)] * F * common;
  }
  return f;
}

double GgxConductorMaterial::pdf(const Vec3& wo, const Vec3& wi) const {
  if (!(wi.z > 0 && wo.z > 0)) return 0;
  const Vec3 h = normalize(wi + wo);
  return ggx_.D(h) * h.z / (4 * std::abs(dot(wo, h)));
}

std::optional<MaterialSample> GgxConductorMaterial::sample(const Vec3& wo, Sampler& s) const {
  const double u1 = s.get1D(), u2 = s.get1D();
  if (!(wo.z > 0)) return std::nullopt;
  // tan² θh = α² u1 / (1 − u1), φh = 2π u2.
  const double tan2 = alpha_ * alpha_ * u1 / (1 - u1), cosH = 1 / std::sqrt(1 + tan2);
  const double sinH = safeSqrt(1 - cosH * cosH), phi = 2 * kPi * u2;
  const Vec3 h{sinH * std::cos(phi), sinH * std::sin(phi), cosH};
  MaterialSample out;
  out.wi = reflect(wo, h);
  out.pdf = pdf(wo, out.wi);
  if (!(out.wi.z > 0) || !(out.pdf > 0)) return std::nullopt;
  const Colour3 f = eval(out.wi, wo);
  for (int k = 0; k < 3; ++k) out.weight[size_t(k)] = f[size_t(k)] * out.wi.z / out.pdf;
  return out;
}

}  // namespace mbsdf
