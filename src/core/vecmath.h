// Small double-precision vector type. docs/physics.md §1: directions point away from the surface,
// macro normal n = +z, theta from +z, phi from +x.
#pragma once
#include <algorithm>
#include <cassert>
#include <cmath>
#include <numbers>

namespace mbsdf {

inline constexpr double kPi = std::numbers::pi;

struct Vec3 {
  double x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr double& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  constexpr bool operator==(const Vec3&) const = default;
};
constexpr Vec3 operator*(double s, const Vec3& v) {
  return v * s;
}
constexpr double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3& v) {
  return std::sqrt(dot(v, v));
}
inline Vec3 normalize(const Vec3& v) {
  return v / length(v);
}
inline bool isFinite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Mirror reflection of a direction pointing away from the surface about normal n.
inline Vec3 reflect(const Vec3& wo, const Vec3& n) {
  return -wo + 2.0 * dot(wo, n) * n;
}

// Refraction of direction wi (pointing away from the surface, on the side of n) into the other
// medium, eta = n_i / n_t. Returns false on total internal reflection. Same form as pbrt-v4's
// Refract(); the result points away from the surface on the opposite side.
inline bool refract(const Vec3& wi, const Vec3& n, double eta, Vec3* wt) {
  double cosTheta_i = dot(n, wi);
  double sin2Theta_i = std::max(0.0, 1.0 - cosTheta_i * cosTheta_i);
  double sin2Theta_t = eta * eta * sin2Theta_i;
  if (sin2Theta_t >= 1.0) return false;
  double cosTheta_t = std::sqrt(1.0 - sin2Theta_t);
  *wt = normalize(-wi * eta + (eta * cosTheta_i - cosTheta_t) * n);
  return true;
}

// The square root and inverse cosine of quantities that are in range in exact arithmetic (1 − cos²,
// a unit vector's component, 1 − x² − y² of a point on the unit disk) but may round just outside it:
// clamped, so a grazing or polar direction never gives NaN. Debug builds assert that what is
// clamped is rounding (within 1e-9), not a wrong argument.
inline double safeSqrt(double x) {
  assert(x > -1e-9 && "safeSqrt: clearly negative, not rounding");
  return std::sqrt(std::max(0.0, x));
}
inline double safeAcos(double x) {
  assert(x > -1 - 1e-9 && x < 1 + 1e-9 && "safeAcos: clearly outside [-1, 1], not rounding");
  return std::acos(std::clamp(x, -1.0, 1.0));
}

// Direction from spherical angles (radians).
inline Vec3 sphericalDirection(double theta, double phi) {
  double s = std::sin(theta);
  return {s * std::cos(phi), s * std::sin(phi), std::cos(theta)};
}
inline double sphericalTheta(const Vec3& w) {
  return safeAcos(w.z);
}
inline double sphericalPhi(const Vec3& w) {
  double p = std::atan2(w.y, w.x);
  return p < 0 ? p + 2 * kPi : p;
}
// w turned by `angle` (radians) about the z axis, the surface normal.
inline Vec3 turnedAboutZ(const Vec3& w, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * w.x - s * w.y, s * w.x + c * w.y, w.z};
}
inline double radians(double deg) {
  return deg * kPi / 180.0;
}
inline double degrees(double rad) {
  return rad * 180.0 / kPi;
}

}  // namespace mbsdf
